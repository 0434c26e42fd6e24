"""The fake device itself: a replay delivers every notification it holds, on the timeline's own axis."""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np

from hri_physio_bridge.polar.capture import read_capture
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.encode import encode_heart_rate
from hri_physio_bridge.polar.fake import (
    FakeClock,
    FakePolarDevice,
    FakeScanner,
    Notification,
    RecordedArrivalClock,
    fake_client_factory,
    play_through,
)
from hri_physio_bridge.polar.gatt import HEART_RATE_MEASUREMENT, PMD_DATA
from hri_physio_bridge.polar.output import MemorySink
from hri_physio_bridge.polar.session import PolarSession
from hri_physio_bridge.polar.synthetic import synthetic_h10, write_capture
from hri_physio_bridge.polar.virtual_time import run_virtual

HR = encode_heart_rate(70, [900])


def played(device: FakePolarDevice, clock: FakeClock, char: str) -> list[bytes]:
    """Connect, subscribe to ``char``, release the timeline: what reached the client."""

    async def play() -> list[bytes]:
        got: list[bytes] = []
        client = device.client(lambda: None)
        await client.connect()
        await client.start_notify(char, lambda _c, data: got.append(bytes(data)))
        device.release()
        await device.wait_finished()
        return got

    return run_virtual(play(), clock)


def delivered_in_replay(clock: FakeClock, first_t: float, speed: float) -> int:
    """How many of three notifications (from ``first_t``) arrive."""
    timeline = [Notification(first_t + k * 0.5, HEART_RATE_MEASUREMENT, HR) for k in range(3)]
    device = FakePolarDevice(timeline=timeline, clock=clock, speed=speed)
    return len(played(device, clock, HEART_RATE_MEASUREMENT))


def test_the_first_notification_is_never_lost_whatever_the_clock_and_capture_times() -> None:
    """Capture times near 5000 s and clocks anywhere: ``(released - t0) + t0`` rounds below the release
    for some of them; the fake compares on the timeline's axis, so none is lost."""
    rng = random.Random(2)
    for _ in range(300):
        clock = FakeClock(rng.uniform(100.0, 200_000.0))
        speed = rng.choice([1.0, 3.0, 100.0])
        assert delivered_in_replay(clock, rng.uniform(1000.0, 9000.0), speed) == 3


def test_notifications_due_while_the_link_is_down_are_lost() -> None:
    clock = FakeClock()
    timeline = [Notification(k * 1.0, HEART_RATE_MEASUREMENT, HR) for k in range(10)]
    device = FakePolarDevice(timeline=timeline, clock=clock)

    async def play() -> list[float]:
        seen: list[float] = []
        client = device.client(lambda: None)
        await client.connect()
        await client.start_notify(HEART_RATE_MEASUREMENT, lambda _c, _d: seen.append(clock()))
        device.release()
        while len(seen) < 3:
            await clock.sleep(0.25)
        device.drop_link()
        await clock.sleep(4.5)  # four notifications fall due with no link
        await client.connect()
        await client.start_notify(HEART_RATE_MEASUREMENT, lambda _c, _d: seen.append(clock()))
        device.release()
        await device.wait_finished()
        return seen

    seen = run_virtual(play(), clock)
    assert device.delivered + device.lost == 10 and device.lost == 4 and len(seen) == 6


def test_a_recorded_notification_of_an_unknown_measurement_is_passed_on() -> None:
    """A capture holds what the device sent: PMD data of a measurement type no model knows still reaches
    the client (which counts it as unexpected), while data of a known but unstarted one does not."""
    clock = FakeClock()
    unknown = bytes([0x07]) + bytes(9)
    unstarted_acc = bytes([0x02]) + bytes(9)
    timeline = [Notification(0.0, PMD_DATA, unknown), Notification(0.5, PMD_DATA, unstarted_acc)]
    device = FakePolarDevice(timeline=timeline, clock=clock)
    assert played(device, clock, PMD_DATA) == [unknown]
    assert device.lost == 1


def replayed_ecg_stamps(capture_path: Path, speed: float) -> tuple[list[float], dict]:
    """A capture replayed as ``polar_streamer --replay`` does, in virtual time: the ECG stamps pushed."""
    clock = FakeClock(1000.0)
    device = FakePolarDevice.from_capture(read_capture(capture_path), speed=speed, clock=clock)
    config = PolarConfig(replay=str(capture_path), replay_speed=speed, streams=device.recorded_streams())
    sink = MemorySink()

    async def run() -> PolarSession:
        session = PolarSession(config, FakeScanner([device], clock), fake_client_factory, sink, clock=clock,
                               watchdog=False, arrival_clock=RecordedArrivalClock(device, clock))
        await play_through(session, device)
        return session

    session = run_virtual(run(), clock)
    return [t for t, _ in sink.samples["ecg"]], session.status()["streams"]["ecg"]


def test_a_replay_gives_the_same_stamps_at_any_speed_even_across_a_clock_jump(tmp_path: Path) -> None:
    """Notifications arrive when the capture says they did: at 1000x the device clock is not mapped
    against arrivals 1000 times too soon (a false drift), and the frame after a bad device timestamp is
    not taken for one out of order (samples were lost at 4x that 1x kept)."""
    syn = synthetic_h10(20.0, heart_rate=False, ppm=20.0, jitter_ms=6.0, seed=5)
    path = tmp_path / "c.jsonl"
    frames = write_capture(path, syn)
    lines = path.read_text().splitlines()
    data_lines = [i for i, line in enumerate(lines) if '"pmd_data"' in line]
    bad = json.loads(lines[data_lines[10]])
    bad["hex"] = bad["hex"][:2] + "00" * 8 + bad["hex"][18:]  # its device timestamp reads 0
    lines[data_lines[10]] = json.dumps(bad)
    path.write_text("\n".join(lines) + "\n")
    at_1x, stats_1x = replayed_ecg_stamps(path, 1.0)
    assert stats_1x["clock_jumps"] == 2 and len(at_1x) >= frames * 73 - 1  # to 0 and back: 1 sample at most
    for speed in (4.0, 1000.0):
        stamps, stats = replayed_ecg_stamps(path, speed)
        assert len(stamps) == len(at_1x)
        assert np.allclose(np.array(stamps) - stamps[0], np.array(at_1x) - at_1x[0], atol=1e-9)
        assert stats == stats_1x

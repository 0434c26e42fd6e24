"""The session on real pylsl outlets, read back by real pylsl inlets (fake device, real time)."""

from __future__ import annotations

import itertools
import json
import uuid

import pylsl
import pytest

from helpers import resolve_lsl, wait_until
from helpers.polar import SessionThread
from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.encode import encode_compressed_frame, encode_ecg_frame, encode_heart_rate
from hri_physio_bridge.polar.fake import FakePolarDevice, FakeScanner, Notification, fake_client_factory
from hri_physio_bridge.polar.gatt import HEART_RATE_MEASUREMENT, PMD_DATA
from hri_physio_bridge.polar.lsl_output import LslSink
from hri_physio_bridge.polar.session import PolarSession
from hri_physio_bridge.polar.synthetic import H10_SETTINGS

pytestmark = pytest.mark.lsl

NS = 1_000_000_000
FRAME = 13
FRAMES = 40  # 4 s of ECG at 130 Hz
LOST = 17  # this frame is never sent


def counter_timeline() -> tuple[list[Notification], list[int]]:
    """ECG whose values count samples (a counter channel), one lost frame, HR once a second."""
    t0 = 599616028236586218
    timeline, sent = [], []
    for k in range(FRAMES):
        values = list(range(k * FRAME, (k + 1) * FRAME))
        last = t0 + ((k + 1) * FRAME - 1) * NS // 130
        if k != LOST:
            timeline.append(
                Notification(((k + 1) * FRAME - 1) / 130 + 0.01, PMD_DATA, encode_ecg_frame(last, values))
            )
            sent += values
    for s in range(1, 4):
        timeline.append(
            Notification(s + 0.005, HEART_RATE_MEASUREMENT, encode_heart_rate(70 + s, [1000, 1010]))
        )
    return timeline, sent


def test_lsl_streams_names_rates_and_every_sample_in_order() -> None:
    device_id = uuid.uuid4().hex[:8].upper()
    timeline, sent = counter_timeline()
    device = FakePolarDevice(
        f"Polar H10 {device_id}", features={0, 2}, settings=dict(H10_SETTINGS), timeline=timeline
    )
    sink = LslSink()
    session = PolarSession(
        PolarConfig(device=device_id, streams=["ecg", "hr", "rr"]),
        FakeScanner([device]),
        fake_client_factory,
        sink,
        clock=pylsl.local_clock,
    )
    with SessionThread(session) as runner:
        inlets = {}
        for kind in ("ECG", "HR", "RR", "Markers"):
            found = resolve_lsl(f"PolarH10/{device_id}/{kind}")
            assert found, f"no LSL stream PolarH10/{device_id}/{kind}"
            inlets[kind] = pylsl.StreamInlet(found[0], max_buflen=60)
            inlets[kind].open_stream(timeout=10)
        info = {k: inlet.info() for k, inlet in inlets.items()}
        assert (info["ECG"].channel_count(), info["ECG"].nominal_srate(), info["ECG"].type()) == (
            1,
            130.0,
            "ECG",
        )
        assert (info["HR"].channel_count(), info["HR"].nominal_srate()) == (1, 1.0)
        assert (info["RR"].channel_count(), info["RR"].nominal_srate()) == (1, 0.0)
        assert info["Markers"].channel_format() == pylsl.cf_string
        assert info["ECG"].desc().child("channels").child("channel").child_value("unit") == "microvolts"
        assert info["ECG"].source_id() == f"{device_id}-ECG"
        runner.call(device.release)
        received: dict[str, list[tuple[float, list]]] = {k: [] for k in inlets}

        def pull_all(timeout: float) -> None:
            for kind, inlet in inlets.items():
                samples, stamps = inlet.pull_chunk(timeout=timeout, max_samples=4096)
                received[kind] += list(zip(stamps, samples, strict=False))

        deadline = pylsl.local_clock() + 30
        while len(received["ECG"]) < len(sent) and pylsl.local_clock() < deadline:
            pull_all(0.2)
        pull_all(0.5)
    assert runner.result == [0]
    ecg_values = [int(row[0]) for _, row in received["ECG"]]
    assert ecg_values == sent  # nothing dropped, duplicated or reordered; only the lost frame is missing
    stamps = [t for t, _ in received["ECG"]]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert stamps[-1] - stamps[0] == pytest.approx((len(sent) + FRAME - 1) / 130, abs=0.05)
    assert [row[0] for _, row in received["HR"]] == [71.0, 72.0, 73.0]
    rr_stamps = [t for t, _ in received["RR"]]
    assert len(rr_stamps) == 6 and all(b > a for a, b in itertools.pairwise(rr_stamps))
    markers = [json.loads(row[0]) for _, row in received["Markers"]]
    gaps = [m for m in markers if m["event"] == "gap"]
    assert len(gaps) == 1 and gaps[0]["missing"] == FRAME and gaps[0]["stream"] == "ECG"
    assert session.status()["streams"]["ecg"]["samples"] == len(sent)


def test_a_corrected_rate_is_declared_anew_and_its_consumer_gets_every_sample() -> None:
    """A Verity Sense announcing PPG at 135 Hz and sending 55 Hz, with a consumer on the first outlet:
    the stream is declared again at 55 Hz and what was held for the rate check waits for a consumer."""
    device_id = uuid.uuid4().hex[:8].upper()
    settings = cp.encode_offered_settings(
        {cp.SettingType.SAMPLE_RATE: [135], cp.SettingType.RESOLUTION: [22], cp.SettingType.CHANNELS: [4]}
    )
    t0, timeline, sent = 599616028236586218, [], []
    for k in range(12):
        rows = [[1000 + 42 * k + i, 2000, 3000, -5] for i in range(42)]
        last = t0 + (42 * k + 41) * NS // 55
        timeline.append(Notification((42 * k + 41) / 55 + 0.02, PMD_DATA,
                                     encode_compressed_frame(1, last, 0, rows, 24, widths=[2])))
        sent += [row[0] for row in rows]
    device = FakePolarDevice(f"Polar Sense {device_id}", features={1}, settings={1: settings},
                             timeline=timeline, speed=4.0)
    sink = LslSink()
    session = PolarSession(PolarConfig(device=device_id, streams=["ppg"]), FakeScanner([device]),
                           fake_client_factory, sink, clock=pylsl.local_clock)
    session.data.reopen_wait_s = 300.0  # this test's consumer may be slow to find the new outlet
    name = f"PolarOH1/{device_id}/PPG"
    with SessionThread(session) as runner:
        [first] = resolve_lsl(name)
        assert first.nominal_srate() == 135.0  # what the device announced
        old = pylsl.StreamInlet(first)
        old.open_stream(timeout=10)
        runner.call(device.release)
        found: list = []
        wait_until(lambda: bool(found.extend(s for s in pylsl.resolve_byprop("name", name, timeout=0.5)
                                             if s.nominal_srate() == 55.0) or found),
                   60, "the stream declared again at 55 Hz")
        inlet = pylsl.StreamInlet(found[0], max_buflen=60)
        inlet.open_stream(timeout=10)
        received: list[float] = []
        deadline = pylsl.local_clock() + 60
        while len(received) < len(sent) and pylsl.local_clock() < deadline:
            samples, _ = inlet.pull_chunk(timeout=0.2, max_samples=4096)
            received += [row[0] for row in samples]
    assert runner.result == [0]
    assert received == sent  # held through the re-declaration, then every sample in order
    stats = session.status()["streams"]["ppg"]
    assert (stats["rate_corrections"], stats["rate_hz"], stats["gaps"]) == (1, 55, 0)

"""The connection life cycle against fake devices in virtual time: streaming, loss, reconnection, errors."""

from __future__ import annotations

import asyncio
import itertools
import json
import random
from pathlib import Path

import pytest

from helpers.polar import NAME, h10, run_session, writes
from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.ble import BleUnavailableError
from hri_physio_bridge.polar.capture import CaptureWriter, read_capture
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.encode import (
    encode_compressed_frame,
    encode_heart_rate,
    encode_ppg_frame,
    encode_ppi_frame,
)
from hri_physio_bridge.polar.fake import (
    FakeClock,
    FakePolarDevice,
    FakeScanner,
    Notification,
    fake_client_factory,
    play_through,
)
from hri_physio_bridge.polar.gatt import HEART_RATE_MEASUREMENT, PMD_CONTROL_POINT, PMD_DATA
from hri_physio_bridge.polar.output import MemorySink
from hri_physio_bridge.polar.protocol import Measurement
from hri_physio_bridge.polar.session import PolarSession
from hri_physio_bridge.polar.virtual_time import run_virtual


class CountingSink(MemorySink):
    def __init__(self) -> None:
        super().__init__()
        self.opens: list[str] = []

    def open(self, stream) -> None:
        self.opens.append(stream.name)
        super().open(stream)


# ----------------------------------------------------------------------------------------------
def test_streams_every_sample_with_accurate_timestamps() -> None:
    clock = FakeClock()
    device, syn = h10(clock, 150.0, ppm=20.0, acc_rate=100, jitter_ms=10.0, seed=4)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg", "acc", "hr", "rr"], acc_rate=100)
    sink = run.sink
    assert {key: (s.name, s.nominal_rate, len(s.channels)) for key, s in sink.streams.items()} == {
        "ecg": ("PolarH10/0A1B2C3D/ECG", 130.0, 1),
        "acc": ("PolarH10/0A1B2C3D/ACC", 100.0, 3),
        "hr": ("PolarH10/0A1B2C3D/HR", 1.0, 1),
        "rr": ("PolarH10/0A1B2C3D/RR", 0.0, 1),
        "markers": ("PolarH10/0A1B2C3D/Markers", 0.0, 1),
    }
    # every ECG sample, in order, unchanged
    assert [row[0] for row in sink.values("ecg")] == syn.ecg_values
    stamps = sink.stamps("ecg")
    assert all(b > a for a, b in itertools.pairwise(stamps))
    # timestamps: true host sampling time (+ the fixed 8 ms minimum latency, which no host can see)
    base = device._base
    truth = [base + t + 0.008 for t in syn.ecg_host_s]
    errors = [abs(s - t) for s, t in zip(stamps, truth, strict=False)]
    settled = errors[130 * 90 :]  # after 90 s
    assert max(settled) < 0.003, max(settled)
    assert run.session.status()["drift_ppm"] == pytest.approx(-20.0, abs=2.0)
    drift = [e for e in sink.events() if e["event"] == "clock_drift"]
    assert len(drift) == 1 and drift[0]["t"] - device._base > 60  # reported once, when it can be estimated
    # RR intervals exactly as reported, beat times never after the truth + lag bound
    rr = [row[0] for row in sink.values("rr")]
    truth_rr = [(b - a) for a, b in zip(syn.beat_host_s, syn.beat_host_s[1:], strict=False)][: len(rr)]
    assert rr == pytest.approx([round(x * 1024) * 1000 / 1024 for x in truth_rr])
    assert sink.values("hr") and all(60 <= row[0] <= 90 for row in sink.values("hr"))
    assert len(sink.values("acc")) == 150 * 100 // 36 * 36
    # subscribe to the control point and the data before any start request
    ops = device.operations
    first_start = next(i for i, op in enumerate(ops) if op[0] == "write" and op[2].startswith("02"))
    assert ("start_notify", PMD_CONTROL_POINT) in ops[:first_start] and ("start_notify", PMD_DATA) in ops[
        :first_start
    ]
    assert "02000001820001010e00" in writes(device)  # the start ECG request
    assert run.status == 0 and run.session.state == "stopped"


def test_lost_and_duplicated_frames() -> None:
    clock = FakeClock()
    device, syn = h10(
        clock, 20.0, heart_rate=False, lose_ecg_frames=frozenset({5, 6}), duplicate_ecg_frames=frozenset({10})
    )
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    stats = run.session.status()["streams"]["ecg"]
    assert (stats["gaps"], stats["missing_samples"], stats["dropped_frames"]) == (1, 146, 1)
    assert [row[0] for row in run.sink.values("ecg")] == syn.ecg_values  # the duplicate is not pushed twice
    gap = [e for e in run.sink.events() if e["event"] == "gap"]
    assert len(gap) == 1 and gap[0]["missing"] == 146 and gap[0]["stream"] == "ECG"
    assert gap[0]["end"] - gap[0]["start"] == pytest.approx(145 / 130, abs=0.002)
    assert [e["reason"] for e in run.sink.events() if e["event"] == "frame_dropped"] == ["duplicate"]


def test_skipped_rr_intervals_are_counted_in_the_status() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 20.0)
    clean = run_session([device], clock, device="0A1B2C3D", streams=["hr", "rr"])
    clean_stats = clean.session.status()["streams"]
    clock = FakeClock()
    device, _ = h10(clock, 20.0)
    bad = Notification(10.05, HEART_RATE_MEASUREMENT, encode_heart_rate(70, [0, 0]))
    device.timeline = sorted([*device.timeline, bad], key=lambda n: n.t)
    run = run_session([device], clock, device="0A1B2C3D", streams=["hr", "rr"])
    stats = run.session.status()["streams"]
    assert stats["rr"]["invalid_intervals"] == 2 and clean_stats["rr"]["invalid_intervals"] == 0
    assert run.sink.values("rr") == clean.sink.values("rr")  # no interval of 0 became a beat
    assert stats["hr"]["samples"] == clean_stats["hr"]["samples"] + 1


def test_timing_counts_cover_every_connection() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 30.0, heart_rate=False, lose_ecg_frames=frozenset({5, 6}),
                    duplicate_ecg_frames=frozenset({10}), disconnect_after=[25])
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert run.session.status()["reconnects"] == 1
    stats = run.session.status()["streams"]["ecg"]
    # The gap and the duplicate came on the first connection; the second connection's timer adds to them.
    counts = (stats["gaps"], stats["missing_samples"], stats["duplicates"], stats["dropped_frames"])
    assert counts == (1, 146, 1, 1)
    assert stats["frames"] > 0 and stats["clock_jumps"] == 0


def test_disconnect_mid_stream_and_reconnect() -> None:
    clock = FakeClock()
    device, syn = h10(clock, 30.0, disconnect_after=[25])
    sink = CountingSink()
    run = run_session([device], clock, sink, device="0A1B2C3D", streams=["ecg", "hr", "rr"])
    assert run.status == 0
    assert len(run.of("connected")) == 2 and len(run.of("disconnected")) == 1
    assert run.session.status()["reconnects"] == 1
    # the outlets were declared once and stayed open
    assert sorted(sink.opens) == sorted(set(sink.opens)) and len(sink.opens) == 4
    # the reconnect sequence: back off, scan, connect, subscribe, restart the streams
    after = run.states[run.states.index("waiting") :]
    assert after[:5] == ["waiting", "searching", "connecting", "starting", "streaming"]
    assert 0.7 <= run.sleeps[0] <= 1.3  # 1 s +- 30 % jitter
    lost = device.operations.index(("link_lost",))
    again = device.operations[lost + 1 :]
    assert again[0] == ("connect",)
    assert ("start_notify", PMD_DATA) in again and (
        "write",
        PMD_CONTROL_POINT,
        "02000001820001010e00",
    ) in again
    # timestamps stay increasing through the reconnection; samples lost during the outage are not invented
    stamps = sink.stamps("ecg")
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert 0 < len(stamps) < len(syn.ecg_values) and device.lost > 0
    values = [row[0] for row in sink.values("ecg")]
    assert values[: 25 * 73] == syn.ecg_values[: 25 * 73]


def test_stop_is_sent_before_disconnect() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 30.0, acc_rate=200)
    run = run_session(
        [device],
        clock,
        device="0A1B2C3D",
        streams=["ecg", "acc"],
        stop_when=lambda s, _e: s.status()["streams"].get("ecg", {}).get("samples", 0) > 500,
    )
    ops = device.operations
    disconnect = ops.index(("disconnect",))
    stop_writes = [i for i, op in enumerate(ops) if op[0] == "write" and op[2] in ("0300", "0302")]
    assert len(stop_writes) == 2 and max(stop_writes) < disconnect
    assert device.active == set() and run.status == 0


def test_backoff_grows_with_jitter_up_to_30_s() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0, connect_failures=8)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    delays = run.sleeps[:8]
    nominal = [1, 2, 4, 8, 16, 30, 30, 30]
    assert all(0.7 * n <= d <= min(30.0, 1.3 * n) for d, n in zip(delays, nominal, strict=False)), delays
    assert len(set(delays)) == len(delays)  # jittered
    assert run.of("connected") and run.status == 0


def test_device_not_found_gives_up() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0, visible=False)
    run = run_session([device], clock, device="0A1B2C3D", give_up_after=25.0, scan_timeout=10.0)
    assert run.status == 1
    assert "not found" in run.session.error and "0A1B2C3D" in run.session.error
    assert run.states[-1] == "failed"


def test_pairing_required_ends_with_status_2() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0, pairing_required=True)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert run.status == 2 and "pairing" in run.session.error
    assert device.connections == 1  # not retried


def test_stream_the_device_does_not_have() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ppg"])
    assert run.status == 2 and "no ppg" in run.session.error and device.connections == 0


def test_setting_the_device_does_not_offer_stops_what_started() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg", "acc"], acc_rate=416)
    assert run.status == 2
    assert "acc_rate 416" in run.session.error and "25, 50, 100, 200" in run.session.error
    ops = device.operations
    assert ops.index(("write", PMD_CONTROL_POINT, "0300")) < ops.index(("disconnect",))


def test_device_busy_is_retried() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0, start_status={Measurement.ECG: cp.Status.INVALID_STATE})
    run = run_session(
        [device], clock, device="0A1B2C3D", streams=["ecg"], stop_when=lambda _s, _e: device.connections >= 3
    )
    assert run.status == 0 and device.connections >= 3
    assert "another client" in run.session.error


def test_device_initiated_stop_restarts_the_stream() -> None:
    clock = FakeClock()
    device, syn = h10(clock, 20.0, heart_rate=False, stop_indication_after=5)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert run.of("device_stopped") and run.of("stream_restarted")
    assert writes(device).count("02000001820001010e00") == 2
    assert run.session.status()["device_stops"] == 1
    assert len(run.sink.values("ecg")) > len(syn.ecg_values) // 2


def test_no_bluetooth_ends_with_status_2() -> None:
    class NoAdapter(FakeScanner):
        async def find(self, match, timeout):
            raise BleUnavailableError("no Bluetooth adapter")

    session = PolarSession(
        PolarConfig(device="0A1B2C3D"), NoAdapter([]), lambda a, cb: None, MemorySink(), clock=FakeClock()
    )
    assert asyncio.run(session.run(asyncio.Event())) == 2
    assert session.error == "no Bluetooth adapter" and session.state == "failed"


def test_capture_then_replay_gives_the_same_samples(tmp_path: Path) -> None:
    clock = FakeClock()
    device, syn = h10(clock, 15.0, acc_rate=50)
    capture = CaptureWriter(tmp_path / "session.jsonl", {"program": "test"})

    async def record() -> PolarSession:
        sink = MemorySink()
        session = PolarSession(
            PolarConfig(device="0A1B2C3D", streams=["ecg", "acc", "rr"], acc_rate=50),
            FakeScanner([device], clock),
            fake_client_factory,
            sink,
            clock=clock,
            sleep=clock.sleep,
            capture=capture,
            rng=random.Random(1),
        )
        await play_through(session, device)
        return session

    recorded = run_virtual(record(), clock)
    capture.close()
    lines = (tmp_path / "session.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["format"] == "hri_physio.polar.capture"
    replayed_capture = read_capture(tmp_path / "session.jsonl")
    assert replayed_capture.header["device"]["name"] == NAME
    clock2 = FakeClock(50_000.0)
    replay = FakePolarDevice.from_capture(replayed_capture, clock=clock2)
    run = run_session([replay], clock2, device="0A1B2C3D", streams=["ecg", "acc", "rr"], acc_rate=50)
    assert [r[0] for r in run.sink.values("ecg")] == syn.ecg_values
    assert run.sink.values("acc") == recorded.sink.values("acc")
    assert run.sink.values("rr") == recorded.sink.values("rr")
    # arrival times are replayed too: the same timestamps, shifted by the replay's start
    shift = run.sink.stamps("ecg")[0] - recorded.sink.stamps("ecg")[0]
    assert [
        round(a - b - shift, 6)
        for a, b in zip(run.sink.stamps("ecg"), recorded.sink.stamps("ecg"), strict=False)
    ] == [0.0] * len(syn.ecg_values)


def test_oh1_ppg_ppi_and_its_reported_rate_quirk() -> None:
    clock = FakeClock()
    ppg_settings = cp.encode_offered_settings(
        {cp.SettingType.SAMPLE_RATE: [130], cp.SettingType.RESOLUTION: [22]}
    )
    t0, period = 599616028236586218, 1_000_000_000 // 135
    timeline = []
    for k in range(40):
        rows = [[1000 + k * 10 + i, 2000, 3000, -5] for i in range(10)]
        timeline.append(
            Notification(k * 10 / 135 + 0.02, PMD_DATA, encode_ppg_frame(t0 + (k * 10 + 9) * period, rows))
        )
    timeline.append(
        Notification(1.5, PMD_DATA, encode_ppi_frame(0, [[62, 968, 11, 6], [63, 0, 0, 1], [63, 951, 10, 6]]))
    )
    device = FakePolarDevice(
        "Polar OH1 1A2B3C4D",
        features={Measurement.PPG, Measurement.PPI},
        settings={Measurement.PPG: ppg_settings},
        timeline=timeline,
        clock=clock,
    )
    run = run_session([device], clock, device="1A2B3C4D", streams=["ppg", "ppi"])
    streams = run.sink.streams
    assert streams["ppg"].name == "PolarOH1/1A2B3C4D/PPG" and streams["ppg"].nominal_rate == 135.0
    assert run.session.status()["streams"]["ppg"]["gaps"] == 0  # 135 Hz spacing is what the device sends
    assert len(run.sink.values("ppg")) == 400 and run.sink.values("ppg")[0] == [1000.0, 2000.0, 3000.0, -5.0]
    assert run.sink.values("ppi") == [[968.0, 11.0, 62.0, 6.0], [951.0, 10.0, 63.0, 6.0]]  # 0 ms skipped
    ppi_stamps = run.sink.stamps("ppi")
    assert ppi_stamps[1] - ppi_stamps[0] == pytest.approx(0.951)


def test_verity_compressed_acc_with_conversion_factor() -> None:
    clock = FakeClock()
    settings = cp.encode_offered_settings(
        {
            cp.SettingType.SAMPLE_RATE: [52],
            cp.SettingType.RESOLUTION: [16],
            cp.SettingType.RANGE: [8],
            cp.SettingType.CHANNELS: [3],
        }
    )
    factor = cp.encode_offered_settings({cp.SettingType.FACTOR: [0.5]})
    rows = [[100, -200, 4000], [104, -190, 3990], [90, -210, 4003]]
    frame = encode_compressed_frame(Measurement.ACC, 599616028236586218, 1, rows, 16, widths=[9])
    device = FakePolarDevice(
        "Polar Sense 2B3C4D5E",
        features={Measurement.ACC},
        settings={Measurement.ACC: settings},
        start_params={Measurement.ACC: factor},
        timeline=[Notification(0.1, PMD_DATA, frame)],
        clock=clock,
    )
    run = run_session([device], clock, device="Polar Sense", streams=["acc"])
    assert (
        run.sink.streams["acc"].name == "PolarOH1/2B3C4D5E/ACC" and run.sink.streams["acc"].nominal_rate == 52
    )
    assert run.sink.values("acc") == [[v * 0.5 for v in row] for row in rows]
    assert "0202000134000101100002010800040103" in writes(device)


def test_reconnects_to_the_same_device_only() -> None:
    """Asked for any 'Polar H10': after the first connection only that strap is taken back."""
    clock = FakeClock()
    mine, _ = h10(clock, 30.0, disconnect_after=[10])
    other = FakePolarDevice(
        "Polar H10 FFFF0000",
        address="A0:9E:1A:00:00:02",
        features={0},
        settings=dict(mine.settings),
        clock=clock,
    )

    def script(_session: PolarSession, events: list[dict]) -> bool:
        searching = [e for e in events if e.get("state") == "searching"]
        if any(e["event"] == "disconnected" for e in events):
            mine.visible = len(searching) > 4  # gone for a few scans, then back
        return mine.connections == 2

    run = run_session([mine, other], clock, device="Polar H10", streams=["ecg"], stop_when=script)
    assert mine.connections == 2 and other.connections == 0
    assert run.session.status()["device"]["id"] == "0A1B2C3D"

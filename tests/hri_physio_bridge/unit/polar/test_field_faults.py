"""What real sensors do that the documentation does not say, through the fake BLE client in virtual time.

The H10's real start answer, INVALID_MTU now and then, an error answer naming no op, notifications
that stop without a disconnect, ECG that starts late, a PPG rate announced wrongly, SDK mode.
"""

from __future__ import annotations

import itertools
import logging

import pytest

from helpers.polar import NAME, h10, run_session, writes
from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.encode import encode_compressed_frame
from hri_physio_bridge.polar.fake import FakeClock, FakePolarDevice, Notification
from hri_physio_bridge.polar.gatt import HEART_RATE_MEASUREMENT, PMD_DATA
from hri_physio_bridge.polar.mtu import MIN_PMD_MTU
from hri_physio_bridge.polar.protocol import Measurement
from hri_physio_bridge.polar.synthetic import H10_RESET_TIME_NS, H10_START_PARAMS

ECG = Measurement.ECG
NS = 1_000_000_000


def warnings_of(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [
        r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING and r.name == "polar_streamer"
    ]


def markers(run, event: str) -> list[dict]:
    return [e for e in run.sink.events() if e["event"] == event]


# ----------------------------------------------------------------------------------------------
def test_the_h10_start_answer_gives_no_warning(caplog: pytest.LogCaptureFixture) -> None:
    """F0 02 00 00 00 00: success with one parameter byte, which carries no settings."""
    caplog.set_level(logging.INFO, logger="polar_streamer")
    clock = FakeClock()
    device, syn = h10(clock, 20.0, heart_rate=False, start_params={ECG: H10_START_PARAMS})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert warnings_of(caplog) == []
    assert [row[0] for row in run.sink.values("ecg")] == syn.ecg_values
    assert any("ECG started" in r.getMessage() and "factor 1" in r.getMessage() for r in caplog.records)


def test_invalid_mtu_once_then_success(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock()
    device, syn = h10(clock, 20.0, heart_rate=False, invalid_mtu_answers=1)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert run.status == 0 and device.connections == 2  # reconnected, not fatal
    status = run.session.status()
    assert status["mtu_refusals"] == 1 and status["mtu"] == 247 and status["connections"] == 1
    assert 0.7 <= run.sleeps[0] <= 1.3  # the first backoff step
    refusal = [w for w in warnings_of(caplog) if "INVALID_MTU" in w]
    assert len(refusal) == 1 and "get settings of ECG" in refusal[0] and "247 bytes" in refusal[0]
    assert [row[0] for row in run.sink.values("ecg")] == syn.ecg_values


def test_a_link_mtu_too_small_is_named_and_retried_until_giving_up(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock()
    device, _ = h10(clock, 20.0, heart_rate=False, mtu=23)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"], give_up_after=20.0)
    assert run.status == 1 and device.connections > 1
    assert "INVALID_MTU" in run.session.error and "(23 bytes)" in run.session.error
    assert ("request_mtu", "512") in device.operations
    short = [w for w in warnings_of(caplog) if w.startswith("the link's MTU is 23 bytes")]
    assert short and f"{MIN_PMD_MTU} bytes" in short[0] and "ExchangeMTU" in short[0]


def test_an_error_answer_naming_no_op_answers_the_pending_request(caplog: pytest.LogCaptureFixture) -> None:
    """F0 00 00 0A answers "get settings of ECG" at once: no 5-s timeout, nothing unexpected."""
    clock = FakeClock()
    device, _ = h10(clock, 20.0, heart_rate=False, invalid_mtu_answers=1, unnamed_errors=True)
    timeouts: list[str] = []

    def first_retry(session, events) -> bool:
        timeouts.extend(w for w in warnings_of(caplog) if "did not answer" in w)
        return session.status()["connections"] == 1

    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"], stop_when=first_retry)
    status = run.session.status()
    assert status["mtu_refusals"] == 1 and status["unexpected_notifications"] == 0
    assert timeouts == [] and device.connections == 2
    retry = next(e for e in run.of("state") if e["state"] == "waiting")
    connected = next(e for e in run.of("state") if e["state"] == "connecting")
    assert retry["t"] - connected["t"] < PolarConfig().response_timeout  # no timeout was waited for


def test_a_stall_mid_stream_is_marked_and_cured_by_a_restart(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock()
    device, syn = h10(clock, 60.0, heart_rate=False, stall_after={ECG: 30})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    [stall] = markers(run, "stall")
    assert (stall["stream"], stall["phase"], stall["action"]) == ("ECG", "streaming", "restart")
    assert stall["silent_s"] >= 5.0
    status = run.session.status()
    assert status["stalls"] == 1 and status["streams"]["ecg"]["stalls"] == 1
    assert status["stall_reconnects"] == 0 and device.connections == 1
    assert writes(device).count("0300") == 2  # the restart's stop, then the one before disconnecting
    assert writes(device).count("02000001820001010e00") == 2
    assert any("no data for" in w and "restarting" in w for w in warnings_of(caplog))
    # data flows again after the restart, and the stamps stay increasing
    values = [row[0] for row in run.sink.values("ecg")]
    assert values[: 30 * 73] == syn.ecg_values[: 30 * 73] and len(values) > 40 * 73
    assert all(b > a for a, b in itertools.pairwise(run.sink.stamps("ecg")))


def test_a_stall_a_restart_does_not_cure_ends_in_a_reconnect() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 90.0, heart_rate=False, stall_after={ECG: 20}, stall_heals="reconnect")
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    actions = [(m["phase"], m["action"]) for m in markers(run, "stall")]
    assert actions == [("streaming", "restart"), ("start", "reconnect")]
    status = run.session.status()
    assert status["stalls"] == 2 and status["stall_reconnects"] == 1 and status["reconnects"] == 1
    assert device.connections == 2 and markers(run, "reconnecting")
    assert status["streams"]["ecg"]["samples"] > 20 * 73 * 2  # streaming again on the new connection


def test_a_silent_heart_rate_is_subscribed_again() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 40.0, stall_after={"hr": 10})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg", "hr", "rr"])
    [stall] = markers(run, "stall")
    assert stall["stream"] == "HR/RR" and stall["action"] == "restart"
    assert device.operations.count(("start_notify", HEART_RATE_MEASUREMENT)) == 2
    stats = run.session.status()["streams"]
    assert stats["hr"]["stalls"] == 1 and stats["rr"]["stalls"] == 1 and stats["ecg"]["stalls"] == 0
    assert stats["hr"]["samples"] > 15  # ten before the stall, the rest after the new subscription


def test_ecg_that_starts_25_s_late_is_no_stall(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="polar_streamer")
    clock = FakeClock()
    device, _ = h10(clock, 60.0, heart_rate=False, start_delays={ECG: [25.0]})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    assert markers(run, "stall") == [] and run.session.status()["stalls"] == 0
    assert run.session.status()["streams"]["ecg"]["samples"] > 30 * 73
    assert any("ECG: first data 2" in r.getMessage() for r in caplog.records)


def test_ecg_that_never_starts_is_restarted_after_its_start_timeout() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 90.0, heart_rate=False, start_delays={ECG: [1000.0]})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"])
    [stall] = markers(run, "stall")
    assert (stall["phase"], stall["action"]) == ("start", "restart")
    assert stall["silent_s"] == pytest.approx(40.0, abs=1)
    assert run.session.status()["streams"]["ecg"]["samples"] > 40 * 73  # the restart started it
    assert device.connections == 1


def test_the_watchdog_timeouts_are_options() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 60.0, heart_rate=False, start_delays={ECG: [25.0]})
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"], start_timeout=20.0)
    [stall] = markers(run, "stall")
    assert stall["phase"] == "start" and stall["silent_s"] == pytest.approx(20.0, abs=1)


# ----------------------------------------------------------------------------------------------
PPG_SETTINGS_135 = cp.encode_offered_settings(
    {cp.SettingType.SAMPLE_RATE: [135], cp.SettingType.RESOLUTION: [22], cp.SettingType.CHANNELS: [4]}
)


def verity_ppg(
    clock: FakeClock, seconds: float, rate: float = 55.0, **options: object
) -> tuple[FakePolarDevice, list[list[int]]]:
    """A Verity Sense announcing PPG at 135 Hz and sampling at ``rate``: frames of 42 compressed samples."""
    t0, timeline, rows_sent = H10_RESET_TIME_NS + 28 * NS, [], []
    for k in range(int(seconds * rate / 42)):
        rows = [[1000 + 42 * k + i, 2000, 3000, -5] for i in range(42)]
        last = t0 + round((42 * k + 41) * NS / rate)
        frame = encode_compressed_frame(Measurement.PPG, last, 0, rows, 24, widths=[2])
        timeline.append(Notification((42 * k + 41) / rate + 0.02, PMD_DATA, frame))
        rows_sent += rows
    device = FakePolarDevice(
        "Polar Sense 2B3C4D5E",
        features={Measurement.PPG, Measurement.ACC},
        settings={Measurement.PPG: PPG_SETTINGS_135},
        timeline=timeline,
        clock=clock,
        **options,
    )
    return device, rows_sent


def test_a_wrongly_announced_rate_is_measured_and_corrected(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock()
    device, rows = verity_ppg(clock, 30.0)
    run = run_session([device], clock, device="2B3C4D5E", streams=["ppg"])
    [marker] = markers(run, "rate_corrected")
    assert (marker["stream"], marker["announced"], marker["rate"]) == ("PPG", 135.0, 55)
    assert marker["measured"] == pytest.approx(55.0, rel=1e-3)
    stats = run.session.status()["streams"]["ppg"]
    assert (stats["gaps"], stats["missing_samples"]) == (0, 0)
    assert (stats["rate_hz"], stats["announced_rate_hz"]) == (55, 135)
    assert run.sink.values("ppg") == [[float(v) for v in row] for row in rows]  # nothing held back for ever
    stamps = run.sink.stamps("ppg")
    assert (stamps[-1] - stamps[0]) / (len(stamps) - 1) == pytest.approx(1 / 55, rel=1e-3)
    # the LSL stream first declared what the device said, then anew at the rate it has
    assert [s.nominal_rate for s in run.sink.reopened] == [55] and run.sink.streams["ppg"].nominal_rate == 55
    assert any("announced 135 Hz but sends 55.0" in w for w in warnings_of(caplog))


def test_a_corrected_rate_is_kept_on_reconnection() -> None:
    clock = FakeClock()
    device, _ = verity_ppg(clock, 40.0, disconnect_after=[15])
    run = run_session([device], clock, device="2B3C4D5E", streams=["ppg"])
    assert device.connections == 2 and len(markers(run, "rate_corrected")) == 1
    assert len(run.sink.reopened) == 1 and run.session.status()["streams"]["ppg"]["gaps"] == 0


def test_the_rate_the_device_announces_rightly_stands() -> None:
    clock = FakeClock()
    device, rows = verity_ppg(clock, 20.0, rate=135.0)
    run = run_session([device], clock, device="2B3C4D5E", streams=["ppg"])
    assert markers(run, "rate_corrected") == [] and run.sink.reopened == []
    assert len(run.sink.values("ppg")) == len(rows)


# ----------------------------------------------------------------------------------------------
SDK_PPG = cp.encode_offered_settings(
    {cp.SettingType.SAMPLE_RATE: [28, 44, 55, 135, 176], cp.SettingType.RESOLUTION: [22],
     cp.SettingType.CHANNELS: [4]}
)


def test_sdk_mode_on_a_verity_sense() -> None:
    clock = FakeClock()
    device, _ = verity_ppg(clock, 10.0, rate=176.0, sdk_mode=True, sdk_settings={Measurement.PPG: SDK_PPG})
    seen: list[bool] = []
    run = run_session(
        [device], clock, device="2B3C4D5E", sdk_mode=True, ppg_rate=176,
        stop_when=lambda s, _e: seen.append(device.sdk_mode) is None and device.finished,
    )
    sent = writes(device)
    assert sent.index("0209") < sent.index("0101")  # SDK mode on before asking for the settings
    assert "02010001b00001011600040104" in sent  # PPG at 176 Hz, 22 bits, 4 channels
    assert sent.index("0301") < sent.index("0309")  # the stream stops before SDK mode goes off
    assert any(seen) and not device.sdk_mode and run.status == 0
    assert run.sink.streams["ppg"].nominal_rate == 176 and "hr" not in run.sink.streams  # SDK mode: no HR


def test_sdk_mode_outlives_a_lost_link_and_is_asked_for_again() -> None:
    clock = FakeClock()
    device, rows = verity_ppg(clock, 20.0, rate=176.0, sdk_mode=True, sdk_settings={Measurement.PPG: SDK_PPG},
                              disconnect_after=[10])
    run = run_session([device], clock, device="2B3C4D5E", sdk_mode=True, ppg_rate=176)
    assert device.connections == 2 and writes(device).count("0209") == 2  # ALREADY_IN_STATE the 2nd time
    assert run.status == 0 and not device.sdk_mode  # switched off before the last disconnect
    assert 10 * 42 < run.session.status()["streams"]["ppg"]["samples"] < len(rows)  # frames lost while down


def test_sdk_mode_on_a_device_without_it_stops_with_status_2() -> None:
    clock = FakeClock()
    device, _ = h10(clock, 5.0)
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg"], sdk_mode=True)
    assert run.status == 2 and "no SDK mode" in run.session.error and NAME in run.session.error
    assert device.connections == 1 and "0209" not in writes(device)


def test_an_sdk_rate_without_sdk_mode_names_the_option() -> None:
    clock = FakeClock()
    device, _ = verity_ppg(clock, 5.0, sdk_mode=True, sdk_settings={Measurement.PPG: SDK_PPG})
    run = run_session([device], clock, device="2B3C4D5E", streams=["ppg"], ppg_rate=176)
    assert run.status == 2 and "ppg_rate 176" in run.session.error and "--sdk-mode" in run.session.error


@pytest.mark.parametrize("streams", [["ppg", "hr"], ["ppi"], ["rr"]])
def test_sdk_mode_with_computed_streams_is_a_configuration_error(streams: list[str]) -> None:
    with pytest.raises(ValueError, match="computes no"):
        PolarConfig(device="2B3C4D5E", sdk_mode=True, streams=streams)

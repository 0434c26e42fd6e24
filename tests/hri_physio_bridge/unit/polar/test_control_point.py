"""PMD control point: the issue's start request and response, settings, features, statuses, fuzzing."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.protocol import Measurement, PolarProtocolError

START_ECG = bytes.fromhex("02 00 00 01 82 00 01 01 0E 00")


def test_start_ecg_request_vector() -> None:
    request = cp.start_request(
        Measurement.ECG, {cp.SettingType.SAMPLE_RATE: 130, cp.SettingType.RESOLUTION: 14}
    )
    assert request == START_ECG


def test_start_ecg_response_vector_is_success() -> None:
    response = cp.decode_control_point(bytes.fromhex("F0 02 00 00 00 00"))
    assert isinstance(response, cp.ControlPointResponse)
    assert (response.op, response.measurement, response.status, response.more) == (2, 0, 0, False)
    assert response.ok and response.ok_for_start()


def test_already_in_state_counts_as_started() -> None:
    response = cp.decode_control_point(bytes.fromhex("F0 02 02 06 00"))
    assert not response.ok and response.ok_for_start()
    refused = cp.decode_control_point(bytes.fromhex("F0 02 02 08"))
    assert not refused.ok_for_start()


def test_get_settings_and_stop_requests() -> None:
    assert cp.get_settings_request(Measurement.ACC) == b"\x01\x02"
    assert cp.stop_request(Measurement.ECG) == b"\x03\x00"


def test_settings_response_with_more_and_factor() -> None:
    params = cp.encode_offered_settings(
        {
            cp.SettingType.SAMPLE_RATE: [25, 50, 100, 200],
            cp.SettingType.RESOLUTION: [16],
            cp.SettingType.RANGE: [2, 4, 8],
            cp.SettingType.FACTOR: [0.244140625],
        }
    )
    response = cp.decode_control_point(
        cp.encode_response(cp.OpCode.GET_SETTINGS, Measurement.ACC, params=params, more=True)
    )
    assert response.more
    decoded = cp.decode_settings(response.params)
    assert decoded[cp.SettingType.SAMPLE_RATE] == [25, 50, 100, 200]
    assert decoded[cp.SettingType.RANGE] == [2, 4, 8]
    assert decoded[cp.SettingType.FACTOR] == [0.244140625]


def test_every_status_has_a_clear_message() -> None:
    for status in cp.Status:
        assert cp.status_text(status) and "unknown" not in cp.status_text(status)
    error = cp.ControlPointRefused(cp.OpCode.START, Measurement.ACC, cp.Status.INVALID_SAMPLE_RATE)
    assert "start ACC" in str(error) and "sample rate" in str(error) and "status 8" in str(error)
    assert "unknown status 99" in cp.status_text(99)


def test_device_stop_indication() -> None:
    message = cp.decode_control_point(bytes([0x01, 0x00, 0x02]))
    assert message == cp.StopIndication((0, 2))


def test_features() -> None:
    assert cp.decode_features(bytes.fromhex("0F 05 00")) == {Measurement.ECG, Measurement.ACC}
    assert cp.decode_features(cp.encode_features({1, 2, 3})) == {
        Measurement.PPG,
        Measurement.ACC,
        Measurement.PPI,
    }
    with pytest.raises(PolarProtocolError):
        cp.decode_features(b"\xf0\x01")


@pytest.mark.parametrize("data", [b"", b"\x42", b"\xf0\x02\x00"])
def test_malformed_indications(data: bytes) -> None:
    with pytest.raises(PolarProtocolError):
        cp.decode_control_point(data)


@pytest.mark.parametrize(
    "params, problem",
    [
        (b"\x00\x01\x82\x00\x01", "entry header at byte 4"),
        (b"\x09\x01\x00", "unknown setting"),
        (b"\x00\x02\x82\x00", "past the end"),
    ],
)
def test_malformed_settings(params: bytes, problem: str) -> None:
    with pytest.raises(PolarProtocolError, match=problem):
        cp.decode_settings(params)


def test_encode_settings_refuses_values_that_do_not_fit() -> None:
    with pytest.raises(ValueError, match="does not fit"):
        cp.encode_settings({cp.SettingType.CHANNELS: 300})


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=40))
def test_fuzz_control_point(data: bytes) -> None:
    for parse in (cp.decode_control_point, cp.decode_settings, cp.decode_features):
        with contextlib.suppress(PolarProtocolError):
            parse(data)


@pytest.mark.parametrize("params", [b"", b"\x00", b"\x05"])
def test_one_parameter_byte_or_less_is_no_settings(params: bytes) -> None:
    """An H10 answers "start ECG" with F0 02 00 00 00 00: one parameter byte that carries nothing."""
    assert cp.decode_settings(params) == {}
    response = cp.decode_control_point(bytes([0xF0, 0x02, 0x00, 0x00, 0x00]) + params)
    assert response.ok and cp.decode_settings(response.params) == {}


def test_start_answer_with_a_conversion_factor() -> None:
    response = cp.decode_control_point(bytes.fromhex("F0 02 01 00 00 05 01 00 00 80 3F"))
    assert cp.decode_settings(response.params) == {cp.SettingType.FACTOR: [1.0]}


@pytest.mark.parametrize(
    "answer, op, measurement, expected",
    [
        ("F0 01 00 00 00 00 01 82 00", cp.OpCode.GET_SETTINGS, Measurement.ECG, True),  # named, success
        ("F0 00 01 0A", cp.OpCode.GET_SETTINGS, Measurement.PPG, True),  # error naming no op
        ("F0 00 01 0A", cp.OpCode.START, Measurement.PPG, True),
        ("F0 00 01 0A", cp.OpCode.GET_SETTINGS, Measurement.ECG, False),  # another measurement type
        ("F0 00 02 00 00", cp.OpCode.START, Measurement.ACC, False),  # a success must name its op
        ("F0 03 00 00 00", cp.OpCode.START, Measurement.ECG, False),  # the answer to another request
        ("F0 02 82 0C", cp.OpCode.START, Measurement.ACC, True),  # bit 7 (offline) is not the type
    ],
)
def test_an_answer_matches_its_request_by_measurement_type(
    answer: str, op: int, measurement: int, expected: bool
) -> None:
    response = cp.decode_control_point(bytes.fromhex(answer))
    assert cp.answers(response, op, measurement) is expected


def test_sdk_mode_requests_and_feature_bit() -> None:
    assert cp.sdk_mode_request(True) == bytes.fromhex("02 09")
    assert cp.sdk_mode_request(False) == bytes.fromhex("03 09")
    verity = bytes.fromhex("0F 6E 02 00")  # PPG, ACC, PPI, gyro, magnetometer + SDK mode
    assert cp.has_sdk_mode(verity) and not cp.has_sdk_mode(bytes.fromhex("0F 05 00 00"))
    assert cp.decode_features(verity) == {
        Measurement.PPG, Measurement.ACC, Measurement.PPI, Measurement.GYRO, Measurement.MAGNETOMETER
    }
    assert cp.has_sdk_mode(cp.encode_features({Measurement.PPG}, sdk_mode=True))
    refused = cp.ControlPointRefused(cp.OpCode.START, cp.SDK_MODE, cp.Status.NOT_SUPPORTED)
    assert str(refused).startswith("start SDK mode: the device does not support")

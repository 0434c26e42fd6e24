"""The PMD control point: requests, responses, settings, features and the device's stop indication.

Requests are ``[op][measurement][settings]`` (op 1 get settings, 2 start, 3 stop); the device
answers each with an indication ``F0 op measurement status more params``. Settings are
``[setting type][count][count values]`` with a fixed width per type. Reading the control point
gives the features (``0F`` then a bit mask of the measurements the device offers). A
device-initiated indication ``01 <measurement...>`` says the device stopped those streams.
SDK mode (Verity Sense: wider rates and ranges, no HR or PPI) is the pseudo-measurement 9,
started and stopped like a stream (``02 09`` / ``03 09``); feature bit 1 of the second mask byte
says a device has it.

Real devices do not always name the request an error answers: an H10 at the default MTU answers
``F0 00 01 0A`` (op 0, measurement 1, INVALID_MTU). :func:`answers` matches such an error to the
pending request for the same measurement type.
Pure Python; written from Polar's "Polar Measurement Data" documentation.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum

from hri_physio_bridge.polar.protocol import Measurement, PolarProtocolError

RESPONSE_CODE = 0xF0
FEATURES_CODE = 0x0F
STOP_INDICATION_CODE = 0x01


class OpCode(IntEnum):
    GET_SETTINGS = 1
    START = 2
    STOP = 3
    GET_SDK_MODE_SETTINGS = 4
    GET_MEASUREMENT_STATUS = 5
    GET_SDK_MODE_STATUS = 6


#: The pseudo-measurement that switches SDK mode on (start) and off (stop).
SDK_MODE = 9
#: Bits of the measurement byte that name the measurement (bit 7 marks offline recording).
MEASUREMENT_MASK = 0x3F


class SettingType(IntEnum):
    SAMPLE_RATE = 0  # Hz, u16
    RESOLUTION = 1  # bits, u16
    RANGE = 2  # +- unit (G for ACC), u16
    RANGE_MILLIUNIT = 3  # u32
    CHANNELS = 4  # u8
    FACTOR = 5  # f32 conversion factor, only in responses
    SECURITY = 6  # 16 bytes


SETTING_WIDTH: dict[SettingType, int] = {
    SettingType.SAMPLE_RATE: 2,
    SettingType.RESOLUTION: 2,
    SettingType.RANGE: 2,
    SettingType.RANGE_MILLIUNIT: 4,
    SettingType.CHANNELS: 1,
    SettingType.FACTOR: 4,
    SettingType.SECURITY: 16,
}


class Status(IntEnum):
    SUCCESS = 0
    INVALID_OP_CODE = 1
    INVALID_MEASUREMENT_TYPE = 2
    NOT_SUPPORTED = 3
    INVALID_LENGTH = 4
    INVALID_PARAMETER = 5
    ALREADY_IN_STATE = 6
    INVALID_RESOLUTION = 7
    INVALID_SAMPLE_RATE = 8
    INVALID_RANGE = 9
    INVALID_MTU = 10
    INVALID_NUMBER_OF_CHANNELS = 11
    INVALID_STATE = 12
    DEVICE_IN_CHARGER = 13
    DISK_FULL = 14


STATUS_TEXT: dict[int, str] = {
    Status.SUCCESS: "success",
    Status.INVALID_OP_CODE: "the device does not know this request (invalid op code)",
    Status.INVALID_MEASUREMENT_TYPE: "the device does not know this measurement type",
    Status.NOT_SUPPORTED: "the device does not support this measurement",
    Status.INVALID_LENGTH: "the request has an invalid length",
    Status.INVALID_PARAMETER: "the request has an invalid parameter",
    Status.ALREADY_IN_STATE: "the measurement is already in that state",
    Status.INVALID_RESOLUTION: "the device does not support this resolution",
    Status.INVALID_SAMPLE_RATE: "the device does not support this sample rate",
    Status.INVALID_RANGE: "the device does not support this range",
    Status.INVALID_MTU: "the connection's MTU is too small for this stream",
    Status.INVALID_NUMBER_OF_CHANNELS: "the device does not support this number of channels",
    Status.INVALID_STATE: "the device is in a state that does not allow this (another client streaming?)",
    Status.DEVICE_IN_CHARGER: "the device is in its charger",
    Status.DISK_FULL: "the device's memory is full",
}

#: Feature bits of the measurements the streamer knows: bit i of the first mask byte after 0F.
_FEATURE_BITS = {
    0: Measurement.ECG,
    1: Measurement.PPG,
    2: Measurement.ACC,
    3: Measurement.PPI,
    5: Measurement.GYRO,
    6: Measurement.MAGNETOMETER,
}
#: SDK mode: bit 1 of the second mask byte.
_SDK_MODE_BIT = 8 + 1


def status_text(status: int) -> str:
    return STATUS_TEXT.get(status, f"unknown status {status}")


class ControlPointRefused(RuntimeError):
    """The device answered a request with an error status."""

    def __init__(self, op: int, measurement: int, status: int) -> None:
        self.op, self.measurement, self.status = op, measurement, status
        super().__init__(f"{request_name(op, measurement)}: {status_text(status)} (status {status})")


def request_name(op: int, measurement: int) -> str:
    """``start ECG``, ``get settings of PPG``, ``stop SDK mode``..."""
    return f"{_op_name(op)} {_measurement_name(measurement)}"


def _op_name(op: int) -> str:
    return {OpCode.GET_SETTINGS: "get settings of", OpCode.START: "start", OpCode.STOP: "stop"}.get(
        op, f"op {op}"
    )


def _measurement_name(measurement: int) -> str:
    if measurement & MEASUREMENT_MASK == SDK_MODE:
        return "SDK mode"
    try:
        return Measurement(measurement & MEASUREMENT_MASK).name
    except ValueError:
        return f"measurement {measurement}"


# ----------------------------------------------------------------------------------------------
# Requests
def get_settings_request(measurement: int) -> bytes:
    return bytes([OpCode.GET_SETTINGS, measurement])


def start_request(measurement: int, settings: Mapping[SettingType, int] | None = None) -> bytes:
    """``02 <measurement> <settings>``; e.g. ECG at 130 Hz / 14 bit: ``02 00 00 01 82 00 01 01 0E 00``."""
    return bytes([OpCode.START, measurement]) + encode_settings(settings or {})


def stop_request(measurement: int) -> bytes:
    return bytes([OpCode.STOP, measurement])


def sdk_mode_request(enable: bool) -> bytes:
    """``02 09`` switches SDK mode on, ``03 09`` off (the device answers NOT_SUPPORTED without it)."""
    return bytes([OpCode.START if enable else OpCode.STOP, SDK_MODE])


def encode_settings(settings: Mapping[SettingType, int]) -> bytes:
    """Selected settings, one value each, in setting-type order (FACTOR is never sent)."""
    out = bytearray()
    for kind in sorted(settings):
        kind = SettingType(kind)
        if kind == SettingType.FACTOR:
            continue
        width = SETTING_WIDTH[kind]
        value = int(settings[kind])
        if not 0 <= value < 1 << (8 * width):
            raise ValueError(f"{kind.name.lower()} {value} does not fit in {width} byte(s)")
        out += bytes([kind, 1]) + value.to_bytes(width, "little")
    return bytes(out)


# ----------------------------------------------------------------------------------------------
# Responses and indications
@dataclass(frozen=True)
class ControlPointResponse:
    op: int
    measurement: int
    status: int
    more: bool
    params: bytes = b""

    @property
    def ok(self) -> bool:
        return self.status == Status.SUCCESS

    def ok_for_start(self) -> bool:
        """Success, or "already in state" (the stream is running already)."""
        return self.status in (Status.SUCCESS, Status.ALREADY_IN_STATE)


@dataclass(frozen=True)
class StopIndication:
    """The device stopped these measurements by itself."""

    measurements: tuple[int, ...] = field(default_factory=tuple)


def decode_control_point(data: bytes) -> ControlPointResponse | StopIndication:
    """A control point indication: a response (``F0 ...``) or a device-initiated stop (``01 ...``)."""
    data = bytes(data)
    if not data:
        raise PolarProtocolError("empty control point indication")
    if data[0] == STOP_INDICATION_CODE:
        return StopIndication(tuple(b & 0x3F for b in data[1:]))
    if data[0] != RESPONSE_CODE:
        raise PolarProtocolError(f"control point indication starts with {data[0]:#04x}, not a response (F0)")
    if len(data) < 4:
        raise PolarProtocolError(f"control point response of {len(data)} byte(s); need at least 4")
    status = data[3]
    more = status == Status.SUCCESS and len(data) > 4 and data[4] != 0
    params = data[5:] if status == Status.SUCCESS else b""
    return ControlPointResponse(op=data[1], measurement=data[2], status=status, more=more, params=params)


def answers(response: ControlPointResponse, op: int, measurement: int) -> bool:
    """Whether ``response`` answers the request ``op`` for ``measurement``.

    The same op and measurement type; or an error status for the same measurement type under
    another op (devices answer some errors with op 0: ``F0 00 01 0A``).
    """
    same_measurement = (response.measurement & MEASUREMENT_MASK) == (measurement & MEASUREMENT_MASK)
    if not same_measurement:
        return False
    return response.op == op or response.status != Status.SUCCESS


def decode_settings(params: bytes) -> dict[SettingType, list[int | float]]:
    """The settings in a get-settings or start response: every offered value per setting type.

    One byte or less is no settings: an H10 answers a start with ``F0 02 00 00 00 00``, whose
    single parameter byte carries nothing (Polar's SDK reads it the same way).
    """
    params = bytes(params)
    out: dict[SettingType, list[int | float]] = {}
    if len(params) <= 1:
        return out
    offset = 0
    while offset < len(params):
        if offset + 2 > len(params):
            raise PolarProtocolError(f"settings end inside an entry header at byte {offset}")
        try:
            kind = SettingType(params[offset])
        except ValueError:
            raise PolarProtocolError(f"unknown setting type {params[offset]} at byte {offset}") from None
        count = params[offset + 1]
        offset += 2
        width = SETTING_WIDTH[kind]
        if offset + count * width > len(params):
            raise PolarProtocolError(f"setting {kind.name.lower()} declares {count} value(s) past the end")
        values: list[int | float] = []
        for _ in range(count):
            chunk = params[offset : offset + width]
            if kind == SettingType.FACTOR:
                values.append(struct.unpack("<f", chunk)[0])
            elif kind == SettingType.SECURITY:
                values.append(int.from_bytes(chunk, "little"))
            else:
                values.append(int.from_bytes(chunk, "little"))
            offset += width
        out.setdefault(kind, []).extend(values)
    return out


def decode_features(data: bytes) -> set[Measurement]:
    """The measurements a device offers, from a read of the control point (``0F <bits> ...``)."""
    data = bytes(data)
    if len(data) < 2 or data[0] != FEATURES_CODE:
        raise PolarProtocolError(f"control point read {data.hex(' ')!r} is not a feature list (0F ...)")
    return {measurement for bit, measurement in _FEATURE_BITS.items() if data[1] & (1 << bit)}


def has_sdk_mode(data: bytes) -> bool:
    """Whether a feature read (``0F <mask> <mask> ...``) offers SDK mode."""
    data = bytes(data)
    return len(data) > 2 and data[0] == FEATURES_CODE and bool(data[2] & (1 << (_SDK_MODE_BIT - 8)))


def encode_features(measurements: set[int], sdk_mode: bool = False) -> bytes:
    """The feature read a device with ``measurements`` answers (used by the fake device)."""
    mask = 0
    for bit, measurement in _FEATURE_BITS.items():
        if measurement in measurements:
            mask |= 1 << bit
    return bytes([FEATURES_CODE, mask, (1 << (_SDK_MODE_BIT - 8)) if sdk_mode else 0])


def encode_response(
    op: int, measurement: int, status: int = Status.SUCCESS, params: bytes = b"", more: bool = False
) -> bytes:
    """A device's response indication (used by the fake device and the synthetic capture)."""
    return bytes([RESPONSE_CODE, op, measurement, status, 1 if more else 0]) + bytes(params)


def encode_offered_settings(settings: Mapping[SettingType, list[int | float]]) -> bytes:
    """A get-settings response's parameters: every offered value per setting type."""
    out = bytearray()
    for kind in sorted(settings):
        kind = SettingType(kind)
        values = settings[kind]
        out += bytes([kind, len(values)])
        for value in values:
            if kind == SettingType.FACTOR:
                out += struct.pack("<f", float(value))
            else:
                out += int(value).to_bytes(SETTING_WIDTH[kind], "little")
    return bytes(out)

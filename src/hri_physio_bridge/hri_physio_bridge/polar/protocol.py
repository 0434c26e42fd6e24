"""Decoding Polar notifications: Heart Rate Measurement (0x2A37) and PMD data frames.

Written from Polar's published BLE SDK documentation (``online_measurement.pdf``, "Polar
Measurement Data") and the Bluetooth Heart Rate Service specification. Pure Python: any tool can
decode a captured notification with it, no Bluetooth stack needed.

Public surface:

- :func:`decode_heart_rate` -> :class:`HeartRate` (``bpm``, ``contact_supported``, ``contact``,
  ``energy_kj``, ``rr_1024``);
- :func:`decode_pmd_frame` -> :class:`PmdFrame` (``measurement``, ``timestamp_ns``, ``frame_type``,
  ``compressed``, ``samples``);
- :class:`PolarProtocolError`, the only exception the parsers raise on malformed input.

PMD data frame layout: ``[type][u64 LE timestamp ns of the LAST sample, epoch 2000-01-01]
[frame type: bit 7 = delta-compressed, low 7 bits = type][payload]``. Raw payloads are
little-endian signed samples of a fixed width; compressed payloads are a reference sample
(``channels`` values of ``ceil(resolution / 8)`` bytes) followed by blocks
``[bit width][count][count * channels deltas of bit width, LSB first]``, each delta sign-extended
and added to the previous sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

__all__ = [
    "HeartRate",
    "Measurement",
    "PmdFrame",
    "PolarProtocolError",
    "decode_heart_rate",
    "decode_pmd_frame",
]


class PolarProtocolError(ValueError):
    """A notification that is not what the protocol says (too short, bad length, unknown type)."""


class Measurement(IntEnum):
    """PMD measurement types (the low 6 bits of a data frame's first byte)."""

    ECG = 0
    PPG = 1
    ACC = 2
    PPI = 3
    GYRO = 5
    MAGNETOMETER = 6


#: Bytes before the payload of a PMD data frame: type, u64 timestamp, frame type.
PMD_HEADER = 10
_MEASUREMENT_MASK = 0x3F
_COMPRESSED_BIT = 0x80
_FRAME_TYPE_MASK = 0x7F
#: Widest delta a compressed block may declare (the SDK decodes into 32-bit integers).
MAX_DELTA_BITS = 32


# ----------------------------------------------------------------------------------------------
# Heart Rate Measurement (Bluetooth SIG characteristic 0x2A37)
@dataclass(frozen=True)
class HeartRate:
    """One Heart Rate Measurement notification."""

    bpm: int
    #: Whether the sensor reports skin contact at all (flags bit 2).
    contact_supported: bool
    #: Skin contact detected (flags bit 1); None when the sensor does not report contact.
    contact: bool | None
    #: Cumulative energy expended in kJ (flags bit 3), None when absent.
    energy_kj: int | None
    #: RR intervals in 1/1024 s, oldest first (flags bit 4).
    rr_1024: list[int] = field(default_factory=list)

    @property
    def rr_ms(self) -> list[float]:
        """The RR intervals in milliseconds."""
        return [rr * 1000.0 / 1024.0 for rr in self.rr_1024]


def decode_heart_rate(data: bytes) -> HeartRate:
    """Decode a Heart Rate Measurement notification (flags, u8/u16 bpm, energy, RR list)."""
    data = bytes(data)
    if len(data) < 2:
        raise PolarProtocolError(f"heart rate notification of {len(data)} byte(s); need at least 2")
    flags = data[0]
    offset = 1
    if flags & 0x01:
        if len(data) < 3:
            raise PolarProtocolError("heart rate notification declares a 16-bit value but has 2 bytes")
        bpm = int.from_bytes(data[1:3], "little")
        offset = 3
    else:
        bpm = data[1]
        offset = 2
    contact_supported = bool(flags & 0x04)
    contact = bool(flags & 0x02) if contact_supported else None
    energy: int | None = None
    if flags & 0x08:
        if len(data) < offset + 2:
            raise PolarProtocolError("heart rate notification declares energy expended but ends before it")
        energy = int.from_bytes(data[offset : offset + 2], "little")
        offset += 2
    rr: list[int] = []
    if flags & 0x10:
        rest = data[offset:]
        if len(rest) % 2:
            raise PolarProtocolError(f"heart rate notification has {len(rest)} RR byte(s); need pairs")
        rr = [int.from_bytes(rest[i : i + 2], "little") for i in range(0, len(rest), 2)]
    elif len(data) > offset:
        raise PolarProtocolError(
            f"heart rate notification has {len(data) - offset} unexpected trailing byte(s)"
        )
    return HeartRate(bpm, contact_supported, contact, energy, rr)


# ----------------------------------------------------------------------------------------------
# PMD data frames
@dataclass(frozen=True)
class PmdFrame:
    """One decoded PMD data notification. ``samples`` are raw integers, one list per sample."""

    measurement: int
    #: Device time of the LAST sample, ns since 2000-01-01T00:00:00Z (0 when the device has none).
    timestamp_ns: int
    #: Frame type (low 7 bits of byte 9).
    frame_type: int
    compressed: bool
    samples: list[list[int]]

    @property
    def sample_count(self) -> int:
        return len(self.samples)


@dataclass(frozen=True)
class _RawLayout:
    width: int  # bytes per value
    values: int  # values per sample
    signed: bool = True


#: Raw (uncompressed) frame layouts by (measurement, frame type).
_RAW: dict[tuple[int, int], _RawLayout] = {
    (Measurement.ECG, 0): _RawLayout(3, 1),  # µV, i24
    (Measurement.PPG, 0): _RawLayout(3, 4),  # OH1: PPG0..2 + ambient, i24
    (Measurement.ACC, 0): _RawLayout(1, 3),  # i8 x, y, z
    (Measurement.ACC, 1): _RawLayout(2, 3),  # i16 x, y, z (mG)
    (Measurement.ACC, 2): _RawLayout(3, 3),  # i24 x, y, z (mG)
}

#: Compressed frames: (channels, resolution in bits) implied when the settings give none.
_COMPRESSED: dict[tuple[int, int], tuple[int, int]] = {
    (Measurement.PPG, 0): (4, 24),  # Verity Sense: PPG0..2 + ambient (device says 22 bits, 3 bytes)
    (Measurement.ACC, 0): (3, 16),
    (Measurement.ACC, 1): (3, 16),
}

#: PPI record: u8 hr, u16 interval ms, u16 error estimate ms, u8 flags.
PPI_RECORD = 6


def decode_pmd_frame(data: bytes, channels: int | None = None, resolution: int | None = None) -> PmdFrame:
    """Decode one PMD data notification.

    ``channels`` and ``resolution`` (bits) come from the stream's settings for compressed frames
    and default to what the measurement and frame type imply. PPI rows are
    ``[hr, ppi_ms, error_estimate_ms, flags]``.
    """
    data = bytes(data)
    if len(data) <= PMD_HEADER:
        raise PolarProtocolError(
            f"PMD frame of {len(data)} byte(s); need a {PMD_HEADER}-byte header and data"
        )
    try:
        measurement = Measurement(data[0] & _MEASUREMENT_MASK)
    except ValueError:
        raise PolarProtocolError(f"unknown PMD measurement type {data[0] & _MEASUREMENT_MASK}") from None
    timestamp = int.from_bytes(data[1:9], "little")
    compressed = bool(data[9] & _COMPRESSED_BIT)
    frame_type = data[9] & _FRAME_TYPE_MASK
    payload = data[PMD_HEADER:]
    key = (int(measurement), frame_type)
    if measurement == Measurement.PPI and frame_type == 0 and not compressed:
        samples = _decode_ppi(payload)
    elif compressed and key in _COMPRESSED:
        default_channels, default_resolution = _COMPRESSED[key]
        samples = decode_delta_payload(
            payload, channels or default_channels, resolution or default_resolution
        )
    elif not compressed and key in _RAW:
        samples = _decode_raw(payload, _RAW[key])
    else:
        kind = "compressed" if compressed else "raw"
        raise PolarProtocolError(f"unsupported {measurement.name} {kind} frame type {frame_type}")
    return PmdFrame(int(measurement), timestamp, frame_type, compressed, samples)


def _signed(value: int, bits: int) -> int:
    return value - (1 << bits) if value & (1 << (bits - 1)) else value


def _decode_raw(payload: bytes, layout: _RawLayout) -> list[list[int]]:
    step = layout.width * layout.values
    if len(payload) % step:
        raise PolarProtocolError(
            f"raw payload of {len(payload)} byte(s) is not a whole number of {step}-byte samples"
        )
    bits = layout.width * 8
    out = []
    for start in range(0, len(payload), step):
        row = []
        for v in range(layout.values):
            offset = start + v * layout.width
            value = int.from_bytes(payload[offset : offset + layout.width], "little")
            row.append(_signed(value, bits) if layout.signed else value)
        out.append(row)
    return out


def _decode_ppi(payload: bytes) -> list[list[int]]:
    if len(payload) % PPI_RECORD:
        raise PolarProtocolError(
            f"PPI payload of {len(payload)} byte(s) is not a whole number of 6-byte records"
        )
    return [
        [
            payload[i],
            int.from_bytes(payload[i + 1 : i + 3], "little"),
            int.from_bytes(payload[i + 3 : i + 5], "little"),
            payload[i + 5],
        ]
        for i in range(0, len(payload), PPI_RECORD)
    ]


def decode_delta_payload(payload: bytes, channels: int, resolution: int) -> list[list[int]]:
    """Samples of a delta-compressed payload: the reference sample, then every block's deltas added up.

    The reference has ``channels`` little-endian values of ``ceil(resolution / 8)`` bytes,
    sign-extended at their byte width (identical to ``resolution`` bits for every valid value).
    A block of width 0 repeats the previous sample ``count`` times.
    """
    if not isinstance(channels, int) or not 1 <= channels <= 64:
        raise PolarProtocolError(f"channels must be 1..64, got {channels!r}")
    if not isinstance(resolution, int) or not 1 <= resolution <= 32:
        raise PolarProtocolError(f"resolution must be 1..32 bits, got {resolution!r}")
    width = (resolution + 7) // 8
    ref_size = channels * width
    if len(payload) < ref_size:
        raise PolarProtocolError(
            f"compressed payload of {len(payload)} byte(s) is shorter than its "
            f"{ref_size}-byte reference sample"
        )
    previous = [
        _signed(int.from_bytes(payload[c * width : (c + 1) * width], "little"), width * 8)
        for c in range(channels)
    ]
    samples = [previous]
    offset = ref_size
    while offset < len(payload):
        if offset + 2 > len(payload):
            raise PolarProtocolError(f"compressed payload ends inside a block header at byte {offset}")
        bits, count = payload[offset], payload[offset + 1]
        offset += 2
        if bits > MAX_DELTA_BITS:
            raise PolarProtocolError(f"delta width of {bits} bits (at most {MAX_DELTA_BITS})")
        nbytes = (bits * count * channels + 7) // 8
        if offset + nbytes > len(payload):
            raise PolarProtocolError(
                f"compressed block of {count} sample(s) x {bits} bits needs {nbytes} byte(s), "
                f"{len(payload) - offset} left"
            )
        block = int.from_bytes(payload[offset : offset + nbytes], "little")  # bit i of the block = bit i here
        offset += nbytes
        mask = (1 << bits) - 1
        position = 0
        for _ in range(count):
            row = []
            for c in range(channels):
                delta = (block >> position) & mask if bits else 0
                position += bits
                row.append(previous[c] + (_signed(delta, bits) if bits else 0))
            samples.append(row)
            previous = row
    return samples

"""Building Polar notifications byte by byte: the inverse of :mod:`protocol`, for the fake device.

Used to script the fake BLE device, to build the synthetic capture shipped in
``tests/data/polar`` and to round-trip the decoders in tests. Nothing here talks to a device.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from hri_physio_bridge.polar.protocol import Measurement


def _field(value: int, width: int) -> bytes:
    """Little-endian two's complement in ``width`` bytes; ValueError when it does not fit."""
    limit = 1 << (8 * width - 1)
    if not -limit <= value < limit:
        raise ValueError(f"{value} does not fit in a signed {8 * width}-bit field")
    return (value & ((1 << (8 * width)) - 1)).to_bytes(width, "little")


def encode_heart_rate(
    bpm: int,
    rr_1024: Sequence[int] = (),
    *,
    contact: bool | None = None,
    energy_kj: int | None = None,
    wide: bool = False,
) -> bytes:
    """A Heart Rate Measurement notification (0x2A37)."""
    flags = 0
    body = bytearray()
    if wide or bpm > 255:
        flags |= 0x01
        body += bpm.to_bytes(2, "little")
    else:
        body.append(bpm)
    if contact is not None:
        flags |= 0x04 | (0x02 if contact else 0)
    if energy_kj is not None:
        flags |= 0x08
        body += energy_kj.to_bytes(2, "little")
    if rr_1024:
        flags |= 0x10
        for rr in rr_1024:
            body += rr.to_bytes(2, "little")
    return bytes([flags]) + bytes(body)


def pmd_header(measurement: int, timestamp_ns: int, frame_type: int, compressed: bool = False) -> bytes:
    return (
        bytes([measurement])
        + timestamp_ns.to_bytes(8, "little")
        + bytes([(frame_type & 0x7F) | (0x80 if compressed else 0)])
    )


def encode_raw_frame(
    measurement: int, timestamp_ns: int, frame_type: int, samples: Sequence[Sequence[int]], width: int
) -> bytes:
    """An uncompressed frame of ``width``-byte signed values."""
    payload = b"".join(_field(v, width) for row in samples for v in row)
    return pmd_header(measurement, timestamp_ns, frame_type) + payload


def encode_ecg_frame(timestamp_ns: int, microvolts: Sequence[int]) -> bytes:
    return encode_raw_frame(Measurement.ECG, timestamp_ns, 0, [[v] for v in microvolts], 3)


def encode_acc_frame(timestamp_ns: int, samples: Sequence[Sequence[int]], width: int = 2) -> bytes:
    """Raw ACC: frame type 0/1/2 for 1/2/3-byte values."""
    return encode_raw_frame(Measurement.ACC, timestamp_ns, width - 1, samples, width)


def encode_ppg_frame(timestamp_ns: int, samples: Sequence[Sequence[int]]) -> bytes:
    """OH1 raw PPG: PPG0, PPG1, PPG2, ambient as 24-bit values."""
    return encode_raw_frame(Measurement.PPG, timestamp_ns, 0, samples, 3)


def encode_ppi_frame(timestamp_ns: int, records: Sequence[Sequence[int]]) -> bytes:
    """PPI records ``[hr, ppi_ms, error_ms, flags]``."""
    payload = b"".join(
        bytes([hr]) + ppi.to_bytes(2, "little") + err.to_bytes(2, "little") + bytes([flags])
        for hr, ppi, err, flags in records
    )
    return pmd_header(Measurement.PPI, timestamp_ns, 0) + payload


def _bits_needed(value: int) -> int:
    """Bits of the narrowest two's complement field holding ``value``."""
    return max(1, (value.bit_length() if value >= 0 else (~value).bit_length()) + 1)


def encode_delta_payload(
    samples: Sequence[Sequence[int]],
    resolution: int,
    block_sizes: Sequence[int] | None = None,
    widths: Sequence[int] | None = None,
) -> bytes:
    """A compressed payload: the first sample as reference, the rest as delta blocks.

    ``block_sizes`` splits the deltas into blocks (default: one block); ``widths`` forces each
    block's bit width (default: the narrowest that holds its deltas).
    """
    if not samples:
        raise ValueError("a compressed payload needs at least the reference sample")
    channels = len(samples[0])
    width_bytes = (resolution + 7) // 8
    out = bytearray(b"".join(_field(v, width_bytes) for v in samples[0]))
    deltas = [[b - a for a, b in zip(prev, cur, strict=True)] for prev, cur in itertools.pairwise(samples)]
    sizes = list(block_sizes) if block_sizes is not None else ([len(deltas)] if deltas else [])
    if sum(sizes) != len(deltas):
        raise ValueError(f"block sizes add up to {sum(sizes)}, there are {len(deltas)} deltas")
    start = 0
    for index, size in enumerate(sizes):
        block = deltas[start : start + size]
        start += size
        needed = max((_bits_needed(v) for row in block for v in row), default=1)
        bits = widths[index] if widths is not None else needed
        if bits < needed:
            raise ValueError(f"block {index} needs {needed} bits, {bits} given")
        packed, position = 0, 0
        for row in block:
            for v in row:
                packed |= (v & ((1 << bits) - 1)) << position
                position += bits
        out += bytes([bits, len(block)]) + packed.to_bytes((position + 7) // 8, "little")
    if any(len(row) != channels for row in samples):
        raise ValueError("every sample needs the same number of channels")
    return bytes(out)


def encode_compressed_frame(
    measurement: int,
    timestamp_ns: int,
    frame_type: int,
    samples: Sequence[Sequence[int]],
    resolution: int,
    block_sizes: Sequence[int] | None = None,
    widths: Sequence[int] | None = None,
) -> bytes:
    return pmd_header(measurement, timestamp_ns, frame_type, compressed=True) + encode_delta_payload(
        samples, resolution, block_sizes, widths
    )

"""The Polar parsers: the issue's test vectors, delta frames of odd widths, malformed input, fuzzing."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hri_physio_bridge.polar.encode import (
    encode_acc_frame,
    encode_compressed_frame,
    encode_delta_payload,
    encode_ecg_frame,
    encode_heart_rate,
    encode_ppg_frame,
    encode_ppi_frame,
)
from hri_physio_bridge.polar.gatt import decode_battery
from hri_physio_bridge.polar.protocol import (
    Measurement,
    PolarProtocolError,
    decode_delta_payload,
    decode_heart_rate,
    decode_pmd_frame,
)

HR_VECTOR = bytes.fromhex("10 48 DB 03 C5 03")
ECG_VECTOR = bytes.fromhex(
    "00 EA 1C AC CC 99 43 52 08 00 68 00 00 58 00 00 46 00 00 3D 00 00 32 00 00 26 00 00 16 00 00 04 00 00"
)
ACC_VECTOR = bytes.fromhex("02 EA 54 A2 42 8B 45 52 08 01 45 FF E4 FF B5 03 45 FF E4 FF B8 03")


# ----------------------------------------------------------------------------------------------
# The vectors
def test_heart_rate_vector() -> None:
    hr = decode_heart_rate(HR_VECTOR)
    assert hr.bpm == 72
    assert hr.rr_1024 == [987, 965]
    assert [round(ms, 1) for ms in hr.rr_ms] == [963.9, 942.4]
    assert hr.energy_kj is None
    assert hr.contact_supported is False and hr.contact is None


def test_ecg_vector() -> None:
    frame = decode_pmd_frame(ECG_VECTOR)
    assert frame.measurement == Measurement.ECG == 0
    assert frame.timestamp_ns == 599616028236586218
    assert isinstance(frame.timestamp_ns, int)
    assert frame.frame_type == 0 and frame.compressed is False
    assert frame.samples == [[104], [88], [70], [61], [50], [38], [22], [4]]


def test_acc_vector() -> None:
    frame = decode_pmd_frame(ACC_VECTOR)
    assert frame.measurement == Measurement.ACC
    assert frame.frame_type == 1 and not frame.compressed
    assert frame.samples == [[-187, -28, 949], [-187, -28, 952]]


# ----------------------------------------------------------------------------------------------
# Heart rate flags
def test_heart_rate_flags_16_bit_contact_energy() -> None:
    data = encode_heart_rate(300, [1024], contact=True, energy_kj=513)
    hr = decode_heart_rate(data)
    assert (hr.bpm, hr.contact_supported, hr.contact, hr.energy_kj, hr.rr_1024) == (
        300,
        True,
        True,
        513,
        [1024],
    )
    assert data[0] == 0x01 | 0x02 | 0x04 | 0x08 | 0x10


def test_heart_rate_contact_lost() -> None:
    hr = decode_heart_rate(bytes([0x04, 60]))
    assert hr.contact_supported is True and hr.contact is False and hr.rr_1024 == []


@pytest.mark.parametrize(
    "data, problem",
    [
        (b"", "at least 2"),
        (bytes([0x01, 60]), "16-bit"),
        (bytes([0x08, 60, 1]), "energy"),
        (bytes([0x10, 60, 1, 2, 3]), "pairs"),
        (bytes([0x00, 60, 1]), "trailing"),
    ],
)
def test_heart_rate_malformed(data: bytes, problem: str) -> None:
    with pytest.raises(PolarProtocolError, match=problem):
        decode_heart_rate(data)


def test_battery() -> None:
    assert decode_battery(b"\x5a") == 90
    for bad in (b"", b"\x65", b"\x01\x02"):
        with pytest.raises(PolarProtocolError):
            decode_battery(bad)


# ----------------------------------------------------------------------------------------------
# Raw frames
def test_raw_acc_widths_round_trip() -> None:
    rows = [[-100, 0, 127], [5, -128, 1]]
    for width, frame_type in ((1, 0), (2, 1), (3, 2)):
        frame = decode_pmd_frame(encode_acc_frame(123, rows, width=width))
        assert (frame.frame_type, frame.samples, frame.timestamp_ns) == (frame_type, rows, 123)
    wide = [[-8_000_000, 8_000_000, 0]]
    assert decode_pmd_frame(encode_acc_frame(1, wide, width=3)).samples == wide


def test_oh1_ppg_and_ppi() -> None:
    ppg = [[100_000, -5, 0, 8_000_000], [1, 2, 3, -8_388_608]]
    frame = decode_pmd_frame(encode_ppg_frame(77, ppg))
    assert frame.measurement == Measurement.PPG and frame.samples == ppg
    records = [[62, 968, 11, 0b110], [63, 951, 10, 0b111]]
    frame = decode_pmd_frame(encode_ppi_frame(0, records))
    assert frame.measurement == Measurement.PPI and frame.timestamp_ns == 0 and frame.samples == records


@pytest.mark.parametrize(
    "data, problem",
    [
        (ECG_VECTOR[:10], "header"),
        (ECG_VECTOR[:-1], "whole number"),
        (bytes([0x04]) + ECG_VECTOR[1:], "unknown PMD measurement type 4"),
        (ECG_VECTOR[:9] + b"\x05" + ECG_VECTOR[10:], "unsupported ECG raw frame type 5"),
        (ECG_VECTOR[:9] + b"\x80" + ECG_VECTOR[10:], "unsupported ECG compressed"),
        (encode_ppi_frame(0, [[60, 1000, 5, 0]])[:-1], "6-byte records"),
    ],
)
def test_pmd_malformed(data: bytes, problem: str) -> None:
    with pytest.raises(PolarProtocolError, match=problem):
        decode_pmd_frame(data)


def test_measurement_type_uses_low_six_bits() -> None:
    frame = decode_pmd_frame(bytes([0xC0]) + ECG_VECTOR[1:])
    assert frame.measurement == Measurement.ECG


# ----------------------------------------------------------------------------------------------
# Delta-compressed frames
def test_delta_block_of_three_bits_by_hand() -> None:
    """Worked by hand: deltas (1,-1,0), (-2,3,-4) as 3-bit fields LSB first = 0x023C39."""
    reference = (1).to_bytes(2, "little") + (2).to_bytes(2, "little") + (3).to_bytes(2, "little")
    payload = reference + bytes([3, 2]) + bytes([0x39, 0x3C, 0x02])
    assert decode_delta_payload(payload, channels=3, resolution=16) == [[1, 2, 3], [2, 1, 3], [0, 4, -1]]


def test_delta_width_changes_between_blocks() -> None:
    """A 3-bit block, then a 5-bit block (deltas 15, -16, 0 = 01111 10000 00000 = 0x020F), 1 channel."""
    payload = (10).to_bytes(2, "little") + bytes([3, 2, 0b111_001]) + bytes([5, 3, 0x0F, 0x02])
    assert decode_delta_payload(payload, channels=1, resolution=14) == [[10], [11], [10], [25], [9], [9]]


def test_compressed_acc_frame_with_settings() -> None:
    rows = [[-1000, 20, 980], [-990, 25, 985], [-1010, 22, 1003], [-1010, 22, 1003], [-700, 0, 1000]]
    data = encode_compressed_frame(
        Measurement.ACC, 42, 1, rows, resolution=16, block_sizes=[2, 2], widths=[7, 13]
    )
    frame = decode_pmd_frame(data, channels=3, resolution=16)
    assert frame.compressed and frame.frame_type == 1 and frame.samples == rows
    assert decode_pmd_frame(data).samples == rows  # ACC type 1 implies 3 channels, 16 bits


def test_compressed_ppg_22_bit_settings() -> None:
    rows = [[2_000_000, -2_000_000, 5, 0], [2_000_100, -1_999_000, 7, 1]]
    data = encode_compressed_frame(Measurement.PPG, 9, 0, rows, resolution=22)
    assert decode_pmd_frame(data, channels=4, resolution=22).samples == rows


def test_zero_width_block_repeats_the_sample() -> None:
    payload = (7).to_bytes(2, "little") + bytes([0, 3])
    assert decode_delta_payload(payload, 1, 16) == [[7], [7], [7], [7]]


@pytest.mark.parametrize(
    "payload, channels, resolution, problem",
    [
        (b"\x01", 1, 16, "reference"),
        (b"\x01\x00\x03", 1, 16, "block header"),
        (b"\x01\x00\x08\x02\x01", 1, 16, "needs 2 byte"),
        (b"\x01\x00\x21\x01" + bytes(5), 1, 16, "at most 32"),
        (b"\x01\x00", 0, 16, "channels"),
        (b"\x01\x00", 1, 40, "resolution"),
    ],
)
def test_delta_malformed(payload: bytes, channels: int, resolution: int, problem: str) -> None:
    with pytest.raises(PolarProtocolError, match=problem):
        decode_delta_payload(payload, channels, resolution)


@settings(max_examples=100, deadline=None)
@given(
    resolution=st.integers(4, 24),
    channels=st.integers(1, 4),
    data=st.data(),
)
def test_delta_round_trip(resolution: int, channels: int, data: st.DataObject) -> None:
    """Any samples and any block split / widths survive encoding and decoding exactly."""
    limit = 1 << (resolution - 1)
    value = st.integers(-limit, limit - 1)
    rows = data.draw(st.lists(st.lists(value, min_size=channels, max_size=channels), min_size=1, max_size=30))
    deltas = len(rows) - 1
    sizes: list[int] = []
    while sum(sizes) < deltas:
        sizes.append(data.draw(st.integers(1, deltas - sum(sizes))))
    payload = encode_delta_payload(rows, resolution, sizes)
    assert decode_delta_payload(payload, channels, resolution) == rows


# ----------------------------------------------------------------------------------------------
# Fuzzing: any byte string either decodes or raises PolarProtocolError
@settings(max_examples=600, deadline=None)
@given(st.binary(max_size=64))
def test_fuzz_heart_rate(data: bytes) -> None:
    try:
        hr = decode_heart_rate(data)
    except PolarProtocolError:
        return
    assert 0 <= hr.bpm < 65536 and all(0 <= rr < 65536 for rr in hr.rr_1024)


@settings(max_examples=500, deadline=None)
@given(
    st.binary(max_size=200),
    st.one_of(st.none(), st.integers(-2, 70)),
    st.one_of(st.none(), st.integers(-2, 40)),
)
def test_fuzz_pmd_frame(data: bytes, channels: int | None, resolution: int | None) -> None:
    try:
        frame = decode_pmd_frame(data, channels, resolution)
    except PolarProtocolError:
        return
    assert frame.samples and all(isinstance(v, int) for row in frame.samples for v in row)


@settings(max_examples=600, deadline=None)
@given(
    st.sampled_from([0x00, 0x01, 0x02, 0x03, 0x82, 0x81]),
    st.sampled_from([0x00, 0x80, 0x01, 0x02, 0x81]),
    st.binary(max_size=120),
)
def test_fuzz_pmd_payloads(kind: int, frame_type: int, payload: bytes) -> None:
    """Valid headers with random payloads reach the raw, compressed and PPI decoders."""
    data = bytes([kind]) + (599616028236586218).to_bytes(8, "little") + bytes([frame_type]) + payload
    with contextlib.suppress(PolarProtocolError):
        decode_pmd_frame(data)


def test_round_trip_ecg_frame_of_73_samples() -> None:
    values = [(-1) ** i * i * 1000 for i in range(73)]
    frame = decode_pmd_frame(encode_ecg_frame(599616028236586218, values))
    assert [row[0] for row in frame.samples] == values

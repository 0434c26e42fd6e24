"""The LSL streamer with real pylsl outlets and inlets: every channel format, input selection, stop.

These run in-process (no node subprocess): a pylsl outlet feeds an LslStreamer input, a
PhysioReceiver relays it to an LslStreamer output, and a pylsl inlet checks what comes out.
"""

from __future__ import annotations

import logging
import re
import threading
import time

import numpy as np
import pylsl
import pytest

from helpers import resolve_lsl, wait_until
from hri_physio_bridge.receiver import PhysioReceiver, ReceiverConfig
from hri_physio_bridge.streamers import OpenCancelled, StreamNotFoundError, numpy_dtype
from hri_physio_bridge.streamers.lsl import LslStreamer

pytestmark = pytest.mark.lsl

RATE = 130.0
N = 40  # samples per format test


def format_values(dtype: str) -> np.ndarray:
    """N x 2 values of ``dtype`` including each format's extremes."""
    if dtype == "string":
        texts = ["", "start", "phase: warm-up", 'say "hi", then ünïcode', "a,b;c\td", "x" * 300]
        return np.array([[texts[i % len(texts)], f"#{i}"] for i in range(N)], dtype=object)
    dt = numpy_dtype(dtype)
    if dt.kind == "i":
        info = np.iinfo(dt)
        ramp = np.linspace(-0.49, 0.49, 2 * N - 6) * float(info.max)  # within range as floats too
        edges = [info.min, info.max, 0, -1, 1, info.max - 1]
        values = np.concatenate([np.array(edges, dtype=dt), ramp.astype(dt)])
        if dt == np.int64:
            values[6:10] = [2**53 + 1, -(2**53) - 1, 2**62 + 3, -(2**62) - 7]  # not floats: exact ints
        return values.reshape(N, 2)
    info = np.finfo(dt)
    special = [info.max, -info.max, info.tiny, info.smallest_subnormal, -0.0, np.nan, np.inf, -np.inf,
               1 / 3, np.pi]
    rest = np.random.default_rng(7).standard_normal(2 * N - len(special)) * 1e3
    return np.concatenate([np.array(special, dtype=dt), rest.astype(dt)]).reshape(N, 2)


def as_bits(values: np.ndarray, dtype: str) -> list:
    """Values in a form where equality is exact (NaN payloads and -0.0 included)."""
    if dtype == "string":
        return values.tolist()
    return np.ascontiguousarray(values, dtype=numpy_dtype(dtype)).view(np.uint8).tolist()


@pytest.mark.parametrize("dtype,fmt", [
    ("string", pylsl.cf_string), ("int8", pylsl.cf_int8), ("int16", pylsl.cf_int16),
    ("int32", pylsl.cf_int32), ("int64", pylsl.cf_int64), ("float32", pylsl.cf_float32),
    ("float64", pylsl.cf_double64),
])
def test_every_channel_format_relayed_exactly(lsl_name: str, dtype: str, fmt: int) -> None:
    """outlet -> LslStreamer input -> PhysioReceiver -> LslStreamer output -> inlet, bit for bit."""
    relay = f"{lsl_name}-relay"
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "Test", 2, RATE, fmt, lsl_name))
    cfg = ReceiverConfig.from_mapping({
        "input": f"lsl:{lsl_name}", "output": f"lsl:{relay}", "dtype": dtype, "num_channels": 2,
        "sampling_rate": RATE, "output_frame": 8, "resolve_timeout": 20.0,
    })
    rx = PhysioReceiver(cfg, LslStreamer(lsl_name), LslStreamer(relay), log=logging.getLogger("test"))
    rx.start()
    got_rows: list = []
    got_stamps: list = []
    try:
        infos = resolve_lsl(relay)
        assert infos, f"relay {relay} did not appear"
        assert infos[0].channel_format() == fmt
        inlet = pylsl.StreamInlet(infos[0], recover=False)
        inlet.open_stream(10)
        wait_until(outlet.have_consumers, 20, "the receiver's inlet")
        values = format_values(dtype)
        stamps = 2000.0 + np.arange(N) / RATE + 1e-7  # fractional, LSL-clock-like
        rows = [[str(v) for v in row] for row in values] if dtype == "string" else values
        for i in range(0, N, 9):  # chunks of 9 in, frames of 8 out
            outlet.push_chunk(rows[i : i + 9], timestamp=stamps[i : i + 9].tolist())
        deadline = time.monotonic() + 20
        while len(got_rows) < N and time.monotonic() < deadline:
            data, ts = inlet.pull_chunk(timeout=0.2, max_samples=100)
            got_rows.extend(data)
            got_stamps.extend(ts)
    finally:
        rx.stop()
    assert len(got_rows) == N, f"{len(got_rows)} of {N} samples relayed"
    got = np.array(got_rows, dtype=object if dtype == "string" else numpy_dtype(dtype))
    np.testing.assert_array_equal(got, values)
    assert as_bits(got, dtype) == as_bits(values, dtype)  # -0.0 and NaN bits too
    np.testing.assert_array_equal(np.array(got_stamps), stamps)  # timestamps unchanged, bit for bit
    assert rx.stats.gaps == [] and rx.stats.published_samples == N


def test_input_selected_by_source_id_and_type(lsl_name: str) -> None:
    """Two outlets share a name; ?source_id= and ?type= pick the right one, every time."""
    ecg = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "ECG", 1, RATE, pylsl.cf_double64, f"{lsl_name}-A"))
    ppg = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "PPG", 1, RATE, pylsl.cf_double64, f"{lsl_name}-B"))
    marks = {"ECG": 1.0, "PPG": 2.0}
    cases = [
        (f"source_id={lsl_name}-A", "ECG"),
        (f"source_id={lsl_name}-B", "PPG"),
        ("type=ECG", "ECG"),
        ("type=PPG", "PPG"),
        (f"type=PPG&source_id={lsl_name}-B", "PPG"),
    ]
    for query, want in cases:
        s = LslStreamer(f"{lsl_name}?{query}")
        spec = s.open_input(timeout=20)
        try:
            assert (spec.type, spec.source_id) == (want, f"{lsl_name}-{'A' if want == 'ECG' else 'B'}"), query
            chosen = ecg if want == "ECG" else ppg
            wait_until(chosen.have_consumers, 20, f"inlet on the {want} outlet")
            for outlet, kind in ((ecg, "ECG"), (ppg, "PPG")):  # both send; only one is listened to
                outlet.push_sample([marks[kind]], pylsl.local_clock())
            got: list[float] = []
            deadline = time.monotonic() + 10
            while not got and time.monotonic() < deadline:
                frame = s.receive(timeout=0.2)
                if frame is not None:
                    got.extend(frame.values[:, 0].tolist())
            assert got and set(got) == {marks[want]}, f"{query}: got {got}"
        finally:
            s.close()
    # Name and type of one stream, source id of the other: no such stream.
    wrong = LslStreamer(f"{lsl_name}?type=ECG&source_id={lsl_name}-B")
    expected = re.escape(f"type='ECG' and source_id='{lsl_name}-B'") + ".*did not appear within 1 s"
    with pytest.raises(StreamNotFoundError, match=expected):
        wrong.open_input(timeout=1.0)


def test_open_input_gives_up_promptly_when_stopped(lsl_name: str) -> None:
    stop = threading.Event()
    threading.Timer(0.5, stop.set).start()
    start = time.monotonic()
    with pytest.raises(OpenCancelled, match=re.escape(f"waiting for LSL stream name='{lsl_name}-never'")):
        LslStreamer(f"{lsl_name}-never").open_input(timeout=30, stop=stop)
    assert time.monotonic() - start < 1.5


@pytest.mark.lsl
def test_more_outlets_than_liblsls_default_port_range_holds_are_all_found(lsl_name: str) -> None:
    """config/lsl_api.cfg widens the port range: with liblsl's default (32 ports, 2 an outlet) the
    17th outlet on the machine got a random port and was never resolved."""
    infos = [pylsl.StreamInfo(f"{lsl_name}/{i}", "Test", 1, 10.0, "float32", f"{lsl_name}{i}")
             for i in range(24)]
    outlets = [pylsl.StreamOutlet(info) for info in infos]
    found = resolve_lsl(pred=f"starts-with(name,'{lsl_name}/')", minimum=len(outlets))
    assert sorted(int(info.name().rsplit("/", 1)[1]) for info in found) == list(range(len(outlets)))
    del outlets


def _received(source: LslStreamer, n: int, timeout: float = 20.0) -> tuple[list[float], list[float]]:
    """Stamps and first-channel values of the input's frames, until ``n`` samples or ``timeout`` s."""
    stamps: list[float] = []
    values: list[float] = []
    deadline = time.monotonic() + timeout
    while len(stamps) < n and time.monotonic() < deadline:
        frame = source.receive(timeout=0.2)
        if frame is not None:
            stamps.extend(frame.timestamps.tolist())
            values.extend(frame.values[:, 0].tolist())
    return stamps, values


@pytest.mark.parametrize("sync", [True, False])
def test_time_correction_is_applied_with_sync_and_reported_either_way(lsl_name: str, sync: bool) -> None:
    """``?sync=1``: liblsl's time correction (the sender's LSL clock -> ours) is added to every stamp;
    without it the stamps are kept bit for bit. Either way the measured offset is in the receiver's
    status. On one host the offset is about 0: this shows the mechanism runs and is reported."""
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "Test", 1, RATE, pylsl.cf_double64, lsl_name))
    address = f"{lsl_name}?sync=1" if sync else lsl_name
    cfg = ReceiverConfig.from_mapping({"input": f"lsl:{address}", "output": f"lsl:{lsl_name}-relay",
                                       "sampling_rate": RATE, "resolve_timeout": 20.0})
    source = LslStreamer(address)
    assert source.corrects_clock is sync
    rx = PhysioReceiver(cfg, source, LslStreamer(f"{lsl_name}-relay"), log=logging.getLogger("test"))
    rx.open()  # the input only: its frames are read here, not relayed
    try:
        wait_until(outlet.have_consumers, 20, "the receiver's inlet")
        stamps = 5000.0 + np.arange(N) / RATE
        outlet.push_chunk([[float(i)] for i in range(N)], timestamp=stamps.tolist())
        got, _ = _received(source, N)
        assert len(got) == N
        offsets: list[float] = []
        wait_until(lambda: offsets.append(source.clock_offset()) or offsets[-1] is not None, 20,
                   "liblsl's first time-correction estimate")
        offset = offsets[-1]
        assert abs(offset) < 0.05, f"one host, one clock: offset {offset}"
        if sync:
            # liblsl re-estimates the offset now and then: each stamp got the estimate of its moment.
            np.testing.assert_allclose(np.array(got), stamps, rtol=0, atol=0.05)
            assert np.all(np.diff(got) > 0)
        else:
            np.testing.assert_array_equal(np.array(got), stamps)  # unchanged, bit for bit
        correction = rx.status()["clock_correction"]
        assert correction["applied"] is sync and correction["measurements"] >= 1
        assert abs(correction["offset_s"]) < 0.05 and correction["span_s"] >= 0
    finally:
        rx.stop()


def _arrival_stamped(n_chunks: int, per_chunk: int, seed: int) -> np.ndarray:
    """Stamps of a source that stamps each chunk on arrival: the chunk's last sample gets the arrival
    time (its true time plus 0-25 ms of BLE delay), the others are counted back at the nominal rate."""
    jitter = np.random.default_rng(seed).uniform(0.0, 0.025, n_chunks)
    last = 5000.0 + (np.arange(n_chunks) + 1) * per_chunk / RATE + jitter
    return (last[:, None] - (per_chunk - 1 - np.arange(per_chunk))[None, :] / RATE).reshape(-1)


@pytest.mark.parametrize("dejitter", [False, True])
def test_dejitter_smooths_a_source_that_stamps_chunks_on_arrival(lsl_name: str, dejitter: bool) -> None:
    """``?dejitter=1``: liblsl's dejitter turns arrival-stamped chunks (every boundary a step a few ms
    forward or back) into stamps the processor's windows accept (no gap, no clock jump), each within
    the jitter of its true time; without it the stamps are kept as sent and the windows are cut."""
    from hri_physio_processing.windowing import Window, WindowAccumulator

    per_chunk, n_chunks = 73, 40  # a Polar H10's ECG notification; 22 s
    stamps = _arrival_stamped(n_chunks, per_chunk, seed=3)
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "ECG", 1, RATE, pylsl.cf_double64, lsl_name))
    address = f"{lsl_name}?dejitter=1" if dejitter else lsl_name
    source = LslStreamer(address)
    assert source.dejitters is dejitter
    source.open_input(timeout=20.0)
    try:
        wait_until(outlet.have_consumers, 20, "the inlet")
        n = per_chunk * n_chunks
        for c in range(n_chunks):
            chunk = slice(c * per_chunk, (c + 1) * per_chunk)
            outlet.push_chunk([[float(i)] for i in range(n)[chunk]], timestamp=stamps[chunk].tolist())
        got_t, got_v = _received(source, n)
    finally:
        source.close()
    assert got_v == [float(i) for i in range(n)]  # every sample, in order, whatever the stamps
    windows = WindowAccumulator(window=int(10 * RATE), hop=int(RATE), sampling_rate=RATE)
    cuts = [e for e in windows.push(np.array(got_t), np.array(got_v)) if not isinstance(e, Window)]
    true_times = 5000.0 + (np.arange(n) + 1) / RATE
    if dejitter:
        assert cuts == []
        assert np.max(np.abs(np.array(got_t) - true_times)) < 0.03
    else:
        np.testing.assert_array_equal(np.array(got_t), stamps)  # kept as sent
        assert len(cuts) >= n_chunks // 4  # chunk boundaries read as gaps or clock jumps

"""Benchmarks for hri_physio_processing, measured side by side on this machine.

1. Per-window processing time of the NeuroKit2 processor for a 60 s / 130 Hz ECG window at a
   5 s hop (warm, its 300 s long HRV window full; ECGSYN at 70 +- 3 bpm), against calling
   NeuroKit2 directly on the same window (ecg_clean, ecg_peaks, quality, hrv_time, hrv_frequency);
   goal: absolute <= 50 ms per window (a window is due every 5 s: >= 100x real time). The processor
   does more than the direct calls: the artefact step (signal_fixpeaks passes) on the window and
   LF/HF of the 300 s long window. With the default ``templatematch`` it is faster than NeuroKit2
   direct because it computes NeuroKit2's template-matching quality without pandas
   (hri_physio_processing.quality).
2. The frequency-domain step of one window (LF, HF, LF/HF of the 300 s long HRV window, every hop):
   ``hrv.band_powers`` (Welch over the whole window, ms^2) and the artefact step before it
   (``artifacts.clean_beats``: beat-free stretches, Lipponen & Tarvainen correction; the processor
   runs it on each 60-s window, and the long window takes the corrected beats), against
   NeuroKit2's ``hrv_frequency`` (what the processor called before) on the same real 300-s RR series
   (pyhrv's sample NN series); goal: <= 5 ms per window for the spectrum.
3. Streaming biquads: samples/s for 1, 8 and 64 channels in chunks, against
   scipy.signal.sosfilt one-shot on the same data; goal: within 2x. Each chunk costs one
   scipy call (~5 us), so the ratio depends on the chunk size; the goal line uses 10 s chunks
   (1300 samples at 130 Hz) and the table shows smaller ones.

Run: ``source scripts/env.sh && python bench/bench_processing.py [--quick]``
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import neurokit2 as nk
import numpy as np
from scipy import signal

from hri_physio_bridge.frames import Frame
from hri_physio_processing.artifacts import clean_beats
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.filters import BandPass, LowPass
from hri_physio_processing.hrv import band_powers
from hri_physio_processing.processor import NeurokitProcessor

ROOT = Path(__file__).resolve().parents[1]
FS = 130
WARM_SECONDS = 310
GOAL_CHUNK = 10 * FS


def nk_direct(x: np.ndarray, quality: str) -> dict[str, float]:
    """What a user would call by hand for the same features."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = nk.ecg_clean(x, sampling_rate=FS)
        _, info = nk.ecg_peaks(clean, sampling_rate=FS)
        peaks = info["ECG_R_Peaks"]
        out = {"hr": float(np.mean(nk.signal_rate(peaks, sampling_rate=FS, desired_length=len(x))))}
        if quality == "zhao2018":
            out["quality"] = nk.ecg_quality(clean, rpeaks=peaks, sampling_rate=FS, method=quality,
                                            approach="fuzzy")
        elif quality != "none":
            q = nk.ecg_quality(clean, rpeaks=peaks, sampling_rate=FS, method=quality)
            out["quality"] = float(np.mean(q))
        td = nk.hrv_time(peaks, sampling_rate=FS)
        fd = nk.hrv_frequency(peaks, sampling_rate=FS)
    out.update(sdnn=td["HRV_SDNN"][0], rmssd=td["HRV_RMSSD"][0], pnn50=td["HRV_pNN50"][0],
               hf=fd["HRV_HF"][0])
    return out


def bench_windows(quality: str, windows: int) -> None:
    warm = WARM_SECONDS * FS  # the long HRV window (300 s) is full from the first timed window on
    seconds = WARM_SECONDS + 5 * (windows + 2)
    x = nk.ecg_simulate(duration=seconds, sampling_rate=FS, heart_rate=70, heart_rate_std=3, noise=0.01,
                        random_state=1)
    t = np.arange(x.shape[0]) / FS
    hop = 5 * FS
    proc = NeurokitProcessor(ProcessorConfig.from_mapping({"quality_method": quality}))
    proc.push(Frame(t[: warm + hop], x[: warm + hop]))  # warm-up
    node_times, direct_times = [], []
    for k in range(windows):
        a = warm + hop * (k + 1)
        chunk = Frame(t[a : a + hop], x[a : a + hop])
        window = x[a + hop - 60 * FS : a + hop]
        # Alternate the two so machine load hits both alike.
        t0 = time.perf_counter()
        outs = proc.push(chunk)
        node_times.append(time.perf_counter() - t0)
        assert outs, "a window is due every hop"
        t0 = time.perf_counter()
        nk_direct(window, quality)
        direct_times.append(time.perf_counter() - t0)
    node, direct = statistics.median(node_times), statistics.median(direct_times)
    print(f"  quality={quality:13s} processor {node * 1e3:7.1f} ms/window   NeuroKit2 direct "
          f"{direct * 1e3:7.1f} ms   ratio {node / direct:5.2f} (overhead {100 * (node / direct - 1):+.0f} %)"
          f"   real-time factor {5.0 / node:6.0f}x per hop, {60.0 / node:6.0f}x per window")


def bench_frequency(windows: int) -> None:
    nn = np.load(ROOT / "tests" / "data" / "pyhrv_nni" / "SampleNNISeriesLong.npy").astype(np.float64)
    beats = np.concatenate([[0.0], np.cumsum(nn) / 1000.0])
    series = [beats[(beats >= s) & (beats < s + 300.0)] for s in np.arange(windows) * 60.0]
    timings: dict[str, list[float]] = {"band_powers": [], "clean_beats": [], "nk": []}
    for b in series:
        for name, fn in (("band_powers", lambda b=b: band_powers(b)),
                         ("clean_beats", lambda b=b: clean_beats(b)),
                         ("nk", lambda b=b: nk.hrv_frequency({"RRI": np.diff(b) * 1000.0}))):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                timings[name].append(_timed(fn))
    ms = {k: 1e3 * statistics.median(v) for k, v in timings.items()}
    verdict = "goal met" if ms["band_powers"] <= 5.0 else "goal missed"
    print(f"  hrv.band_powers {ms['band_powers']:6.2f} ms/window ({verdict})   artefact step (clean_beats) "
          f"{ms['clean_beats']:6.2f} ms   together {ms['band_powers'] + ms['clean_beats']:6.2f} ms   "
          f"NeuroKit2 hrv_frequency (before) {ms['nk']:6.2f} ms")


def _rate(fn: Callable[[], None], samples: int, repeat: int) -> float:
    best = min(_timed(fn) for _ in range(repeat))
    return samples / best


def _timed(fn: Callable[[], None]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench_filters(seconds: int, repeat: int) -> None:
    n = seconds * FS
    for channels in (1, 8, 64):
        x = np.random.default_rng(channels).normal(size=(n, channels))
        for chunk in (13, 130, GOAL_CHUNK):
            lp = LowPass(40.0, FS)

            def streamed(f: LowPass = lp, c: int = chunk, data: np.ndarray = x) -> None:
                f.reset()
                for i in range(0, n, c):
                    f.process(data[i : i + c])

            def one_shot(sos: np.ndarray = lp.sos, data: np.ndarray = x) -> None:
                signal.sosfilt(sos, data, axis=0)

            ours = _rate(streamed, n, repeat)
            ref = _rate(one_shot, n, repeat)
            verdict = ("goal met" if ref / ours <= 2.0 else "goal missed") if chunk == GOAL_CHUNK else ""
            print(f"  {channels:2d} ch, chunk {chunk:5d}: streaming {ours / 1e6:7.2f} M samples/s   "
                  f"sosfilt one-shot {ref / 1e6:7.2f} M samples/s   one-shot/streaming {ref / ours:5.2f}"
                  f"  {verdict}")
    bp = BandPass(10.0, 5.0, FS)
    x = np.random.default_rng(0).normal(size=(n, 8))
    ours = _rate(lambda: [bp.process(x[i : i + 130]) for i in range(0, n, 130)], n, repeat)
    print(f"  band-pass, 8 ch, chunk 130: {ours / 1e6:.2f} M samples/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args()
    windows = 8 if args.quick else 30
    print(f"Per-window time, 60 s / 130 Hz ECG window, 5 s hop, warm, median of {windows} windows:")
    for quality in ("none", "templatematch", "zhao2018"):
        bench_windows(quality, windows)
    print(f"Frequency-domain step, 300 s of real RR (pyhrv sample series), median of {windows} windows:")
    bench_frequency(windows)
    print("Streaming Butterworth biquad (low-pass 40 Hz), 600 s at 130 Hz, best of runs; samples/s count\n"
          "time steps (each carries every channel); small chunks pay scipy's ~5 us per call:")
    bench_filters(600, 3 if args.quick else 7)


if __name__ == "__main__":
    main()

"""Accuracy of the processor's heart rate and HRV on real recordings, against independent references.

1. LF, HF (ms^2) and LF/HF on real RR series (pyhrv's 1-h sample NNI series, MIT-BIH 100's reference
   beat annotations), 300-s windows every 60 s: NeuroKit2's ``hrv_frequency`` (what the processor
   used before) and ``hri_physio_processing.hrv.band_powers`` against the Task Force reference
   written from the definition in ``tests/helpers/hrv_reference.py``. With pyhrv / hrv-analysis
   importable (``PYTHONPATH``), also against them configured as close to the method as they allow.
2. pNN50 on MIT-BIH 100, 60-s windows: NeuroKit2's ``hrv_time`` and the processor against the
   definition (NN50 over N - 1 successive differences) on the same R-peaks.
3. MIT-BIH 208 (scipy 1.11.4's ``ecg.dat``, 5 min): every 60-s window (5-s hop) through the
   processor; windows holding a beat-free stretch > 2 s (GQRS reference beats, wfdb) versus the
   others: how many are flagged, SDNN / RMSSD, HR error against GQRS (mean of 60 / RR, as pyhrv and
   hrv-analysis define mean HR; RR > 2 s left out).
4. PPG (heartpy's data2, 2 min, and data3, 11 min): every 60-s window through the processor in
   PPG mode; HR error against heartpy's accepted peaks (60 / median of its accepted consecutive
   inter-beat intervals in the window; windows where those cover less than half the window are
   not scored) and the share of windows that publish a rate.

Run: ``source scripts/env.sh && nice -n 19 python bench/bench_hrv_accuracy.py``
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import neurokit2 as nk
import numpy as np
from scipy.signal import resample_poly

from hri_physio_bridge.frames import Frame
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.hrv import band_powers
from hri_physio_processing.processor import NeurokitProcessor, StatusOutput

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
sys.path.insert(0, str(ROOT / "tests"))
from helpers import hrv_reference as ref  # noqa: E402
from helpers.processing import nk_corrected_beats  # noqa: E402
from helpers.recordings import ecg208, heartpy_ppg  # noqa: E402

warnings.simplefilter("ignore")


def rel(a: float, b: float) -> float:
    return abs(a / b - 1.0)


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


# -- real RR series ----------------------------------------------------------------------------
def rr_series() -> dict[str, np.ndarray]:
    """Beat times (s) of the real RR series."""
    import wfdb

    nn = np.load(DATA / "pyhrv_nni" / "SampleNNISeriesLong.npy").astype(np.float64)
    ann = wfdb.rdann(str(DATA / "mitdb" / "100"), "atr")
    symbols = "NLRBAaJSVrFejnE/fQ?"
    beats = np.array([s for s, sym in zip(ann.sample, ann.symbol, strict=True) if sym in symbols])
    return {"pyhrv SampleNNISeriesLong": np.concatenate([[0.0], np.cumsum(nn) / 1000.0]),
            "MIT-BIH 100 annotations": beats / 360.0}


def windows_of(beats: np.ndarray, seconds: float, hop: float) -> list[np.ndarray]:
    out = []
    t = beats[0]
    while t + seconds <= beats[-1]:
        out.append(beats[(beats >= t) & (beats < t + seconds)])
        t += hop
    return out


def spectrum_section() -> None:
    print("1. LF, HF (ms^2), LF/HF on real RR, 300-s windows every 60 s: |relative error| against the "
          "Task Force reference, median / max")
    for name, beats in rr_series().items():
        errs: dict[str, dict[str, list[float]]] = {"NeuroKit2 hrv_frequency (before)": {},
                                                   "band_powers (after)": {}}
        for b in windows_of(beats, 300.0, 60.0):
            r = ref.band_powers(np.diff(b) * 1000.0)
            fd = nk.hrv_frequency({"RRI": np.diff(b) * 1000.0})
            old = {"lf": fd["HRV_LF"][0], "hf": fd["HRV_HF"][0], "lfhf": fd["HRV_LFHF"][0]}
            new = band_powers(b)
            for label, vals in (("NeuroKit2 hrv_frequency (before)", old), ("band_powers (after)", new)):
                for k in ("lf", "hf", "lfhf"):
                    errs[label].setdefault(k, []).append(rel(vals[k], r[k]))
        print(f"  {name} ({len(windows_of(beats, 300.0, 60.0))} windows)")
        for label, e in errs.items():
            print(f"    {label:34s} " + "  ".join(
                f"{k.upper()} {100 * np.median(v):8.2f} % / {100 * max(v):8.2f} %" for k, v in e.items()))
    _libraries()


def _libraries() -> None:
    """pyhrv (one Hann periodogram below 5 min) and hrv-analysis (cubic, Hann, 256-sample segments)."""
    try:
        import types

        sys.modules.setdefault("nolds", types.ModuleType("nolds"))  # hrv-analysis imports it at the top
        import pyhrv.frequency_domain as pfd
        from hrvanalysis import get_frequency_domain_features
    except ImportError as exc:
        print(f"  (pyhrv / hrv-analysis not importable: {exc}; put them on PYTHONPATH to compare)")
        return
    nn = np.load(DATA / "pyhrv_nni" / "SampleNNISeriesLong.npy").astype(np.float64)
    beats = np.concatenate([[0.0], np.cumsum(nn) / 1000.0])
    e_py: dict[str, list[float]] = {"lf": [], "hf": []}
    e_ha: dict[str, list[float]] = {"lf": [], "hf": []}
    for b in windows_of(beats, 240.0, 60.0):
        rr = np.diff(b) * 1000.0
        ours = band_powers(b, segment_seconds=300.0)  # one segment: pyhrv's plan below 5 min
        res = pfd.welch_psd(nni=rr, window="hann", detrend=True, show=False, mode="dev")[0]
        _vlf, lf, hf = res["fft_abs"]
        e_py["lf"].append(rel(ours["lf"], lf))
        e_py["hf"].append(rel(ours["hf"], hf))
        ours = band_powers(b, segment_seconds=64.0)  # hrv-analysis: scipy's 256-sample segments
        ha = get_frequency_domain_features(list(rr), method="welch", sampling_frequency=4,
                                           interpolation_method="cubic")
        e_ha["lf"].append(rel(ours["lf"], ha["lf"]))
        e_ha["hf"].append(rel(ours["hf"], ha["hf"]))
    n = len(e_py["lf"])
    print(f"  pyhrv 0.5.0 welch_psd(window='hann') vs band_powers (one segment), 240-s windows ({n}): "
          + _summary(e_py))
    print("  hrv-analysis 1.0.6 welch (cubic, 4 Hz) vs band_powers (64-s segments; hrv-analysis drops the "
          "tail that does not fill a segment): "
          + _summary(e_ha))


def _summary(errors: dict[str, list[float]]) -> str:
    return "  ".join(f"{k.upper()} median {100 * np.median(v):.3f} % max {100 * max(v):.3f} %"
                     for k, v in errors.items())


# -- processor runs ------------------------------------------------------------------------------
def run(x: np.ndarray, fs: float, mode: str, **extra: object) -> list[dict]:
    """Every window's status of the processor (60-s windows, 5-s hop) on a recording fed in 1-s chunks."""
    cfg = ProcessorConfig.from_mapping({"mode": mode, "sampling_rate": fs, "window_seconds": 60,
                                        "hop_seconds": 5, "input": f"ros:/physio/bench/{mode}", **extra})
    proc = NeurokitProcessor(cfg)
    t = np.arange(x.shape[0]) / fs
    out = []
    step = int(fs)
    for a in range(0, x.shape[0], step):
        out.extend(proc.push(Frame(t[a : a + step], x[a : a + step])))
    out.extend(proc.finish())
    return [o.payload for o in out if isinstance(o, StatusOutput) and o.payload.get("event") == "window"]


def pnn50_section() -> None:
    import wfdb

    rec = wfdb.rdrecord(str(DATA / "mitdb" / "100"), channels=[0])
    x = resample_poly(rec.p_signal[:, 0], 13, 36)[: 600 * 130]
    old, new = [], []
    for a in range(0, x.shape[0] - 60 * 130 + 1, 30 * 130):
        seg = x[a : a + 60 * 130]
        clean = nk.ecg_clean(seg, sampling_rate=130)
        peaks = nk.ecg_peaks(clean, sampling_rate=130)[1]["ECG_R_Peaks"]
        definition = ref.time_domain(np.diff(peaks) / 130.0 * 1000.0)["pnn50"]
        old.append(nk.hrv_time(peaks, sampling_rate=130)["HRV_pNN50"][0] / definition - 1.0)
    for st in run(x, 130.0, "ecg"):
        if st["ok"] and st["features"].get("pnn50"):
            a = round(st["window"]["t_start"] * 130)
            seg = x[a : a + st["window"]["samples"]]
            clean = nk.ecg_clean(seg, sampling_rate=130)
            peaks = nk.ecg_peaks(clean, sampling_rate=130)[1]["ECG_R_Peaks"]
            beats, _ = nk_corrected_beats(peaks)  # the processor's NN: after artefact correction
            definition = ref.time_domain(np.diff(beats) * 1000.0)["pnn50"]
            new.append(st["features"]["pnn50"] / definition - 1.0)
    print("2. pNN50 against the definition (NN50 / (N-1)) on the same NN, MIT-BIH 100, 60-s windows: "
          f"NeuroKit2 hrv_time {100 * np.median(old):+.2f} % (median of {len(old)}); processor "
          f"{100 * np.median(new):+.2f} % median, {100 * np.max(np.abs(new)):.2f} % max |.| "
          f"({len(new)} windows)")


def ecg208_section() -> None:
    rec = ecg208()
    wins = run(rec.x130, 130.0, "ecg")
    gaps = rec.gaps()
    rows: dict[str, list[tuple[dict, float]]] = {"with": [], "without": []}
    for st in wins:
        t0, t1 = st["window"]["t_start"], st["window"]["t_end"]
        holds = any(t0 < a and b < t1 for a, b in gaps)
        rows["with" if holds else "without"].append((st, rec.rate(t0, t1)))
    print(f"3. MIT-BIH 208 excerpt (scipy ecg.dat), {len(wins)} windows of 60 s; GQRS finds "
          f"{rec.gqrs.shape[0]} beats, beat-free stretches > 2 s: "
          + ", ".join(f"{a:.1f}-{b:.1f} s ({b - a:.2f} s)" for a, b in gaps))
    for label, items in rows.items():
        sts = [s for s, _ in items]
        flagged = sum(1 for s in sts if not s["ok"] or s["features"].get("sdnn") is None)
        sd = [s["features"]["sdnn"] for s in sts if s["features"].get("sdnn") is not None]
        rm = [s["features"]["rmssd"] for s in sts if s["features"].get("rmssd") is not None]
        hr_err = [abs(s["features"]["hr"] - r) for s, r in items if s["features"].get("hr") is not None]
        corrected = [s.get("beats", {}).get("corrected", 0) for s in sts]
        print(f"   {label:7s} a > 2 s beat-free stretch inside: {len(sts):2d} windows, SDNN/RMSSD NaN in "
              f"{flagged:2d}; SDNN median {pct(sd, 50):6.1f} ms (max {max(sd) if sd else math.nan:6.1f}), "
              f"RMSSD median {pct(rm, 50):6.1f} ms; HR |error| p90 {pct(hr_err, 90):5.2f} bpm "
              f"({len(hr_err)} with HR); corrected beats per window median {np.median(corrected):.0f}")


def ppg_section() -> None:
    print("4. PPG heart rate (default options) against heartpy's accepted peaks (60 / median IBI), "
          "60-s windows every 5 s")
    for name, label in (("data2", "heartpy data2 (2 min)"), ("data3", "heartpy data3 (11 min)")):
        rec = heartpy_ppg(name)
        wins = run(rec.x, rec.fs, "ppg")
        errs, published, scored = [], 0, 0
        for st in wins:
            ref_hr = rec.rate(st["window"]["t_start"], st["window"]["t_end"])
            if math.isnan(ref_hr):
                continue
            scored += 1
            hr = st["features"].get("hr")
            if hr is not None:
                published += 1
                errs.append(abs(hr - ref_hr))
        print(f"   {label:24s} fs {rec.fs:7.3f} Hz: {scored} scored windows, HR published in {published} "
              f"({100 * published / max(scored, 1):.0f} %), |error| median {pct(errs, 50):5.2f} p90 "
              f"{pct(errs, 90):5.2f} max {max(errs) if errs else math.nan:5.2f} bpm")


def main() -> None:
    spectrum_section()
    pnn50_section()
    ecg208_section()
    ppg_section()


if __name__ == "__main__":
    main()

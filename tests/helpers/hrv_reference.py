"""Independent HRV references written from the definitions, for tests and bench/bench_hrv_accuracy.py.

Frequency domain (Task Force 1996): the RR series (ms, each value placed at the time of the beat
that ends it) is resampled evenly at 4 Hz by a cubic spline, its mean removed, and its power
spectral density estimated by Welch's method: Hann-windowed segments, each with its own mean
removed, |FFT|^2 averaged, one-sided density in ms^2/Hz. Band power (ms^2) is the density summed
over the band's bins times the bin width. This is written with numpy's FFT and scipy's
``CubicSpline`` only (not ``scipy.signal.welch``), so it shares no spectral code with the processor.

Segment plan (part of the stated method): segments of about ``segment_seconds`` (at most the series),
overlapping by at least half, the first starting at the first resampled sample and the last ending
at the last one, so the whole series is used.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

FS = 4.0
NFFT = 4096
LF_BAND = (0.04, 0.15)
HF_BAND = (0.15, 0.40)


def resampled_rr(rr_ms: np.ndarray, fs: float = FS, beat_times: np.ndarray | None = None) -> np.ndarray:
    """``beat_times`` (s), when given, place each interval exactly (else the cumulative sum does)."""
    rr = np.asarray(rr_ms, dtype=np.float64)
    t = np.cumsum(rr) / 1000.0 if beat_times is None else np.asarray(beat_times, dtype=np.float64)[1:]
    t = t - t[0]
    grid = np.arange(0.0, t[-1], 1.0 / fs)
    return CubicSpline(t, rr)(grid)


def segment_starts(n: int, seg: int) -> tuple[int, np.ndarray]:
    """Segment length and start indices covering [0, n) exactly (see the module docstring)."""
    if n <= seg:
        return n, np.array([0])
    k = max(1, round((n - seg) / (seg / 2.0)) + 1)
    if k == 1:
        return n, np.array([0])
    step = n // (k + 1)
    length = n - (k - 1) * step
    return length, np.arange(k) * step


def welch_psd(x: np.ndarray, fs: float, segment_seconds: float,
              nfft: int = NFFT) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64) - np.mean(x)
    length, starts = segment_starts(x.shape[0], round(segment_seconds * fs))
    # Hann, periodic form (as a spectral-analysis window): w[k] = 0.5 - 0.5 cos(2 pi k / L)
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(length) / length)
    nfft = max(nfft, length)
    acc = np.zeros(nfft // 2 + 1)
    for s in starts:
        seg = x[s : s + length]
        seg = seg - seg.mean()
        acc += np.abs(np.fft.rfft(seg * w, nfft)) ** 2
    psd = acc / starts.shape[0] / (fs * np.sum(w**2))
    psd[1:] *= 2.0  # one-sided
    if nfft % 2 == 0:
        psd[-1] /= 2.0  # the Nyquist bin has no mirror
    return np.fft.rfftfreq(nfft, 1.0 / fs), psd


def band_powers(rr_ms: np.ndarray, segment_seconds: float = 120.0,
                beat_times: np.ndarray | None = None) -> dict[str, float]:
    """LF, HF (ms^2), LF/HF, LFnu and HFnu of an RR series (ms) by the method above."""
    f, p = welch_psd(resampled_rr(rr_ms, FS, beat_times), FS, segment_seconds)
    df = f[1] - f[0]
    lf = float(p[(f >= LF_BAND[0]) & (f < LF_BAND[1])].sum() * df)
    hf = float(p[(f >= HF_BAND[0]) & (f < HF_BAND[1])].sum() * df)
    return {"lf": lf, "hf": hf, "lfhf": lf / hf,
            "lfnu": 100.0 * lf / (lf + hf), "hfnu": 100.0 * hf / (lf + hf)}


def time_domain(rr_ms: np.ndarray) -> dict[str, float]:
    """SDNN, RMSSD (ms) and pNN50, pNN20 (%) by the Task Force definitions.

    pNNx is the share of successive-interval differences larger than x ms: NNx over the number of
    differences (N - 1 for N intervals), as pyhrv and hrv-analysis compute it.
    """
    rr = np.asarray(rr_ms, dtype=np.float64)
    d = np.diff(rr)
    return {"sdnn": float(np.std(rr, ddof=1)), "rmssd": float(np.sqrt(np.mean(d**2))),
            "pnn50": 100.0 * np.count_nonzero(np.abs(d) > 50.0) / d.shape[0],
            "pnn20": 100.0 * np.count_nonzero(np.abs(d) > 20.0) / d.shape[0]}


def mean_rate(nn_ms: np.ndarray, tolerance: float = 0.2) -> float:
    """Mean instantaneous heart rate (bpm, mean of 60000 / NN) over the intervals within ``tolerance``
    of the median."""
    nn = np.asarray(nn_ms, dtype=np.float64)
    med = np.median(nn)
    return float(np.mean(60000.0 / nn[np.abs(nn - med) <= tolerance * med]))


def lomb_band_powers(rr_ms: np.ndarray, beat_times: np.ndarray) -> dict[str, float]:
    """LF, HF (ms^2) from the classic Lomb (1976) / Scargle (1982) periodogram, written out with its
    time offset tau, of the NN intervals (mean removed) at the beats that end them; one-sided density
    scaled by 2 T / N so a sinusoid's band power is its variance; bands summed on the Welch grid."""
    t = np.asarray(beat_times, dtype=np.float64)[1:]
    t = t - t[0]
    y = np.asarray(rr_ms, dtype=np.float64)
    y = y - y.mean()
    f = np.arange(NFFT // 2 + 1) * FS / NFFT
    p = np.zeros_like(f)
    for k in range(1, f.shape[0]):
        w = 2.0 * np.pi * f[k]
        tau = np.arctan2(np.sum(np.sin(2 * w * t)), np.sum(np.cos(2 * w * t))) / (2 * w)
        c, s = np.cos(w * (t - tau)), np.sin(w * (t - tau))
        p[k] = 0.5 * ((y @ c) ** 2 / (c @ c) + (y @ s) ** 2 / (s @ s))
    p *= 2.0 * t[-1] / t.shape[0]
    df = f[1] - f[0]
    lf = float(p[(f >= LF_BAND[0]) & (f < LF_BAND[1])].sum() * df)
    hf = float(p[(f >= HF_BAND[0]) & (f < HF_BAND[1])].sum() * df)
    return {"lf": lf, "hf": hf, "lfhf": lf / hf}

"""Heart-rate variability of an NN-interval series by the Task Force (1996) definitions.

Time domain: SDNN (sample SD, ms), RMSSD (ms), pNN50 and pNN20 (%): NNx over the number of
successive differences (N - 1 for N intervals), as pyhrv and hrv-analysis compute it.

Frequency domain, in absolute units (ms^2), over the whole series:

1. each NN interval (ms) is placed at the time of the beat that ends it; the series is resampled
   evenly at 4 Hz by a cubic spline (not-a-knot), from the first of those times up to the last;
2. Welch's method: Hann-windowed segments of about ``segment_seconds`` (120 s; the whole series
   when shorter), overlapping by at least half and placed so the first starts at the first
   resampled sample and the last ends at the last one (no part of the series is left out); each
   segment's mean is removed; the one-sided density (ms^2/Hz) is evaluated on a 4096-point grid;
   (``spectrum="lomb"``: the Lomb-Scargle periodogram of the intervals at their own times instead,
   no resampling; scaled so that a sinusoid's band power is its variance, as Welch's);
3. band power is the density summed over the bins in the band times the bin width: LF
   0.04-0.15 Hz, HF 0.15-0.40 Hz (lower edge included, upper excluded); LF/HF; LFnu and HFnu are
   LF and HF as a percentage of LF + HF.

NeuroKit2's ``hrv_frequency`` is not used: it scales the spectrum by its own maximum (so LF and HF
are not in ms^2) and its Welch segments can leave the end of a 5-min series out.
"""

from __future__ import annotations

import numpy as np

RESAMPLE_HZ = 4.0
NFFT = 4096
SEGMENT_SECONDS = 120.0
LF_BAND = (0.04, 0.15)
HF_BAND = (0.15, 0.40)
NO_POWER = 1e-6  # ms^2; below it LF + HF is rounding noise of constant intervals
#: Each frequency-domain method in one sentence (reports print it next to the numbers).
METHODS = {
    "welch": ("Task Force (1996): NN intervals (artefact-corrected, Lipponen & Tarvainen 2019) resampled "
              "at 4 Hz by a cubic spline, Welch's method (Hann, ~120 s segments overlapping >= 50 % and "
              "tiling the whole window), LF 0.04-0.15 Hz and HF 0.15-0.40 Hz in ms^2"),
    "lomb": ("Task Force (1996) bands on the Lomb-Scargle periodogram of the NN intervals "
             "(artefact-corrected, Lipponen & Tarvainen 2019) at their beat times, not resampled, mean "
             "removed, one-sided density scaled to ms^2/Hz, LF 0.04-0.15 Hz and HF 0.15-0.40 Hz in ms^2"),
}
SPECTRA = tuple(METHODS)
METHOD = METHODS["welch"]
#: Keys of :func:`band_powers`.
FREQUENCY_KEYS = ("lf", "hf", "lfhf", "lfnu", "hfnu")
#: Keys of :func:`time_domain`.
TIME_KEYS = ("sdnn", "rmssd", "pnn50", "pnn20")


def time_domain(nn_ms: np.ndarray) -> dict[str, float]:
    """SDNN, RMSSD, pNN50, pNN20 of NN intervals (ms); NaN for what fewer than 2 intervals cannot give."""
    nn = np.asarray(nn_ms, dtype=np.float64).reshape(-1)
    out = dict.fromkeys(TIME_KEYS, float("nan"))
    if nn.shape[0] < 2:
        return out
    d = np.abs(np.diff(nn))
    out["sdnn"] = float(np.std(nn, ddof=1))
    out["rmssd"] = float(np.sqrt(np.mean(d * d)))
    out["pnn50"] = 100.0 * float(np.count_nonzero(d > 50.0)) / d.shape[0]
    out["pnn20"] = 100.0 * float(np.count_nonzero(d > 20.0)) / d.shape[0]
    return out


def segment_plan(n: int, seg: int) -> tuple[int, int]:
    """(nperseg, step) for Welch over ``n`` samples with segments near ``seg``: the segments tile
    [0, n) exactly, overlapping by at least half."""
    if n <= seg:
        return n, n
    k = round((n - seg) / (seg / 2.0)) + 1
    if k <= 1:
        return n, n
    step = n // (k + 1)
    return n - (k - 1) * step, step


def resample(beat_times: np.ndarray, nn_ms: np.ndarray, fs: float = RESAMPLE_HZ) -> np.ndarray:
    """NN intervals (ms) placed at the beats that end them, resampled evenly at ``fs`` (cubic)."""
    t = np.asarray(beat_times, dtype=np.float64) - float(beat_times[0])
    grid = np.arange(0.0, t[-1], 1.0 / fs)
    # scipy is imported where it is used: the launcher imports this module (through the processor's
    # configuration) only to validate options, and scipy.signal alone costs it a second of start-up.
    from scipy.interpolate import make_interp_spline

    return make_interp_spline(t, np.asarray(nn_ms, dtype=np.float64), k=3)(grid)


def band_powers(beat_times: np.ndarray, segment_seconds: float = SEGMENT_SECONDS,
                spectrum: str = "welch") -> dict[str, float]:
    """LF, HF (ms^2), LF/HF, LFnu, HFnu (%) of a run of beats (times in s, no gap in between), by
    Welch (the default) or Lomb-Scargle (``spectrum="lomb"``; :func:`lomb_psd`).

    Raises ValueError when the run is too short to hold two LF cycles; callers check lengths first.
    """
    beats = np.asarray(beat_times, dtype=np.float64).reshape(-1)
    if beats.shape[0] < 5:
        raise ValueError(f"{beats.shape[0]} beats: too few for a spectrum")
    if spectrum not in METHODS:
        raise ValueError(f"unknown spectrum {spectrum!r}; choose one of {', '.join(SPECTRA)}")
    nn = np.diff(beats) * 1000.0
    if beats[-1] - beats[1] < 2.0 / LF_BAND[0]:
        raise ValueError(f"{beats[-1] - beats[1]:.3g} s of beats: too short for a spectrum")
    if spectrum == "lomb":
        f, p = lomb_psd(beats[1:], nn)
    else:
        x = resample(beats[1:], nn)
        nperseg, step = segment_plan(x.shape[0], round(segment_seconds * RESAMPLE_HZ))
        from scipy.signal import welch

        f, p = welch(x, fs=RESAMPLE_HZ, window="hann", nperseg=nperseg, noverlap=nperseg - step,
                     nfft=max(NFFT, nperseg), detrend="constant", scaling="density")
    df = float(f[1] - f[0])
    lf = float(p[(f >= LF_BAND[0]) & (f < LF_BAND[1])].sum() * df)
    hf = float(p[(f >= HF_BAND[0]) & (f < HF_BAND[1])].sum() * df)
    total = lf + hf
    if not total > NO_POWER:  # constant intervals: rounding noise only
        return dict.fromkeys(FREQUENCY_KEYS, float("nan"))
    return {"lf": lf, "hf": hf, "lfhf": lf / hf if hf > 0 else float("nan"),
            "lfnu": 100.0 * lf / total, "hfnu": 100.0 * hf / total}


def lomb_psd(times: np.ndarray, nn_ms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Lomb-Scargle density (ms^2/Hz) of NN intervals at their (uneven) times, on the same
    frequency grid as the Welch estimate (0 to 2 Hz in steps of 4 Hz / 4096).

    scipy's unnormalised periodogram of a sinusoid of amplitude A peaks at A^2 N / 4 over a width of
    about 1 / T; scaled by 2 T / N its integral is A^2 / 2, the sinusoid's variance (Parseval).
    """
    t = np.asarray(times, dtype=np.float64) - float(times[0])
    y = np.asarray(nn_ms, dtype=np.float64)
    y = y - y.mean()
    f = np.fft.rfftfreq(NFFT, 1.0 / RESAMPLE_HZ)
    p = np.zeros_like(f)
    from scipy.signal import lombscargle

    p[1:] = lombscargle(t, y, 2.0 * np.pi * f[1:], normalize=False)
    return f, p * 2.0 * float(t[-1]) / t.shape[0]

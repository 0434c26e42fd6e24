"""Features of one window of ECG, PPG or EDA, computed with NeuroKit2, with validity rules.

Every feature is either a number NeuroKit2 computed on exactly this window's samples, or NaN
with a reason (``WindowResult.nan_reasons``), never a silent 0. Window-level problems
(``WindowResult.flags``) make every feature NaN:

* before NeuroKit2 runs: NaN/inf samples, flat line, saturation, wrong sampling rate
  (:mod:`signal_checks`);
* after it ran: mean rate outside [min_hr, max_hr] or signal quality below ``min_quality``
  (noise that is not ECG/PPG still yields "peaks"; these two catch it).

HRV is computed from the beats by :mod:`hrv` (Task Force 1996 definitions; LF and HF in ms^2
by Welch over the whole run of beats), not by NeuroKit2's ``hrv_time``/``hrv_frequency``.
Window-length rules for frequency-domain HRV follow NeuroKit2's guidance: HF needs at least
1 min, LF 2 min and LF/HF (and LFnu, HFnu, which are LF/HF in another form) 5 min of signal;
shorter windows give NaN with the reason.
With ``frequency_domain`` off, :func:`extract` leaves LF, HF and LF/HF to the caller, which
computes them with :func:`hrv_frequency_of_beats` on a longer run of beats (the processor's
``hrv_window_seconds``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hri_physio_processing import hrv
from hri_physio_processing.artifacts import clean_beats
from hri_physio_processing.quality import templatematch_quality
from hri_physio_processing.signal_checks import Flag, check_rate, check_values

MODES = ("ecg", "ppg", "eda")

HEART_SCALARS = ("hr", "sdnn", "rmssd", "pnn50", "pnn20", "lf", "hf", "lfhf", "lfnu", "hfnu", "quality")
EDA_SCALARS = ("tonic", "scr_count", "scr_amplitude")
SCALARS: dict[str, tuple[str, ...]] = {"ecg": HEART_SCALARS, "ppg": HEART_SCALARS, "eda": EDA_SCALARS}
#: Name of the peak-mask output per mode.
PEAKS_FEATURE = {"ecg": "rpeaks", "ppg": "peaks", "eda": "scr_peaks"}
#: Sample-rate outputs per mode (frames of the window's samples).
SIGNAL_FEATURES: dict[str, tuple[str, ...]] = {
    "ecg": ("clean", "rpeaks", "beat_hr"),
    "ppg": ("clean", "peaks", "beat_hr"),
    "eda": ("clean", "scr_peaks"),
}

#: Minimum window length (s) for each frequency-domain HRV feature (NeuroKit2's guidance).
MIN_SECONDS = {"hf": 60.0, "lf": 120.0, "lfhf": 300.0, "lfnu": 300.0, "hfnu": 300.0}
FREQUENCY_SCALARS = hrv.FREQUENCY_KEYS

#: Intervals within this fraction of the window's median count as regular (rate and its check).
REGULAR_TOLERANCE = 0.2

QUALITY_METHODS = ("templatematch", "averageQRS", "zhao2018", "none")
#: zhao2018 answers with a category; published as a number.
ZHAO_SCORES = {"Excellent": 1.0, "Barely acceptable": 0.5, "Unacceptable": 0.0}


@dataclass(frozen=True)
class FeatureSettings:
    """What :func:`extract` needs to know (a subset of the processor configuration)."""

    mode: str = "ecg"
    sampling_rate: float = 130.0
    quality_method: str = "templatematch"
    min_quality: float = 0.5
    min_beats: int = 5
    min_hr: float = 30.0
    max_hr: float = 220.0
    flatline_seconds: float = 2.0
    saturation_fraction: float = 0.01
    rate_tolerance: float = 0.05
    correct_artifacts: bool = False
    max_beat_gap_seconds: float = 2.0  # a longer interval is a beat-free stretch, not a heartbeat
    max_corrected_fraction: float = 0.1  # more corrected beats: HRV NaN
    min_regular_fraction: float = 0.8  # fewer regular intervals: rate and HRV NaN
    hrv_spectrum: str = "welch"  # or "lomb" (hrv.band_powers)
    frequency_domain: bool = True  # LF, HF, LF/HF on the window itself (off: the caller's long window)
    polarity: str = "auto"  # "auto" (ECG: each window by its dominant deflection), "upright", "inverted"
    ecg_inverted_when_unclear: bool = False  # auto, a window with no clear polarity: the last clear one

    @property
    def nk_rate(self) -> int | float:
        """Sampling rate as handed to NeuroKit2 (an int when whole, as the seed did)."""
        fs = float(self.sampling_rate)
        return int(fs) if fs.is_integer() else fs


@dataclass
class WindowResult:
    """Outputs of one window. ``peaks`` are sample offsets into the window."""

    mode: str
    num_samples: int
    clean: np.ndarray
    peaks: np.ndarray
    scalars: dict[str, float]
    nan_reasons: dict[str, str] = field(default_factory=dict)
    flags: list[Flag] = field(default_factory=list)
    processed: bool = False  # NeuroKit2 ran on this window
    beats: dict[str, object] = field(default_factory=dict)  # artefact counts (ECG/PPG), for the status
    #: ECG/PPG: the beats after the artefact step (sample positions into the window, fractional), and
    #: why they are unfit for HRV (None: fit). The processor's long HRV window is built from them.
    nn_beats: np.ndarray | None = None
    hrv_reason: str | None = None
    inverted: bool = False  # ECG: the signal was turned over (R waves negative) before peak detection
    polarity_clear: bool = False  # ECG, auto: the window's own deflections decided the polarity

    @property
    def ok(self) -> bool:
        return not self.flags


def load_neurokit() -> None:
    """Import NeuroKit2 now (it imports scipy.stats, scikit-learn and more: seconds of CPU, once).

    Imported lazily, it would make the first window seconds late, at a moment of the session no one
    chose, with the input piling up meanwhile; a processor calls this before it opens its input.
    """
    import neurokit2  # noqa: F401


def _empty(mode: str, n: int, flags: list[Flag]) -> WindowResult:
    """A window NeuroKit2 did not (successfully) process: every feature NaN, with the reasons."""
    reason = "; ".join(f.reason for f in flags)
    return WindowResult(
        mode=mode, num_samples=n, clean=np.full(n, np.nan), peaks=np.empty(0, dtype=np.int64),
        scalars=dict.fromkeys(SCALARS[mode], math.nan), nan_reasons=dict.fromkeys(SCALARS[mode], reason),
        flags=flags,
    )


def _nan_all(result: WindowResult, flag: Flag, keep: tuple[str, ...] = ()) -> WindowResult:
    """Flag a processed window: its features (but ``keep``) become NaN and no peak is trusted."""
    result.flags.append(flag)
    for key in result.scalars:
        if key not in keep:
            result.scalars[key] = math.nan
            result.nan_reasons[key] = flag.reason
    result.peaks = np.empty(0, dtype=np.int64)
    return result


def extract(timestamps: np.ndarray, x: np.ndarray, cfg: FeatureSettings) -> WindowResult:
    """Features of one window of one channel."""
    if cfg.mode not in MODES:
        raise ValueError(f"unknown mode {cfg.mode!r}; choose one of {', '.join(MODES)}")
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    fs = float(cfg.sampling_rate)
    flags: list[Flag] = []
    rate_flag = check_rate(timestamps, fs, cfg.rate_tolerance)
    if rate_flag is not None:
        flags.append(rate_flag)
    flags.extend(check_values(x, fs, cfg.flatline_seconds, cfg.saturation_fraction))
    if flags:
        return _empty(cfg.mode, x.shape[0], flags)
    runner: Callable[[np.ndarray, FeatureSettings], WindowResult] = {
        "ecg": _ecg, "ppg": _ppg, "eda": _eda,
    }[cfg.mode]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # NeuroKit2 warns freely; our reasons say what matters
            return runner(x, cfg)
    except Exception as exc:  # NeuroKit2 raises many types on degenerate input
        flag = Flag("neurokit_error", f"NeuroKit2 failed: {type(exc).__name__}: {exc}")
        return _empty(cfg.mode, x.shape[0], [flag])


def detect(x: np.ndarray, cfg: FeatureSettings,
           inverted: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cleaned signal and peaks only (the same NeuroKit2 calls as :func:`extract`).

    Used on a window plus its lead-in, to place peaks near the window's start; ``inverted``: the
    window's own ECG polarity (None: decided here as :func:`extract` does).
    """
    import neurokit2 as nk

    x = np.asarray(x, dtype=np.float64).reshape(-1)
    fs = cfg.nk_rate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if cfg.mode == "ecg":
            clean = np.asarray(nk.ecg_clean(x, sampling_rate=fs), dtype=np.float64)
            polarity = cfg.polarity if inverted is None else ("inverted" if inverted else "upright")
            clean, _, _ = upright_ecg(clean, float(cfg.sampling_rate), polarity,
                                      cfg.ecg_inverted_when_unclear)
            _, info = nk.ecg_peaks(clean, sampling_rate=fs, correct_artifacts=cfg.correct_artifacts)
            return clean, np.asarray(info["ECG_R_Peaks"], dtype=np.int64)
        if cfg.mode == "ppg":
            signals, info = nk.ppg_process(_ppg_upright(x, cfg)[0], sampling_rate=fs)
            peaks = np.asarray(info["PPG_Peaks"], dtype=np.int64)
            return signals["PPG_Clean"].to_numpy(dtype=np.float64), peaks
        signals, info = nk.eda_process(x, sampling_rate=fs)
        peaks = np.asarray(info["SCR_Peaks"], dtype=np.float64)
        return signals["EDA_Clean"].to_numpy(dtype=np.float64), peaks[np.isfinite(peaks)].astype(np.int64)


# -- ECG / PPG -------------------------------------------------------------------
#: Auto polarity looks at blocks this long: each holds a beat at any rate above 30 bpm.
POLARITY_BLOCK_SECONDS = 2.0
#: Auto polarity is clear when at least this share of the blocks point the same way. Measured on
#: 60-s windows: turned-over ECG (MIT-BIH 100 both leads, 208, a real H10 recording, NeuroKit2's
#: simulation with noise up to 0.5) had 0.85-1.0 of its blocks pointing down in 95 % of windows
#: (0.60 at worst, in the H10's noisy stretches); brown and white noise at most 0.73.
POLARITY_CLEAR_SHARE = 0.8


def upright_ecg(clean: np.ndarray, fs: float, polarity: str = "auto",
                inverted_when_unclear: bool = False) -> tuple[np.ndarray, bool, bool]:
    """The cleaned ECG with its dominant deflection up; whether it was turned over; whether the
    signal itself made that clear (``auto`` only).

    A strap worn upside down, or electrodes swapped, gives an ECG whose R waves point down: the peak
    detector then times other waves of the beat, and HRV comes out several times too high with a
    quality that passes (a real H10 recording turned over: RMSSD 63 ms instead of 6). ``auto`` takes,
    in each 2-s block, the sample farthest from the mean (the deflections NeuroKit2's ``ecg_invert``
    looks at, on the already cleaned signal: cleaning is linear, so this costs no second pass) and
    turns the signal over when at least :data:`POLARITY_CLEAR_SHARE` of them are negative (NeuroKit2
    turns at half, which turns noise over too). Short of that either way
    (noise, a stretch of artefacts) the window is not clear and ``inverted_when_unclear`` decides:
    the polarity of the stream so far, which a strap keeps. A lead whose S wave is deeper than its R
    is timed on the S wave, which beats as regularly. ``upright`` / ``inverted`` fix the polarity.
    """
    if polarity in ("upright", "inverted"):
        inverted = polarity == "inverted"
        return (-clean if inverted else clean), inverted, False
    block = max(round(POLARITY_BLOCK_SECONDS * fs), 1)
    blocks = clean.shape[0] // block
    if blocks == 0:
        inverted, clear = inverted_when_unclear, False
    else:
        centred = (clean[: blocks * block] - np.mean(clean)).reshape(blocks, block)
        down = float(np.mean(centred[np.arange(blocks), np.argmax(np.abs(centred), axis=1)] < 0))
        clear = max(down, 1.0 - down) >= POLARITY_CLEAR_SHARE
        inverted = down >= POLARITY_CLEAR_SHARE if clear else inverted_when_unclear
    return (-clean if inverted else clean), inverted, clear


def _ecg(x: np.ndarray, cfg: FeatureSettings) -> WindowResult:
    import neurokit2 as nk

    fs = cfg.nk_rate
    clean = np.asarray(nk.ecg_clean(x, sampling_rate=fs), dtype=np.float64)
    clean, inverted, clear = upright_ecg(clean, float(cfg.sampling_rate), cfg.polarity,
                                         cfg.ecg_inverted_when_unclear)
    _, info = nk.ecg_peaks(clean, sampling_rate=fs, correct_artifacts=cfg.correct_artifacts)
    peaks = np.asarray(info["ECG_R_Peaks"], dtype=np.int64)

    def quality() -> float:
        if cfg.quality_method == "none":
            return math.nan
        if cfg.quality_method == "templatematch":  # NeuroKit2's method, without its pandas cost
            return float(np.mean(templatematch_quality(clean, peaks, fs)))
        q = nk.ecg_quality(clean, rpeaks=peaks, sampling_rate=fs, method=cfg.quality_method,
                           **({"approach": "fuzzy"} if cfg.quality_method == "zhao2018" else {}))
        return ZHAO_SCORES[q] if isinstance(q, str) else float(np.mean(q))

    res = _heart(clean, peaks, quality, cfg)
    res.inverted, res.polarity_clear = inverted, clear
    return res


def _ppg_upright(x: np.ndarray, cfg: FeatureSettings) -> tuple[np.ndarray, bool]:
    """The PPG turned over when the user says it is upside down (``inverted``), and whether it was:
    a PPG window holds no reliable cue of its own polarity."""
    inverted = cfg.polarity == "inverted"
    return (-x if inverted else x), inverted


def _ppg(x: np.ndarray, cfg: FeatureSettings) -> WindowResult:
    import neurokit2 as nk

    upright, inverted = _ppg_upright(x, cfg)
    signals, info = nk.ppg_process(upright, sampling_rate=cfg.nk_rate)
    clean = signals["PPG_Clean"].to_numpy(dtype=np.float64)
    peaks = np.asarray(info["PPG_Peaks"], dtype=np.int64)

    def quality() -> float:
        if cfg.quality_method == "none" or "PPG_Quality" not in signals:
            return math.nan
        return float(signals["PPG_Quality"].mean())

    res = _heart(clean, peaks, quality, cfg)
    res.inverted = inverted
    return res


def _heart(clean: np.ndarray, peaks: np.ndarray, quality: Callable[[], float],
           cfg: FeatureSettings) -> WindowResult:
    """Rate, quality and HRV from beat positions (ECG R-peaks or PPG systolic peaks)."""
    import neurokit2 as nk

    n = clean.shape[0]
    fs = cfg.nk_rate
    duration = n / float(cfg.sampling_rate)
    res = WindowResult(cfg.mode, n, clean, peaks, dict.fromkeys(HEART_SCALARS, math.nan), processed=True)
    if peaks.shape[0] < max(cfg.min_beats, 2):
        reason = f"only {peaks.shape[0]} beat(s) found, at least {max(cfg.min_beats, 2)} needed"
        return _nan_all(res, Flag("too_few_beats", reason))
    # Plausibility on NeuroKit2's mean instantaneous rate of all peaks (noise yields "peaks" too);
    # the published rate is the robust one below.
    hr = float(np.mean(nk.signal_rate(peaks, sampling_rate=fs, desired_length=n)))
    res.scalars["quality"] = quality()
    if cfg.quality_method == "none":
        res.nan_reasons["quality"] = "quality_method is none"
    if not cfg.min_hr <= hr <= cfg.max_hr:
        return _nan_all(res, Flag(
            "implausible_rate",
            f"mean rate {hr:.1f} bpm outside [{cfg.min_hr:g}, {cfg.max_hr:g}]: not a heart signal?",
        ), keep=("quality",))
    q = res.scalars["quality"]
    if math.isfinite(q) and q < cfg.min_quality:
        flag = Flag("low_quality", f"signal quality {q:.3f} below min_quality {cfg.min_quality:g}")
        return _nan_all(res, flag, keep=("quality",))
    beats = clean_beats(peaks / float(cfg.sampling_rate), cfg.max_beat_gap_seconds,
                        cfg.max_corrected_fraction)
    res.beats = beats.as_status()
    if cfg.mode == "ppg":  # pulse peaks: spurious and missed ones are common; the regular intervals
        hr, regular = robust_rate(beats.nn_ms)
    else:  # R-peaks: every detected interval is a heartbeat (premature beats too), stretches left out
        rr = np.diff(peaks) / float(cfg.sampling_rate) * 1000.0
        rr = rr[rr <= 1000.0 * cfg.max_beat_gap_seconds]
        hr = float(np.mean(60000.0 / rr)) if rr.shape[0] else math.nan
        regular = robust_rate(beats.nn_ms)[1]
    res.beats["regular_fraction"] = round(regular, 4) if math.isfinite(regular) else None
    res.scalars["hr"] = hr
    hrv_reason = beats.hrv_reason
    if not math.isfinite(hr):
        res.nan_reasons["hr"] = hrv_reason = "no inter-beat interval left after the artefact checks"
    elif cfg.mode == "ppg" and regular < cfg.min_regular_fraction:
        # (ECG keeps its rate: an irregular rhythm of trusted R-peaks, atrial fibrillation say, still
        # has one; noise there is the quality check's. Its HRV is NaN by the rule below.)
        hrv_reason = (f"only {regular:.0%} of the clean inter-beat intervals within "
                      f"{REGULAR_TOLERANCE:.0%} of their median (min_regular_fraction "
                      f"{cfg.min_regular_fraction:.0%}): noise or an irregular rhythm, no trusted rate")
        res.scalars["hr"] = math.nan
        res.nan_reasons["hr"] = hrv_reason
    if hrv_reason is None:
        irregular = round((1.0 - regular) * beats.nn_ms.shape[0])
        if beats.corrected_beats + irregular > cfg.max_corrected_fraction * beats.beats:
            # the correction did not catch them all (its thresholds adapt to a contaminated series)
            hrv_reason = (f"{beats.corrected_beats} beat(s) corrected and {irregular} interval(s) still off "
                          f"the median by more than {REGULAR_TOLERANCE:.0%}, of {beats.beats} beats (more "
                          f"than max_corrected_fraction {cfg.max_corrected_fraction:.0%}): artefacts left, "
                          "HRV would be inflated")
    res.nn_beats = np.concatenate(beats.runs) * float(cfg.sampling_rate)
    res.hrv_reason = hrv_reason
    if hrv_reason is not None:
        for key in hrv.TIME_KEYS:
            res.scalars[key] = math.nan
            res.nan_reasons[key] = hrv_reason
        short = _too_short(duration, "window") if cfg.frequency_domain else {}
        for key in FREQUENCY_SCALARS:
            res.scalars[key] = math.nan
            res.nan_reasons[key] = short.get(key, hrv_reason)
    else:
        res.scalars.update(hrv.time_domain(beats.nn_ms))
        if not cfg.frequency_domain:
            for key in FREQUENCY_SCALARS:
                res.nan_reasons[key] = "computed on the long HRV window (hrv_window_seconds), not per window"
        else:
            values, reasons = hrv_frequency_of_beats(beats.runs[0], duration, cleaned=True,
                                                     spectrum=cfg.hrv_spectrum)
            res.scalars.update(values)
            res.nan_reasons.update(reasons)
    for key, value in res.scalars.items():
        if not math.isfinite(value) and key not in res.nan_reasons:
            res.nan_reasons[key] = "not computable from this window's beats (too few or too irregular)"
    return res


def robust_rate(nn_ms: np.ndarray) -> tuple[float, float]:
    """PPG heart rate (bpm) from clean NN intervals, and the share of them it rests on (the share of
    regular intervals, which the rate check uses in both modes).

    The mean instantaneous rate (60000 / NN, averaged over intervals, as pyhrv and hrv-analysis
    define mean HR) of the intervals within ``REGULAR_TOLERANCE`` of their median: without the
    spurious or missed beats the correction left (one extra PPG peak splits an interval into two
    short ones and pulls a plain mean up by several bpm). In a rhythm with many premature beats the
    ones the correction did not move are left out too, which lowers the rate slightly.
    """
    nn = np.asarray(nn_ms, dtype=np.float64)
    if not nn.shape[0]:
        return math.nan, math.nan
    med = float(np.median(nn))
    inside = nn[np.abs(nn - med) <= REGULAR_TOLERANCE * med]
    return float(np.mean(60000.0 / inside)), inside.shape[0] / nn.shape[0]


def _too_short(seconds: float, what: str) -> dict[str, str]:
    """NaN reasons for the frequency-domain features that ``seconds`` of beats cannot support."""
    return {key: f"{what} {seconds:g} s shorter than the {need:g} s {key.upper()} needs"
            for key, need in MIN_SECONDS.items() if seconds < need}


def hrv_frequency_of_beats(beat_times: np.ndarray, seconds: float, max_gap: float = 2.0,
                           max_corrected_fraction: float = 0.1, cleaned: bool = False,
                           spectrum: str = "welch") -> tuple[dict[str, float], dict[str, str]]:
    """LF, HF (ms^2), LF/HF, LFnu, HFnu of a run of beats (times in s, no gap between them) spanning
    ``seconds``, by :func:`hrv.band_powers`, after the artefact steps of :func:`artifacts.clean_beats`
    (unless ``cleaned``: the beats went through them already, window by window; then only a
    beat-free stretch is checked for).

    From the beats' source timestamps, so beats found by different windows join into one series.
    Returns the values and the NaN reasons.
    """
    beats = np.asarray(beat_times, dtype=np.float64).reshape(-1)
    values = dict.fromkeys(FREQUENCY_SCALARS, math.nan)
    reasons = _too_short(seconds, "clean beat series of")
    if len(reasons) == len(FREQUENCY_SCALARS):
        return values, reasons
    if beats.shape[0] < 5:
        reason = f"only {beats.shape[0]} beat(s) in the {seconds:g} s HRV window"
        return values, dict.fromkeys(FREQUENCY_SCALARS, reason)
    if not cleaned:
        result = clean_beats(beats, max_gap, max_corrected_fraction, origin=float(beats[0]))
        if result.hrv_reason is not None:
            return values, dict.fromkeys(FREQUENCY_SCALARS, f"HRV window: {result.hrv_reason}")
        beats = result.runs[0]
    elif float(np.max(np.diff(beats))) > max_gap:
        reason = f"HRV window: a beat-free stretch longer than {max_gap:g} s inside"
        return values, dict.fromkeys(FREQUENCY_SCALARS, reason)
    try:
        powers = hrv.band_powers(beats, spectrum=spectrum)
    except ValueError as exc:
        reason = f"{exc} (in the {seconds:g} s HRV window)"
        return values, dict.fromkeys(FREQUENCY_SCALARS, reason)
    for key in FREQUENCY_SCALARS:
        if key in reasons:
            continue
        values[key] = powers[key]
        if not math.isfinite(values[key]):
            reasons[key] = "no power in the LF and HF bands (constant intervals?)"
    return values, reasons


# -- EDA -----------------------------------------------------------------------------
def _eda(x: np.ndarray, cfg: FeatureSettings) -> WindowResult:
    import neurokit2 as nk

    signals, info = nk.eda_process(x, sampling_rate=cfg.nk_rate)
    clean = signals["EDA_Clean"].to_numpy(dtype=np.float64)
    raw_peaks = np.asarray(info["SCR_Peaks"], dtype=np.float64)
    keep = np.isfinite(raw_peaks)
    peaks = raw_peaks[keep].astype(np.int64)
    amplitudes = np.asarray(info["SCR_Amplitude"], dtype=np.float64)[keep]
    res = WindowResult("eda", clean.shape[0], clean, peaks, dict.fromkeys(EDA_SCALARS, math.nan),
                       processed=True)
    res.scalars["tonic"] = float(signals["EDA_Tonic"].mean())
    res.scalars["scr_count"] = float(peaks.shape[0])
    if np.isfinite(amplitudes).any():
        res.scalars["scr_amplitude"] = float(np.nanmean(amplitudes))
    if not math.isfinite(res.scalars["scr_amplitude"]):
        res.nan_reasons["scr_amplitude"] = "no skin conductance response in this window"
    return res

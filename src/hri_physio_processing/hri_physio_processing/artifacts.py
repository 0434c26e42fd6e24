"""From detected beats to clean NN intervals: beat-free stretches, then RR-artefact correction.

1. Beat-free stretches: an interval between two detected beats longer than ``max_gap`` seconds
   (2 s) is not a heartbeat interval but a stretch without detectable beats (saturation, flat
   line, baseline jump, lost contact). The beats are split there into runs and the interval is left
   out of everything; HRV of a window holding one is NaN (a single such interval inflates SDNN and
   RMSSD several-fold), the rate comes from the runs.
2. Each run is corrected by Lipponen & Tarvainen (2019) as NeuroKit2's ``signal_fixpeaks``
   (``method="kubios"``) implements it: extra beats removed, missed beats inserted, ectopic and
   long/short beats moved to the middle of their neighbours. NeuroKit2's own ``iterative`` loop
   reports only the last pass's artefacts, so the passes are run here (the same stopping rule:
   until a pass finds no fewer artefacts than the one before) and their counts summed.

The result is the NN-interval series (ms) of the runs, how many beats were corrected, and a reason
when the series is not fit for HRV (a beat-free stretch, or more than ``max_corrected_fraction``
of the beats corrected: then the series is more interpolation than measurement).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

#: Artefact kinds of Lipponen & Tarvainen (2019), as NeuroKit2 names them.
KINDS = ("ectopic", "missed", "extra", "longshort")
#: Runs shorter than this are not corrected (the method's thresholds need neighbours).
MIN_RUN_BEATS = 5
MAX_PASSES = 10
UNITS = 1_000_000  # beat times go to NeuroKit2 as integer microseconds


@dataclass
class CleanBeats:
    """NN intervals of a beat series after the two steps (module docstring)."""

    nn_ms: np.ndarray  # every clean interval, runs concatenated (beat-free stretches left out)
    runs: list[np.ndarray]  # corrected beat times (s) of each run
    beats: int  # detected beats
    corrected_beats: int = 0  # moved, removed or inserted by the correction
    found: dict[str, int] = field(default_factory=lambda: dict.fromkeys(KINDS, 0))  # per kind, all passes
    gaps: list[tuple[float, float]] = field(default_factory=list)  # beat-free stretches (start, end), s
    hrv_reason: str | None = None

    def as_status(self) -> dict[str, object]:
        return {
            "detected": self.beats, "corrected": self.corrected_beats, "found": dict(self.found),
            "beat_free": [[round(a, 3), round(b, 3)] for a, b in self.gaps],
        }


def correct_run(times: np.ndarray) -> tuple[np.ndarray, dict[str, int], int]:
    """One run of beat times (s) corrected by Lipponen & Tarvainen (2019).

    Returns the corrected times, the artefacts found per kind (summed over the passes; a beat may
    be found in two passes) and the number of beats corrected: moved, removed or inserted.
    """
    import neurokit2 as nk

    counts = dict.fromkeys(KINDS, 0)
    if times.shape[0] < MIN_RUN_BEATS:
        return times, counts, 0
    t0 = float(times[0])
    peaks = original = np.rint((times - t0) * UNITS).astype(np.int64)  # the method takes sample indices
    previous = math.inf
    for _ in range(MAX_PASSES):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            info, fixed = nk.signal_fixpeaks(peaks, sampling_rate=UNITS, method="kubios", iterative=False)
        found = {k: len(info[k]) for k in KINDS}
        n = sum(found.values())
        if n == 0 or n >= previous:
            break
        previous = n
        for k in KINDS:
            counts[k] += found[k]
        peaks = np.unique(np.asarray(fixed, dtype=np.int64))
    changed = max(np.setdiff1d(original, peaks).shape[0], np.setdiff1d(peaks, original).shape[0])
    if not changed:
        return times, counts, 0  # untouched: the exact source times
    return t0 + peaks / UNITS, counts, int(changed)


def clean_beats(times: np.ndarray, max_gap: float = 2.0, max_corrected_fraction: float = 0.1,
                origin: float = 0.0) -> CleanBeats:
    """Clean NN intervals of beat times (s); ``origin`` is subtracted in the reported stretches."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    rr = np.diff(t)
    cut = np.flatnonzero(rr > max_gap)
    gaps = [(float(t[i]) - origin, float(t[i + 1]) - origin) for i in cut]
    runs, counts, corrected = [], dict.fromkeys(KINDS, 0), 0
    for run in np.split(t, cut + 1):
        fixed, found, changed = correct_run(run)
        runs.append(fixed)
        corrected += changed
        for k in KINDS:
            counts[k] += found[k]
    nn = np.concatenate([np.diff(r) for r in runs]) * 1000.0 if runs else np.empty(0)
    res = CleanBeats(nn, runs, int(t.shape[0]), corrected, counts, gaps)
    if gaps:
        longest = max(gaps, key=lambda g: g[1] - g[0])
        res.hrv_reason = (f"{len(gaps)} beat-free stretch(es) longer than {max_gap:g} s (longest "
                          f"{longest[1] - longest[0]:.2f} s at {longest[0]:.1f}-{longest[1]:.1f} s: "
                          "saturation, flat line, baseline jump or lost contact): HRV would be inflated")
    elif t.shape[0] and res.corrected_beats > max_corrected_fraction * t.shape[0]:
        res.hrv_reason = (f"{res.corrected_beats} of {t.shape[0]} beats corrected as artefacts (more than "
                          f"{max_corrected_fraction:.0%}): too few measured intervals for HRV")
    return res

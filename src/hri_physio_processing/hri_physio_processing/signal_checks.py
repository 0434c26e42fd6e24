"""Checks that decide whether a window is worth handing to NeuroKit2 at all.

A window that fails one of these is flagged and its features are NaN: NeuroKit2 would
otherwise turn a detached electrode (flat line), a clipped amplifier (saturation), dropped
samples (NaN), a corrupt value or a misconfigured sampling rate into plausible-looking numbers
(or into an error that names none of them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Flag:
    """A window-level problem: a short code and a sentence for the status message."""

    code: str
    reason: str


def longest_run(mask: np.ndarray) -> int:
    """Length of the longest run of True in a 1-D boolean array."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return 0
    edges = np.diff(np.concatenate([[0], m.view(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return int((stops - starts).max())


def check_rate(timestamps: np.ndarray, fs: float, tolerance: float) -> Flag | None:
    """Sampling rate implied by the timestamps versus the configured one."""
    t = np.asarray(timestamps, dtype=np.float64)
    if t.shape[0] < 3:
        return None
    span = float(t[-1] - t[0])
    measured = (t.shape[0] - 1) / span if span > 0 else float("inf")
    if abs(measured / fs - 1.0) > tolerance:
        return Flag(
            "rate_mismatch",
            f"timestamps imply {measured:.4g} Hz but sampling_rate is {fs:g} Hz "
            f"(more than {tolerance:.0%} apart): check the configuration",
        )
    return None


def check_values(
    x: np.ndarray, fs: float, flatline_seconds: float, saturation_fraction: float
) -> list[Flag]:
    """Non-finite samples, flat lines and clipping in one channel of a window."""
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    flags: list[Flag] = []
    finite = np.isfinite(x)
    if not finite.all():
        bad = int((~finite).sum())
        run = longest_run(~finite)
        flags.append(Flag(
            "nonfinite",
            f"{bad} NaN/inf sample(s), longest run {run} ({run / fs:.3g} s)",
        ))
        return flags  # the value checks below need finite samples
    if x.shape[0] < 2:
        return flags
    still = np.diff(x) == 0
    run = longest_run(still) + 1 if still.any() else 1
    if run / fs >= flatline_seconds:
        flags.append(Flag(
            "flatline",
            f"signal constant for {run / fs:.3g} s (>= {flatline_seconds:g} s): electrode off or "
            "stream stalled",
        ))
        return flags
    corrupt = _corrupt_samples(x)
    if corrupt is not None:
        flags.append(corrupt)
        return flags  # one such value swamps every filter and peak after it
    lo, hi = float(x.min()), float(x.max())
    at_rail = int(np.count_nonzero(x == hi)) + int(np.count_nonzero(x == lo))
    if at_rail / x.shape[0] >= saturation_fraction:
        flags.append(Flag(
            "saturated",
            f"{at_rail / x.shape[0]:.1%} of samples sit at the window's extremes ({lo:g} / {hi:g}): "
            "clipped signal",
        ))
    return flags


#: A sample this many times the window's 1-99 % range away from its median is not a signal (no
#: artefact of a body or an amplifier reaches that): a corrupt value, a unit mix-up, a decoding error.
CORRUPT_FACTOR = 1e4


def _corrupt_samples(x: np.ndarray) -> Flag | None:
    """Samples absurdly far from the rest of the window (one ruins the filters: no beat is found)."""
    with np.errstate(over="ignore", invalid="ignore"):
        lo, mid, hi = np.percentile(x, [1.0, 50.0, 99.0])
        spread = float(hi - lo)
    if not np.isfinite(spread):  # so many of them that the range itself overflows
        return Flag("corrupt_values", f"values up to {float(np.max(np.abs(x))):.3g} in more than 1 % of "
                    "the window: too large to process, corrupt values, not a signal")
    if spread <= 0.0:
        return None
    with np.errstate(over="ignore"):
        distance = np.abs(x - mid)
    far = distance > CORRUPT_FACTOR * spread
    if not far.any():
        return None
    worst = float(x[int(np.argmax(distance))])
    return Flag("corrupt_values", f"{int(far.sum())} sample(s) more than {CORRUPT_FACTOR:g} times the "
                f"window's 1-99 % range ({spread:.3g}) from its median, the farthest {worst:.3g}: "
                "corrupt values, not a signal")

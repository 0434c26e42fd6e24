"""What a coach can learn about one person's heart from the means its rule updates see.

Heart rate follows exercise demand with a lag: a quick part (about a third of the change,
within ~10 s) and a slow part (the rest, after a few seconds of dead time, with a time
constant of about a minute). So a 30-s mean taken one minute after a change still shows
much of the old activity. :class:`ResponseModel` fits that picture to the rule updates'
means: for each activity level it estimates the *gain* (bpm above rest per unit of drive),
choosing the slow time constant from a small grid, with recent windows weighted more (the
heart drifts up over a session). From the gains a policy predicts where heart rate would
settle for any activity and ladder step, before trying it.

Numbers only (numpy/scipy), no clock: times are given by the caller.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

#: Grid of slow time constants tried by the fit (s): people range from about 20 to 120 s.
TAU_GRID = (30.0, 45.0, 60.0, 85.0, 120.0)


def load_scipy() -> None:
    """Import the parts of scipy the fits use (scipy.signal here, scipy.optimize in identification):
    over a second of CPU on first use, which a coach spends before its session, not at a rule update."""
    import scipy.optimize
    import scipy.signal  # noqa: F401


def first_order_lag(u: np.ndarray, tau: float, axis: int = -1) -> np.ndarray:
    """``u`` through a first-order lag of time constant ``tau`` (in samples), along ``axis``.

    scipy is imported here, not at the module's top: the coach's node and the launcher import the
    policies to list and validate them, and scipy.signal alone costs them a second of start-up.
    """
    from scipy.signal import lfilter

    a = math.exp(-1.0 / tau)
    return lfilter([1.0 - a], [1.0, -a], u, axis=axis)


@dataclass(frozen=True)
class ResponseFit:
    """Gains (bpm per unit of drive) per activity level, the chosen time constant, the fit error."""

    gains: dict[Hashable, float]
    tau: float
    rms: float  # weighted RMS residual of the window means, bpm
    windows: int


class ResponseHistory:
    """What a person performed over time (level and drive, from a time on) and the HR means seen."""

    def __init__(self) -> None:
        self.settings: list[tuple[float, Hashable, float]] = []  # (since t, level, drive)
        self.windows: list[tuple[float, float, float]] = []  # (from t, to t, mean bpm)

    def set(self, t: float, level: Hashable, drive: float) -> None:
        """From ``t`` on the person performs ``level`` at ``drive`` (the ladder's multiplier)."""
        if self.settings and t < self.settings[-1][0]:
            raise ValueError(f"settings must come in time order ({t} < {self.settings[-1][0]})")
        if self.settings and self.settings[-1][1:] == (level, drive):
            return
        self.settings.append((t, level, drive))

    def add_window(self, t0: float, t1: float, mean: float) -> None:
        """The mean heart rate over ``(t0, t1]``."""
        if t1 > t0 and math.isfinite(mean):
            self.windows.append((t0, t1, mean))

    def levels_seen(self) -> list[Hashable]:
        """The levels performed so far, in the order first performed."""
        return list(dict.fromkeys(level for _, level, _ in self.settings))


class ResponseModel(ResponseHistory):
    """Settings performed over time and the HR means seen; :meth:`fit` explains the one by the other."""

    def __init__(self, rest: float, fast_share: float = 0.35, tau_fast: float = 10.0, dead_time: float = 8.0,
                 taus: Sequence[float] = TAU_GRID, recency: float = 300.0) -> None:
        if not 0.0 <= fast_share <= 1.0:
            raise ValueError(f"fast_share must be in [0, 1], got {fast_share}")
        if tau_fast <= 0 or dead_time < 0 or recency <= 0 or not taus or min(taus) <= 0:
            raise ValueError("time constants and recency must be > 0 s, dead time >= 0 s")
        super().__init__()
        self.rest = rest
        self.fast_share = fast_share
        self.tau_fast = tau_fast
        self.dead_time = dead_time
        self.taus = tuple(float(t) for t in taus)
        self.recency = recency

    def _inputs(self, start: float, n: int) -> dict[Hashable, np.ndarray]:
        """Per level, the drive applied in each second since ``start`` (0 while another level runs)."""
        times = np.array([s[0] for s in self.settings]) - start
        which = np.searchsorted(times, np.arange(n) + 0.5, side="right") - 1
        out: dict[Hashable, np.ndarray] = {}
        for i, (_, level, drive) in enumerate(self.settings):
            u = out.setdefault(level, np.zeros(n))
            u[which == i] = drive
        return out

    def fit(self, now: float) -> ResponseFit | None:
        """Least-squares gains for the levels performed so far (None before any window)."""
        if not self.settings or not self.windows:
            return None
        start = self.settings[0][0]
        n = max(1, math.ceil(now - start))
        inputs = self._inputs(start, n)
        levels = list(inputs)
        bounds = [(max(0, math.floor(t0 - start)), min(n, math.ceil(t1 - start)))
                  for t0, t1, _ in self.windows]
        keep = [i for i, (a, b) in enumerate(bounds) if b > a]
        if not keep:
            return None
        means = np.array([self.windows[i][2] for i in keep]) - self.rest
        w = np.sqrt(0.5 ** ((now - np.array([self.windows[i][1] for i in keep])) / self.recency))
        lo = np.array([bounds[i][0] for i in keep])
        hi = np.array([bounds[i][1] for i in keep])
        u = np.stack([inputs[lv] for lv in levels])  # a row per level
        fast = first_order_lag(u, self.tau_fast, axis=1)
        delay = round(self.dead_time)
        delayed = np.concatenate([np.zeros((len(levels), delay)), u[:, :n - delay]], axis=1) if delay else u
        c = np.zeros((len(levels), n + 1))
        best: ResponseFit | None = None
        for tau in self.taus:
            slow = first_order_lag(delayed, tau, axis=1)
            response = self.fast_share * fast + (1.0 - self.fast_share) * slow
            c[:, 1:] = np.cumsum(response, axis=1)
            a_mat = np.ascontiguousarray(((c[:, hi] - c[:, lo]) / (hi - lo)).T)  # a column per level
            used = a_mat.max(axis=0) > 1e-3
            if not used.any():
                return None
            sol, *_ = np.linalg.lstsq(a_mat[:, used] * w[:, None], means * w, rcond=None)
            gains_used = np.maximum(sol, 0.0)
            resid = (a_mat[:, used] @ gains_used - means) * w
            rms = float(np.sqrt(np.sum(resid ** 2) / np.sum(w ** 2)))
            if best is None or rms < best.rms - 1e-9:
                fitted = [lv for lv, on in zip(levels, used, strict=True) if on]
                gains = {lv: float(g) for lv, g in zip(fitted, gains_used, strict=True)}
                best = ResponseFit(gains, tau, rms, len(keep))
        return best

"""Online identification of one person's heart-rate response, with its uncertainty.

What a coach sees are the means of its rule updates' windows (30 s of 1-Hz heart rate) and the
settings it ran (activity level and the ladder's drive, from when). :class:`ResponseEstimator`
explains the one by the other with a small linear-in-the-gains model, re-fitted at every rule
update from everything seen so far:

    HR(t) - rest = sum over levels l of  fast_l * F_l(t) + slow_l * S_l(t; tau)  +  drift * D(t)

* ``F_l`` is the level's drive (0 while another level runs) through a quick first-order lag
  (``tau_fast``); ``S_l`` the same drive delayed by ``dead_time`` through a slow lag ``tau``;
  ``D`` the minutes of exercise so far (cardiovascular drift, bpm/min).
* The *gains* (``fast_l``, ``slow_l``, ``drift``) enter linearly: for a given ``tau`` they are a
  weighted ridge least-squares solution (a Gaussian prior: the fast share of a level's gain near
  ``fast_share``, drift near 0, levels with a stated cost in METs near the same gain per net MET, so
  a level seen for a minute borrows strength from one seen for five), i.e. the posterior mean of a
  linear-Gaussian model; its covariance is the gains' uncertainty.
* ``tau`` is not taken from a list: it is the minimiser (scipy's bounded scalar search over
  ``log tau``) of the profiled residual plus a log-normal prior (median ``tau_prior`` s), and its
  uncertainty comes from the curvature of that profile.

A setting's *settled* heart rate is ``rest + drive * (fast_l + slow_l)`` (plus the drift reached and
the ``offset`` the last two windows show beyond the fit: offset-free prediction, as in model-predictive
control),
with a standard deviation from the gains' covariance and from ``tau``'s uncertainty (a slow
responder still climbing leaves the gain uncertain: the band is wide until the data pin it).
:meth:`ResponseEstimator.trajectory` predicts the next seconds of the current setting.

Numbers only (numpy/scipy), no clock: times are given by the caller.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Hashable
from dataclasses import dataclass

import numpy as np

from hri_physio_coach.policies.response_model import ResponseHistory, first_order_lag


@dataclass(frozen=True)
class Estimate:
    """The identified response: gains per level, their covariance, time constant and noise."""

    levels: tuple[Hashable, ...]
    theta: np.ndarray  # fast_0, slow_0, fast_1, slow_1, ..., drift (bpm per unit drive; drift bpm/min)
    cov: np.ndarray  # posterior covariance of theta
    tau: float  # s, the slow time constant
    log_tau_sd: float  # uncertainty of log(tau)
    sigma: float  # bpm, residual SD of a window mean
    windows: int
    gains_lo: dict[Hashable, float]  # settled gain (fast + slow) if tau were one SD shorter ...
    gains_hi: dict[Hashable, float]  # ... and one SD longer
    offset: float = 0.0  # bpm: what the last two windows show beyond the fit (a persistent disturbance)

    def gain(self, level: Hashable) -> float | None:
        if level not in self.levels:
            return None
        i = self.levels.index(level)
        return float(self.theta[2 * i] + self.theta[2 * i + 1])

    def gain_sd(self, level: Hashable) -> float | None:
        """SD of the settled gain: the gains' covariance and half the spread over tau's interval."""
        if level not in self.levels:
            return None
        i = self.levels.index(level)
        e = np.zeros(len(self.theta))
        e[2 * i] = e[2 * i + 1] = 1.0
        var = float(e @ self.cov @ e)
        spread = 0.5 * abs(self.gains_hi[level] - self.gains_lo[level])
        return math.sqrt(max(var, 0.0) + spread ** 2)

    @property
    def drift(self) -> float:
        return float(self.theta[-1])


class ResponseEstimator(ResponseHistory):
    """Settings performed over time and the window means seen; :meth:`fit` identifies the response."""

    def __init__(self, rest: float, tau_fast: float = 6.0, dead_time: float = 5.0, fast_share: float = 0.3,
                 fast_share_sd: float = 0.25, tau_prior: float = 60.0, log_tau_prior_sd: float = 0.5,
                 tau_bounds: tuple[float, float] = (10.0, 300.0), drift_prior_sd: float = 0.4,
                 noise: float = 1.5, recency: float = 360.0, per_met_sd: float = 3.0,
                 same_cost_sd: float = 1.2) -> None:
        if tau_fast <= 0 or dead_time < 0 or recency <= 0 or noise <= 0:
            raise ValueError("tau_fast, recency and noise must be > 0, dead_time >= 0")
        if not 0 < tau_bounds[0] < tau_prior < tau_bounds[1]:
            raise ValueError(f"need 0 < tau_bounds[0] < tau_prior < tau_bounds[1], got {tau_bounds}, "
                             f"{tau_prior}")
        super().__init__()
        self.rest = rest
        self.tau_fast = tau_fast
        self.dead_time = dead_time
        self.fast_share = fast_share
        self.fast_share_sd = fast_share_sd
        self.tau_prior = tau_prior
        self.log_tau_prior_sd = log_tau_prior_sd
        self.tau_bounds = tau_bounds
        self.drift_prior_sd = drift_prior_sd
        self.noise = noise
        self.recency = recency
        self.per_met_sd = per_met_sd
        self.same_cost_sd = same_cost_sd
        self.costs: dict[Hashable, float] = {}  # stated cost (METs) of each level named otherwise
        self._last_tau = tau_prior

    def set(self, t: float, level: Hashable, drive: float, cost: float | None = None) -> None:
        """From ``t`` on ``level`` (an activity, or its cost) runs at ``drive``; ``cost``: its stated METs."""
        if cost is not None:
            self.costs[level] = float(cost)
        super().set(t, level, drive)

    def cost_of(self, level: Hashable) -> float | None:
        """The stated cost (METs, > 1) of a level: given with it, or the level itself when it is a number."""
        cost = self.costs.get(level)
        if cost is None and isinstance(level, int | float) and not isinstance(level, bool):
            cost = float(level)
        return cost if cost is not None and cost > 1.0 else None

    # --- the model's columns --------------------------------------------------------------------
    def _inputs(self, start: float, n: int, levels: list[Hashable]) -> np.ndarray:
        """Drive per level (rows) in each second since ``start`` (0 while another level runs)."""
        times = np.array([s[0] for s in self.settings]) - start
        which = np.searchsorted(times, np.arange(n) + 0.5, side="right") - 1
        u = np.zeros((len(levels), n))
        for i, (_, level, drive) in enumerate(self.settings):
            u[levels.index(level), which == i] = drive
        return u

    def _slow(self, u: np.ndarray, tau: float) -> np.ndarray:
        delay = round(self.dead_time)
        if delay:
            u = np.concatenate([np.zeros((u.shape[0], delay)), u[:, :u.shape[1] - delay]], axis=1)
        return first_order_lag(u, tau, axis=1)

    @staticmethod
    def _window_means(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Mean of each row of ``x`` over each window ``[lo, hi)`` (rows x windows)."""
        c = np.zeros((x.shape[0], x.shape[1] + 1))
        c[:, 1:] = np.cumsum(x, axis=1)
        return (c[:, hi] - c[:, lo]) / (hi - lo)

    @staticmethod
    def _design(slow: np.ndarray, fast: np.ndarray, ramp: np.ndarray) -> np.ndarray:
        """The design matrix from the columns' window means (:meth:`_window_means`): fast/slow per level
        interleaved, then drift; windows are rows."""
        cols = np.empty((2 * len(slow) + 1, ramp.shape[-1]))
        cols[0:-1:2] = fast
        cols[1:-1:2] = slow
        cols[-1] = ramp
        return cols.T

    def _prior(self, levels: list[Hashable]) -> tuple[np.ndarray, np.ndarray]:
        """Ridge rows (and targets) of the prior: fast share near ``fast_share``, drift near 0, and levels
        with a stated cost near the same gain per net MET (``per_met_sd`` bpm per net MET apart; two
        activities with the same stated cost ``same_cost_sd`` apart: a label is a population mean, each
        person's cost of an activity spreads around it)."""
        k = len(levels)
        rows = [np.zeros(2 * k + 1) for _ in range(k + 1)]
        s, sd = self.fast_share, self.fast_share_sd
        for i in range(k):
            # (1 - s) fast_i - s slow_i = 0 <=> fast_i / (fast_i + slow_i) = s; SD in bpm per drive ~ sd*gain.
            rows[i][2 * i], rows[i][2 * i + 1] = (1.0 - s) / (sd * 30.0), -s / (sd * 30.0)
        rows[k][-1] = 1.0 / self.drift_prior_sd
        costed = sorted((cost, i) for i, lv in enumerate(levels) if (cost := self.cost_of(lv)) is not None)
        for (m_a, a), (m_b, b) in itertools.pairwise(costed):
            sd = self.same_cost_sd if m_a == m_b else self.per_met_sd
            row = np.zeros(2 * k + 1)
            row[2 * a:2 * a + 2] = 1.0 / ((m_a - 1.0) * sd)
            row[2 * b:2 * b + 2] = -1.0 / ((m_b - 1.0) * sd)
            rows.append(row)
        return np.array(rows), np.zeros(len(rows))

    def fit(self, now: float) -> Estimate | None:
        """The posterior of the response given everything seen up to ``now`` (None before any window)."""
        if not self.settings or not self.windows:
            return None
        levels = self.levels_seen()
        start = self.settings[0][0]
        n = max(1, math.ceil(now - start))
        spans = [(max(0, math.floor(t0 - start)), min(n, math.ceil(t1 - start)), t1, m)
                 for t0, t1, m in self.windows]
        spans = [s for s in spans if s[1] > s[0]]
        if not spans:
            return None
        lo = np.array([s[0] for s in spans])
        hi = np.array([s[1] for s in spans])
        y = np.array([s[3] for s in spans]) - self.rest
        age = now - np.array([s[2] for s in spans])
        w = np.sqrt(0.5 ** (age / self.recency)) / self.noise  # whitening: SD noise / sqrt(recency weight)
        u = self._inputs(start, n, levels)
        fast = first_order_lag(u, self.tau_fast, axis=1)
        exercising = (u.sum(axis=0) > 0).astype(float)
        ramp = np.cumsum(exercising) / 60.0  # minutes of exercise so far
        prior_rows, prior_y = self._prior(levels)

        fast_means = self._window_means(fast, lo, hi)  # the same for every slow time constant
        ramp_means = self._window_means(ramp[None, :], lo, hi)[0]

        @functools.cache  # the search's best point is asked for again
        def solve(log_tau: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
            slow_means = self._window_means(self._slow(u, math.exp(log_tau)), lo, hi)
            a = self._design(slow_means, fast_means, ramp_means)
            aw = np.vstack([a * w[:, None], prior_rows])
            yw = np.concatenate([y * w, prior_y])
            theta, *_ = np.linalg.lstsq(aw, yw, rcond=None)
            resid = aw @ theta - yw
            cost = float(resid @ resid) + ((log_tau - math.log(self.tau_prior)) / self.log_tau_prior_sd) ** 2
            return cost, theta, aw, a

        bounds = (math.log(self.tau_bounds[0]), math.log(self.tau_bounds[1]))
        from scipy.optimize import minimize_scalar  # here: see first_order_lag

        res = minimize_scalar(lambda x: solve(x)[0], bounds=bounds, method="bounded",
                              options={"xatol": 0.03, "maxiter": 25})
        log_tau = float(res.x)
        cost, theta, aw, a = solve(log_tau)
        # Curvature of the profiled cost (a Laplace approximation): the SD of log(tau).
        h = 0.15
        c_lo, c_hi = solve(log_tau - h)[0], solve(log_tau + h)[0]
        curvature = max((c_lo - 2.0 * cost + c_hi) / h ** 2, 1e-6)
        log_tau_sd = min(math.sqrt(2.0 / curvature), 1.0)
        raw = a @ theta - y
        offset = -float(np.mean(raw[-2:]))
        resid = raw * w * self.noise
        dof = max(len(y) - 2, 1)
        sigma = max(math.sqrt(float(resid @ resid) / dof), self.noise)
        scale = (sigma / self.noise) ** 2
        cov = np.linalg.pinv(aw.T @ aw) * scale
        lo_theta = solve(log_tau - log_tau_sd)[1]
        hi_theta = solve(log_tau + log_tau_sd)[1]
        gains_lo = {lv: float(lo_theta[2 * i] + lo_theta[2 * i + 1]) for i, lv in enumerate(levels)}
        gains_hi = {lv: float(hi_theta[2 * i] + hi_theta[2 * i + 1]) for i, lv in enumerate(levels)}
        self._last_tau = math.exp(log_tau)
        return Estimate(tuple(levels), theta, cov, math.exp(log_tau), log_tau_sd, sigma, len(y),
                        gains_lo, gains_hi, offset)

    def _state(self, est: Estimate, now: float, ahead: float) -> np.ndarray | None:
        """The model's columns ``ahead`` s after ``now`` if the current setting is kept (None: no data)."""
        if not self.settings:
            return None
        start = self.settings[0][0]
        n = max(1, math.ceil(now + ahead - start))
        levels = list(est.levels)
        if any(level not in levels for _, level, _ in self.settings):
            return None
        u = self._inputs(start, n, levels)
        fast = first_order_lag(u, self.tau_fast, axis=1)
        slow = self._slow(u, est.tau)
        exercising = (u.sum(axis=0) > 0).astype(float)
        ramp = np.cumsum(exercising) / 60.0
        x = np.empty(len(est.theta))
        x[0:-1:2] = fast[:, -1]
        x[1:-1:2] = slow[:, -1]
        x[-1] = ramp[-1]
        return x

    def _shifted(self, est: Estimate, sds: float) -> np.ndarray:
        """The gains with every activity's moved ``sds`` of its SDs."""
        theta = est.theta.copy()
        for i, level in enumerate(est.levels):
            g, sd = est.gain(level), est.gain_sd(level)
            if g is not None and sd is not None and g > 0:
                theta[2 * i:2 * i + 2] *= max(0.0, 1.0 + sds * sd / g)
        return theta

    def trajectory(self, est: Estimate, now: float, ahead: float, sds: float = 0.0) -> float | None:
        """Predicted heart rate ``ahead`` s after ``now`` if the current setting is kept (None: no data),
        the fit's ``offset`` included; with ``sds``, every activity's gain moved that many of its SDs
        (e.g. 1: the top of the band, what a guard against overshooting looks at)."""
        x = self._state(est, now, ahead)
        if x is None:
            return None
        theta = self._shifted(est, sds) if sds else est.theta
        return self.rest + float(x @ theta) + est.offset

    def trajectory_band(self, est: Estimate, now: float, ahead: float,
                        sds: float) -> tuple[float | None, float | None]:
        """:meth:`trajectory` and its band's edge ``sds`` SDs away, from one pass over the settings."""
        x = self._state(est, now, ahead)
        if x is None:
            return None, None
        base = self.rest + est.offset
        return base + float(x @ est.theta), base + float(x @ self._shifted(est, sds))

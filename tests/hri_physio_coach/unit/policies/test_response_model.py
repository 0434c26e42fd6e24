"""The lagged-response fit the predictive policy uses: it recovers what made the means."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hri_physio_coach.policies.response_model import ResponseModel


def first_order_means(rest: float, plan: list[tuple[float, float, float]], windows: list[tuple[float, float]],
                      tau: float, fast_share: float = 0.35, tau_fast: float = 10.0, dead: float = 8.0
                      ) -> list[float]:
    """Window means of a heart driven by ``plan`` [(from t, gain, drive)], simulated at 0.05 s (not 1 s)."""
    dt = 0.05
    end = max(w[1] for w in windows)
    t = np.arange(plan[0][0], end, dt)
    level = np.zeros_like(t)
    for start, gain, drive in plan:
        level[t >= start] = gain * drive
    delayed = np.interp(t - dead, t, level, left=0.0)
    fast = np.zeros_like(t)
    slow = np.zeros_like(t)
    for i in range(1, len(t)):
        fast[i] = fast[i - 1] + dt * (level[i] - fast[i - 1]) / tau_fast
        slow[i] = slow[i - 1] + dt * (delayed[i] - slow[i - 1]) / tau
    hr = rest + fast_share * fast + (1 - fast_share) * slow
    return [float(hr[(t > a) & (t <= b)].mean()) for a, b in windows]


def test_fit_recovers_gains_per_level_and_the_time_constant() -> None:
    rest = 70.0
    plan = [(180.0, 30.0, 0.95), (360.0, 60.0, 0.95), (480.0, 60.0, 1.05)]  # marching, stepping, faster
    windows = [(180.0 + 30 * k, 210.0 + 30 * k) for k in range(12)]
    means = first_order_means(rest, plan, windows, tau=85.0)
    model = ResponseModel(rest)
    for start, gain, drive in plan:
        model.set(start, f"level-{gain:g}", drive)
    for (a, b), m in zip(windows, means, strict=True):
        model.add_window(a, b, m)
    fit = model.fit(540.0)
    assert fit is not None
    assert fit.tau == 85.0
    assert fit.gains["level-30"] == pytest.approx(30.0, rel=0.03)
    assert fit.gains["level-60"] == pytest.approx(60.0, rel=0.03)
    assert fit.rms < 0.5


def test_a_heart_still_rising_is_predicted_to_settle_higher_than_its_last_mean() -> None:
    rest = 80.0
    plan = [(0.0, 50.0, 1.0)]
    windows = [(0.0, 30.0), (30.0, 60.0), (60.0, 90.0)]
    means = first_order_means(rest, plan, windows, tau=60.0)
    model = ResponseModel(rest)
    model.set(0.0, "stepping", 1.0)
    for (a, b), m in zip(windows, means, strict=True):
        model.add_window(a, b, m)
    fit = model.fit(90.0)
    assert fit is not None
    settled = rest + fit.gains["stepping"]
    assert means[-1] < rest + 42  # 90 s in, far from where it goes
    assert settled == pytest.approx(130.0, abs=4.0)


def test_nothing_to_fit_and_bad_inputs() -> None:
    model = ResponseModel(70.0)
    assert model.fit(100.0) is None  # no setting, no window
    model.set(0.0, "a", 1.0)
    assert model.fit(100.0) is None  # no window
    model.add_window(10.0, 10.0, 90.0)  # empty window: ignored
    model.add_window(10.0, 20.0, math.nan)  # no mean: ignored
    assert model.windows == []
    model.set(5.0, "a", 1.0)  # the same setting again: not a change
    assert len(model.settings) == 1
    with pytest.raises(ValueError, match="time order"):
        model.set(-1.0, "b", 1.0)
    with pytest.raises(ValueError):
        ResponseModel(70.0, fast_share=1.5)

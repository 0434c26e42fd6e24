"""Adaptation policies (Algorithms 1 and 2, static) and the thesis's proposed fixes."""

from __future__ import annotations

import random

import pytest

from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.policies.adapter import Adapter, AdapterOptions
from hri_physio_coach.policies.registry import make_policy
from hri_physio_coach.policies.simple import FuzzyPolicy, StaticPolicy, ThresholdPolicy
from hri_physio_coach.policies.types import (
    AT_LIMIT,
    CONDITIONING,
    COOL_DOWN,
    ENCOURAGE,
    GATED,
    HOLD,
    SCHEDULED_SLOW_DOWN,
    SLOW_DOWN,
    SPEED_UP,
    WARM_UP,
    RuleInput,
)
from hri_physio_coach.zones import HeartRateZone

ZONE = HeartRateZone.from_age(33, 85.4)  # [125.2, 155.05], target 140.125
SPEEDS = [0.90, 0.95, 1.00, 1.05, 1.10, 1.15]
TEMPOS = ["110", "115", "120", "125", "130", "135"]


def ladder(start: int = 1) -> SpeedLadder:
    return SpeedLadder(SPEEDS, TEMPOS, start)


def rule(t: float, hr: float, phase: str = CONDITIONING, start: float = 0.0, end: float = 600.0) -> RuleInput:
    return RuleInput(t=t, hr=hr, zone=ZONE, phase=phase, phase_start=start, phase_end=end)


class ScriptedRng:
    """Stands in for the policy's random.Random: returns the given draws in order."""

    def __init__(self, draws: list[float]) -> None:
        self.draws = list(draws)

    def random(self) -> float:
        return self.draws.pop(0)


def run(adapter: Adapter, hrs: list[float], phase: str = CONDITIONING, period: float = 30.0,
        start: float = 0.0, end: float = 600.0) -> list:
    return [adapter.update(rule(start + period * (i + 1), hr, phase, start, end)) for i, hr in enumerate(hrs)]


def test_threshold_algorithm_1() -> None:
    a = Adapter(ThresholdPolicy(), ladder(1))
    decisions = run(a, [110.0, ZONE.low, 140.0, ZONE.high, 160.0, 170.0, 120.0])  # bounds are in the zone
    assert [d.action for d in decisions] == [SPEED_UP, ENCOURAGE, ENCOURAGE, ENCOURAGE, SLOW_DOWN, SLOW_DOWN,
                                             SPEED_UP]
    assert [d.index_after for d in decisions] == [2, 2, 2, 2, 1, 0, 1]
    assert decisions[0].zone_state == "below" and decisions[4].zone_state == "above"
    assert "< zone low 125.2" in decisions[0].reason and "> zone high 155.1" in decisions[4].reason
    assert all(d.policy == "threshold" for d in decisions)


def test_fuzzy_algorithm_2_with_scripted_draws() -> None:
    policy = FuzzyPolicy(seed=1)
    a = Adapter(policy, ladder(2))
    p130 = ZONE.adaptation_probability(130.0)  # ~0.68
    p150 = ZONE.adaptation_probability(150.0)  # ~0.66
    policy.rng = ScriptedRng([p130 - 0.01, p130 + 0.01, p150 - 0.01, 0.0, 0.999999, 0.5])
    decisions = run(a, [130.0, 130.0, 150.0, ZONE.target, 100.0, 141.0])
    assert [d.action for d in decisions] == [SPEED_UP, ENCOURAGE, SLOW_DOWN, ENCOURAGE, SPEED_UP, ENCOURAGE]
    assert [d.index_after for d in decisions] == [3, 3, 2, 2, 3, 3]
    assert decisions[0].p == pytest.approx(p130) and decisions[0].draw == pytest.approx(p130 - 0.01)
    assert decisions[3].p == 0.0  # at the target even a draw of 0 does not update (0 < 0 is false)
    assert decisions[4].p == 1.0  # far below the zone: always updates


def test_fuzzy_is_seeded_and_updates_with_probability_p() -> None:
    def decisions(seed: int) -> list[int]:
        a = Adapter(FuzzyPolicy(seed), ladder(2))
        out = []
        for i in range(2000):
            a.ladder.index = 2  # stay off the ladder ends
            out.append(a.update(rule(30.0 * i, 132.66)).delta)  # p = 0.5
        return out

    first, again, other = decisions(7), decisions(7), decisions(8)
    assert first == again
    assert first != other
    rate = sum(1 for d in first if d != 0) / len(first)
    assert rate == pytest.approx(0.5, abs=0.04)
    assert set(first) == {0, 1}  # below the target: only speed-ups


def test_static_never_adapts() -> None:
    a = Adapter(StaticPolicy(), ladder(1))
    decisions = run(a, [60.0, 200.0, 140.0, 100.0, 180.0])
    assert {d.action for d in decisions} == {ENCOURAGE}
    assert a.ladder.index == 1


def test_make_policy() -> None:
    assert make_policy("threshold").name == "threshold"
    assert make_policy("fuzzy", seed=3).name == "fuzzy"
    assert make_policy("static").name == "static"
    with pytest.raises(ValueError, match="unknown adaptation policy 'pid'"):
        make_policy("pid")


def test_refractory_period() -> None:
    a = Adapter(ThresholdPolicy(), ladder(0), AdapterOptions(refractory_period=60.0))
    decisions = run(a, [110.0] * 5)  # t = 30, 60, 90, 120, 150
    assert [d.action for d in decisions] == [SPEED_UP, HOLD, SPEED_UP, HOLD, SPEED_UP]
    assert "refractory: 30 s since the last update < 60 s" in decisions[1].reason
    # Without the option every update adapts.
    plain = run(Adapter(ThresholdPolicy(), ladder(0)), [110.0] * 5)
    assert [d.action for d in plain] == [SPEED_UP] * 5
    # Off unless a period is given.
    assert AdapterOptions().refractory_period is None


def test_conditioning_only() -> None:
    a = Adapter(ThresholdPolicy(), ladder(1), AdapterOptions(conditioning_only=True))
    warm = run(a, [110.0, 110.0], phase=WARM_UP)
    cond = run(a, [110.0, 170.0], phase=CONDITIONING)
    cool = run(a, [170.0], phase=COOL_DOWN)
    assert [d.action for d in warm] == [HOLD, HOLD]
    assert "restricted to conditioning" in warm[0].reason
    assert [d.action for d in cond] == [SPEED_UP, SLOW_DOWN]
    assert [d.action for d in cool] == [HOLD]
    assert a.ladder.index == 1


def test_cooldown_schedule_lowers_tempo_through_cooldown() -> None:
    a = Adapter(ThresholdPolicy(), ladder(5), AdapterOptions(cooldown_schedule=True))
    # Cool-down 1080..1380 s, rule updates every 30 s; HR far below the zone would mean "speed up".
    decisions = run(a, [100.0] * 9, phase=COOL_DOWN, start=1080.0, end=1380.0)
    # floor(5 * remaining / 300) at 30, 60, ..., 270 s into the cool-down.
    assert [d.index_after for d in decisions] == [4, 4, 3, 3, 2, 2, 1, 1, 0]
    assert {d.action for d in decisions} == {SCHEDULED_SLOW_DOWN, HOLD}
    assert all(d.delta <= 0 for d in decisions)
    # Without the schedule the same HR speeds up in the cool-down.
    plain = run(Adapter(ThresholdPolicy(), ladder(4)), [100.0], phase=COOL_DOWN, start=1080.0, end=1380.0)
    assert plain[0].action == SPEED_UP


def test_warmup_speedup_cap() -> None:
    a = Adapter(ThresholdPolicy(), ladder(0), AdapterOptions(warmup_max_speedups=2))
    warm = run(a, [110.0] * 4, phase=WARM_UP)
    assert [d.action for d in warm] == [SPEED_UP, SPEED_UP, HOLD, HOLD]
    assert "warm-up speed-up cap 2 reached" in warm[2].reason
    assert a.warmup_speedups == 2
    slow = run(a, [170.0], phase=WARM_UP)  # slowing down is never capped
    assert slow[0].action == SLOW_DOWN
    cond = run(a, [110.0, 110.0], phase=CONDITIONING)  # the cap is for the warm-up only
    assert [d.action for d in cond] == [SPEED_UP, SPEED_UP]


@pytest.mark.parametrize("policy", ["threshold", "fuzzy", "static"])
@pytest.mark.parametrize("options", [
    AdapterOptions(), AdapterOptions(refractory_period=60.0, cooldown_schedule=True, warmup_max_speedups=1)])
def test_ladder_limits_are_never_exceeded(policy: str, options: AdapterOptions) -> None:
    rng = random.Random(42)
    lad = ladder(1)
    a = Adapter(make_policy(policy, seed=5), lad, options)
    phases = [WARM_UP] * 10 + [CONDITIONING] * 20 + [COOL_DOWN] * 10
    seen = []
    for i in range(400):
        phase = phases[i % len(phases)]
        hr = rng.choice([60.0, 100.0, 124.0, 140.0, 156.0, 200.0])
        d = a.update(rule(30.0 * i, hr, phase, start=30.0 * (i - i % 10), end=30.0 * (i - i % 10) + 300.0))
        assert 0 <= d.index_after <= 5 and abs(d.delta) <= 5
        assert 0.90 <= lad.speed <= 1.15 and 110.0 <= (lad.tempo or 0) <= 135.0
        seen.append(d.action)
    if policy != "static":
        assert AT_LIMIT in seen  # pushing at the ends was attempted and refused


def test_at_limit_both_ends() -> None:
    top = Adapter(ThresholdPolicy(), ladder(5))
    d = top.update(rule(30.0, 100.0))
    assert (d.action, d.proposed, d.delta, d.index_after) == (AT_LIMIT, 1, 0, 5)
    assert "already at the fastest step" in d.reason
    bottom = Adapter(ThresholdPolicy(), ladder(0))
    d = bottom.update(rule(30.0, 180.0))
    assert (d.action, d.proposed, d.delta) == (AT_LIMIT, -1, 0)
    assert "slowest" in d.reason
    # An at-limit refusal does not start a refractory period.
    assert bottom.last_adaptation is None


def test_gated_decision_records_why() -> None:
    a = Adapter(ThresholdPolicy(), ladder(2))
    d = a.gated(90.0, "too few valid HR samples: 3 < 10", hr=150.0)
    assert (d.action, d.delta, d.index_before, d.index_after) == (GATED, 0, 2, 2)
    assert d.as_dict()["reason"] == "too few valid HR samples: 3 < 10"
    assert d.as_dict()["changed"] is False


@pytest.mark.parametrize("kwargs", [{"refractory_period": -1.0}, {"warmup_max_speedups": -2}])
def test_bad_options(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        AdapterOptions(**kwargs)

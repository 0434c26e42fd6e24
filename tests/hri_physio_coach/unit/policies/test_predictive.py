"""The predictive policy, rule update by rule update, on a heart that follows a known response."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import pytest

from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.policies.adapter import Adapter
from hri_physio_coach.policies.predictive import OUT_OF_REACH_BELOW, ROUTINE, PredictivePolicy, Setting
from hri_physio_coach.policies.registry import make_policy
from hri_physio_coach.policies.types import (
    CHANGE_ACTIVITY,
    CONDITIONING,
    COOL_DOWN,
    ENCOURAGE,
    OUT_OF_REACH,
    SCHEDULED_SLOW_DOWN,
    WARM_UP,
    Controls,
    RuleInput,
)
from hri_physio_coach.zones import HeartRateZone

SPEEDS = (0.90, 0.95, 1.00, 1.05, 1.10, 1.15)
SUFFIXES = ("110", "115", "120", "125", "130", "135")
TEMPOS = tuple(float(s) for s in SUFFIXES)
LEVELS = (3.5, 5.8, 6.3)
ZONE = HeartRateZone.from_age(33, 80.0)  # [122.2, 153.8]
WARM = (180.0, 480.0)
COND = (480.0, 1080.0)
COOL = (1080.0, 1380.0)
# The conditioning of the packaged routine: (duration, cost) of its slots.
MIX = (("conditioning", ((60.0, 3.5), (120.0, 5.8), (60.0, 3.5), (120.0, 6.3), (60.0, 3.5), (120.0, 5.8),
                         (60.0, 3.5))),)


class Heart:
    """A heart whose HR settles at rest + gain[level] * drive, with a 60 s lag (what the policy assumes)."""

    def __init__(self, gains: dict[float, float], rest: float = 80.0) -> None:
        self.gains = gains
        self.rest = rest
        self.hr = rest
        self.target = rest

    def set(self, policy: PredictivePolicy, level: float, index: int) -> None:
        c = controls(level, index)
        self.target = self.rest + self.gains[level] * policy.drive(c, index)

    def run(self, seconds: float) -> float:
        """Mean HR over the next ``seconds`` (first-order, tau 60 s)."""
        total = 0.0
        for _ in range(int(seconds)):
            self.hr += (self.target - self.hr) / 60.0
            total += self.hr
        return total / int(seconds)


def controls(mets: float, index: int, chosen: float | None = None, window_start: float = 0.0) -> Controls:
    return Controls(activity=f"a{mets}", mets=mets, chosen=chosen, levels=LEVELS, speeds=SPEEDS,
                    tempos=TEMPOS, index=index, window_start=window_start, routine_costs=MIX)


class Session:
    """The routine's warm-up (marching, then stepping) and conditioning, rule updates every 30 s."""

    def __init__(self, gains: dict[float, float]) -> None:
        self.policy = PredictivePolicy()
        self.ladder = SpeedLadder(SPEEDS, SUFFIXES, 1)
        self.adapter = Adapter(self.policy, self.ladder)
        self.heart = Heart(gains)
        self.mets = 3.5
        self.decisions = []

    def performing(self, t: float, routine_mets: float) -> None:
        level = self.adapter.level if self.adapter.level is not None else routine_mets
        self.mets = level
        self.heart.set(self.policy, level, self.ladder.index)
        self.adapter.observe(t, controls(level, self.ladder.index, self.adapter.level))

    def rule(self, t: float, phase: str, span: tuple[float, float]) -> None:
        hr = self.heart.run(30)
        inp = RuleInput(t, hr, ZONE, phase, span[0], span[1],
                        controls(self.mets, self.ladder.index, self.adapter.level, t - 30))
        d = self.adapter.update(inp)
        self.decisions.append(d)
        if d.changed:
            self.performing(t, self.mets)

    def warm_up(self) -> None:
        self.performing(180.0, 3.5)
        for t in range(210, 481, 30):
            if t == 390:
                self.performing(360.0, 5.8)  # the routine's step-up starts at 360
            self.rule(float(t), WARM_UP, WARM)

    def conditioning(self) -> None:
        for t in range(510, 1081, 30):
            self.rule(float(t), CONDITIONING, COND)


def test_the_warm_up_is_not_spent_climbing_and_the_conditioning_is_set_up_one_lag_ahead() -> None:
    s = Session({3.5: 25.0, 5.8: 55.0, 6.3: 60.0})  # stepping at 120 BPM settles at 135 bpm
    s.warm_up()
    early = [d for d in s.decisions if d.t < 420]
    assert all(not d.changed for d in early)  # measuring, not climbing
    plan = next(d for d in s.decisions if d.changed)
    assert plan.t == 420.0  # one lag (60 s) before the conditioning
    assert plan.action == CHANGE_ACTIVITY and plan.level_after == 5.8  # keep stepping through it
    target = ZONE.low + 0.5 * (ZONE.high - ZONE.low)
    settled = s.heart.rest + 55.0 * s.policy.drive(controls(5.8, s.ladder.index), s.ladder.index)
    assert abs(settled - target) < 4.0  # the chosen step lands near the zone's middle
    s.conditioning()
    changes = [d for d in s.decisions if d.changed and d.t > 480]
    assert len(changes) <= 1
    assert ZONE.low <= s.heart.hr <= ZONE.high


def test_an_unfit_person_marches_and_the_zone_is_not_overshot() -> None:
    s = Session({3.5: 55.0, 5.8: 110.0, 6.3: 120.0})  # stepping would settle far above the zone
    s.warm_up()
    s.conditioning()
    assert s.adapter.level == 3.5  # marching
    assert ZONE.low <= s.heart.hr <= ZONE.high


def test_out_of_reach_below_is_said_once_and_the_hardest_setting_is_kept() -> None:
    s = Session({3.5: 10.0, 5.8: 25.0, 6.3: 27.0})  # a very fit person: even the hardest settles below
    s.warm_up()
    s.conditioning()
    notices = [d for d in s.decisions if d.action == OUT_OF_REACH]
    assert len(notices) == 1 and notices[0].notice == OUT_OF_REACH_BELOW
    assert (s.adapter.level, s.ladder.index) == (6.3, len(SPEEDS) - 1)
    late = [d for d in s.decisions if d.t > notices[0].t]
    assert late and all(d.action == ENCOURAGE for d in late)  # no cycling after the notice


def test_cool_down_plan_is_the_easiest_activity_at_the_slowest_step() -> None:
    s = Session({3.5: 25.0, 5.8: 55.0, 6.3: 60.0})
    s.warm_up()
    s.conditioning()
    c = controls(s.mets, s.ladder.index, s.adapter.level)
    inp = RuleInput(1080.0, s.heart.hr, ZONE, COOL_DOWN, *COOL, c)
    d = s.adapter.plan(inp)
    assert d is not None and d.action == SCHEDULED_SLOW_DOWN
    assert (s.adapter.level, s.ladder.index) == (3.5, 0)
    assert d.level_before == 5.8 and d.level_after == 3.5 and d.changed


def test_other_policies_never_plan_nor_pick_activities() -> None:
    for name in ("threshold", "fuzzy", "static"):
        adapter = Adapter(make_policy(name), SpeedLadder(SPEEDS, SUFFIXES, 1))
        assert not adapter.chooses_activity
        inp = RuleInput(1080.0, 130.0, ZONE, COOL_DOWN, *COOL, controls(5.8, 1))
        assert adapter.plan(inp) is None
        d = adapter.update(replace(inp, t=1110.0, hr=100.0))
        assert d.level_before is None and d.level_after is None
    assert make_policy("predictive").chooses_activity


def test_prediction_uses_the_stated_costs_for_an_activity_not_tried_yet() -> None:
    s = Session({3.5: 25.0, 5.8: 55.0, 6.3: 60.0})
    s.warm_up()
    c = controls(5.8, 2)
    arms = s.policy.gain(6.3)
    steps = s.policy.gain(5.8)
    assert arms is not None and steps is not None
    assert arms / steps == pytest.approx((6.3 - 1) / (5.8 - 1))
    assert math.isfinite(s.policy.predict(RuleInput(420, 130, ZONE, WARM_UP, *WARM, c), c,
                                          s.policy.best(RuleInput(420, 130, ZONE, WARM_UP, *WARM, c), c)))


def test_between_marching_and_stepping_the_routine_keeps_its_own_alternation() -> None:
    s = Session({3.5: 20.0, 5.8: 90.0, 6.3: 99.0})  # marching settles below the zone, stepping above it
    s.warm_up()
    c = controls(s.mets, s.ladder.index, s.adapter.level)
    inp = RuleInput(480.0, 130.0, ZONE, CONDITIONING, *COND, c)
    singles = [s.policy.predict(inp, c, Setting(level, k)) for level in LEVELS for k in range(len(SPEEDS))]
    assert not any(ZONE.low <= p <= ZONE.high for p in singles)  # no activity held lands in the zone
    assert s.adapter.level is None  # the routine's own activities, slot by slot
    mix = s.policy.predict(inp, c, Setting(ROUTINE, s.ladder.index))
    assert ZONE.low <= mix <= ZONE.high


@pytest.mark.parametrize("name", ["predictive", "adaptive"])
def test_warm_up_imports_what_the_first_fit_needs_so_no_rule_update_stalls_on_it(name: str) -> None:
    # A fresh interpreter: this one may have imported scipy already. Importing the policies must not
    # load scipy (the launcher lists them); warm_up must, so the fits' lazy imports find it loaded.
    script = (
        "import sys\n"
        "from hri_physio_coach.policies.registry import make_policy\n"
        f"policy = make_policy({name!r})\n"
        "before = {m for m in ('scipy.signal', 'scipy.optimize') if m in sys.modules}\n"
        "policy.warm_up()\n"
        "after = {m for m in ('scipy.signal', 'scipy.optimize') if m in sys.modules}\n"
        "print(sorted(before), sorted(after))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                         check=True)
    assert out.stdout.split("\n")[0] == "[] ['scipy.optimize', 'scipy.signal']", out.stdout + out.stderr


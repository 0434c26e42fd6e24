"""The ``predictive`` policy: predict where heart rate will settle, and hold what lands mid-zone.

What it does, and the facts about exercising hearts it rests on:

* Heart rate lags demand by about a minute, so the mean of the last 30 s says little about
  where it is going. The policy fits a lagged response to every rule update's mean
  (:class:`~hri_physio_coach.policies.response_model.ResponseModel`) and acts on the *predicted
  steady state* of the current setting, not on the last mean.
* Tempo and gesture speed move demand only a little; the activity moves it a lot (marching
  vs stepping is about a factor of two). So the policy uses both controls: the activity
  (any activity of the routine with a stated cost in METs, run in place of the routine's own
  within the same phase and duration, announced by the robot) and the speed ladder.
* The warm-up is not spent climbing the ladder: it runs as written (marching, then
  stepping), which shows how this person responds to both. One lag (``lead``, 60 s) before
  the conditioning starts, the policy picks the activity and step predicted to settle in the
  middle of the zone, so heart rate arrives there when the conditioning begins.
* In the conditioning it holds that setting while the prediction stays inside the zone's
  inner band, and re-plans (at most once per ``hold`` seconds) when it drifts out.
* When no single activity settles inside the zone (marching too easy, stepping too hard),
  it hands the activities back to the routine, whose alternation averages in between, at
  the step whose average is predicted nearest the middle.
* The cool-down runs the easiest activity at the slowest step, so heart rate ends below
  HRR40 where the person can get there.
* When no setting can reach the zone (heart rate stays below it with the hardest activity at
  the fastest step, or above it with the easiest at the slowest), it says so once (a
  ``notice``) and keeps the closest setting instead of cycling.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

from hri_physio_coach.policies.response_model import ResponseFit, ResponseModel, load_scipy
from hri_physio_coach.policies.types import (
    CONDITIONING,
    COOL_DOWN,
    FOLLOW_ROUTINE,
    WARM_UP,
    BasePolicy,
    Controls,
    Proposal,
    RuleInput,
)

#: The "level" of running the routine's own activities, slot by slot (its mix of costs).
ROUTINE = "routine"
#: Notices (said once per session).
OUT_OF_REACH_BELOW = "zone_out_of_reach_below"
OUT_OF_REACH_ABOVE = "zone_out_of_reach_above"


@dataclass(frozen=True)
class Setting:
    level: Hashable  # the activity's cost in METs (or its name when the routine states none)
    index: int  # ladder step


class PredictivePolicy(BasePolicy):
    """Acts on the predicted steady-state heart rate, with the activity and the ladder as controls."""

    name = "predictive"
    chooses_activity = True

    def __init__(self, target: float = 0.5, band: float = 0.2, hold: float = 60.0, lead: float = 60.0,
                 settle: float = 90.0, tempo_gain: float = 0.65, gesture_gain: float = 0.25,
                 reference_tempo: float = 120.0) -> None:
        if not 0.0 < target < 1.0 or not 0.0 <= band < 0.5:
            raise ValueError(f"need 0 < target < 1 and 0 <= band < 0.5 (fractions of the zone), "
                             f"got {target}, {band}")
        self.target = target  # where in the zone to aim (0 = low bound, 1 = high bound)
        self.band = band  # inner margin of the zone, each side, as a fraction of its width
        self.hold = hold  # s to leave a setting alone after a change (the heart needs a lag)
        self.lead = lead  # s before the conditioning at which its setting is chosen
        self.settle = settle  # s a setting at a limit is held before the zone is declared out of reach
        self.tempo_gain = tempo_gain  # share of a tempo change a person follows (0.3-1 in studies)
        self.gesture_gain = gesture_gain  # effort per unit of gesture speed (assumed)
        self.reference_tempo = reference_tempo
        self.model = ResponseModel(rest=70.0)
        self.last_change = -math.inf
        self.prepared = False
        self.noticed: str | None = None
        self.fit: ResponseFit | None = None

    def warm_up(self) -> None:
        load_scipy()

    # --- what is being performed ----------------------------------------------------------------
    @staticmethod
    def level_of(c: Controls) -> Hashable | None:
        return c.mets if c.mets is not None else c.activity

    def drive(self, c: Controls, index: int) -> float:
        """How much a ladder step multiplies an activity's demand (1 at the reference tempo, speed 1)."""
        tempo = c.tempos[index]
        tempo_part = 1.0 + self.tempo_gain * (tempo / self.reference_tempo - 1.0) if tempo else 1.0
        return tempo_part * (1.0 + self.gesture_gain * (c.speeds[index] - 1.0))

    def observe(self, t: float, c: Controls) -> None:
        level = self.level_of(c)
        if level is not None:
            self.model.set(t, level, self.drive(c, c.index))

    def plan(self, inp: RuleInput) -> Proposal | None:
        """At a phase start: the cool-down gets the easiest setting; the conditioning its plan if not made."""
        c = inp.controls
        if c is None:
            return None
        if inp.phase == COOL_DOWN:
            level = min(c.levels) if c.levels else None
            return Proposal(-c.index, "cool-down: the easiest activity at the slowest step", level=level)
        if inp.phase != WARM_UP and not self.prepared and self.fit_now(inp.t) is not None:
            self.prepared = True
            return self._move(inp, c, self.best(inp, c), "plan for the conditioning")
        return None

    # --- predictions ----------------------------------------------------------------------------
    def fit_now(self, t: float) -> ResponseFit | None:
        self.fit = self.model.fit(t)
        return self.fit

    def gain(self, level: Hashable) -> float | None:
        """bpm per unit of drive for ``level``: fitted, or scaled from a fitted level by the net METs."""
        if self.fit is None:
            return None
        if level in self.fit.gains:
            return self.fit.gains[level]
        if not isinstance(level, int | float):
            return None
        known = [(lv, g) for lv, g in self.fit.gains.items() if isinstance(lv, int | float) and lv > 1.0]
        if not known:
            return None
        ref, g = min(known, key=lambda kg: abs(kg[0] - level))
        return g * (level - 1.0) / (ref - 1.0)

    @staticmethod
    def routine_mix(inp: RuleInput, c: Controls) -> tuple[tuple[float, float], ...]:
        """(duration, cost) of the routine's own activities in the phase a decision is for."""
        kind = CONDITIONING if inp.phase == WARM_UP else inp.phase
        return next((slots for k, slots in c.routine_costs if k == kind), ())

    def predict(self, inp: RuleInput, c: Controls, s: Setting) -> float | None:
        """The heart rate (bpm) the setting would settle at (the routine's mix: its time average)."""
        if s.level == ROUTINE:
            mix = self.routine_mix(inp, c)
            gains = [(d, self.gain(m)) for d, m in mix]
            if not mix or any(g is None for _, g in gains):
                return None
            mean_gain = sum(d * g for d, g in gains if g is not None) / sum(d for d, _ in gains)
            return inp.zone.hr_rest + mean_gain * self.drive(c, s.index)
        g = self.gain(s.level)
        return None if g is None else inp.zone.hr_rest + g * self.drive(c, s.index)

    def current(self, c: Controls) -> Setting:
        """The setting in force: the level the policy holds, or the routine's own activities."""
        if c.levels:
            return Setting(ROUTINE if c.chosen is None else c.chosen, c.index)
        return Setting(self.level_of(c), c.index)

    def candidates(self, c: Controls) -> list[Setting]:
        levels: list[Hashable] = list(c.levels) if c.levels else [self.level_of(c)]
        return [Setting(lv, k) for lv in levels for k in range(len(c.speeds))]

    def target_hr(self, inp: RuleInput) -> float:
        return inp.zone.low + self.target * (inp.zone.high - inp.zone.low)

    def best(self, inp: RuleInput, c: Controls) -> Setting:
        """The setting predicted to settle nearest the target (ties: fewer changes).

        One activity held is steadier than the routine's alternation, so the routine's mix is
        a candidate only when no single activity settles inside the zone.
        """
        current = self.current(c)
        doing = self.level_of(c)
        target = self.target_hr(inp)

        def scored(settings: list[Setting]) -> list[tuple[float, float, Setting]]:
            out = []
            for s in settings:
                pred = self.predict(inp, c, s)
                if pred is not None:
                    switch = 0.0 if s.level in (current.level, doing) else 1.0  # keep doing what you do
                    out.append((abs(pred - target) + switch + 0.2 * abs(s.index - c.index), pred, s))
            return out

        single = scored(self.candidates(c))
        if not single:
            return current
        best = min(single, key=lambda x: x[0])
        if not inp.zone.low <= best[1] <= inp.zone.high and c.levels and self.routine_mix(inp, c):
            mixes = scored([Setting(ROUTINE, k) for k in range(len(c.speeds))])
            best = min([best, *mixes], key=lambda x: x[0])
        return best[2]

    # --- decisions ------------------------------------------------------------------------------
    def _move(self, inp: RuleInput, c: Controls, s: Setting, why: str) -> Proposal:
        pred = self.predict(inp, c, s)
        text = f"{why}: predicted {pred:.0f} bpm" if pred is not None else why
        if not c.levels:
            level = None
        elif s.level == ROUTINE:
            level = FOLLOW_ROUTINE
        else:
            level = float(s.level)  # type: ignore[arg-type]
        if s.index == c.index and (level is None or s == self.current(c)):
            return Proposal(0, f"{text} with the current setting")
        self.last_change = inp.t
        return Proposal(s.index - c.index, f"{text} (level {s.level}, step {s.index})", level=level)

    def _learn(self, inp: RuleInput) -> Proposal | None:
        """Add the window just measured to the model; the answer when there is nothing to decide (no
        exercise setting, or the cool-down), else None."""
        c = inp.controls
        if c is None or self.level_of(c) is None:
            return Proposal(0, "no exercise setting to adapt")
        self.model.rest = inp.zone.hr_rest
        self.model.add_window(c.window_start, inp.t, inp.hr)
        if inp.phase == COOL_DOWN:
            return Proposal(0, "cool-down: holding the easiest setting")
        return None

    def propose(self, inp: RuleInput) -> Proposal:
        settled = self._learn(inp)
        if settled is not None or inp.controls is None:
            return settled or Proposal(0, "no exercise setting to adapt")
        return self._decide(inp, inp.controls)

    def _decide(self, inp: RuleInput, c: Controls) -> Proposal:
        """The rule update's decision, once the window is learnt and there is a setting to change."""
        zone = inp.zone
        measuring = inp.phase == WARM_UP and inp.t < inp.phase_end - self.lead - 1e-6
        if measuring and inp.hr < zone.low:
            return Proposal(0, "warm-up: measuring the response, not climbing the ladder")
        since = inp.t - self.last_change
        if self.prepared and since < self.hold and inp.hr <= zone.high:
            return Proposal(0, f"holding: {since:.0f} s since the last change < {self.hold:g} s")
        if self.fit_now(inp.t) is None:
            return Proposal(0, "no heart-rate response to go on yet")
        if measuring:
            doing = self.predict(inp, c, Setting(self.level_of(c), c.index))
            if doing is not None and doing > zone.high:
                return self._move(inp, c, self.best(inp, c), "warm-up: heading above the zone")
            return Proposal(0, "warm-up: measuring the response, not climbing the ladder")
        current = self.current(c)
        pred = self.predict(inp, c, current)
        if not self.prepared:
            self.prepared = True
            return self._move(inp, c, self.best(inp, c), "plan for the conditioning")
        width = zone.high - zone.low
        lo, hi = zone.low + self.band * width, zone.high - self.band * width
        if pred is not None and lo <= pred <= hi:
            return Proposal(0, f"predicted {pred:.0f} bpm, inside [{lo:.0f}, {hi:.0f}]")
        best = self.best(inp, c)
        if best != current:
            return self._move(inp, c, best, "re-plan")
        return self._out_of_reach(inp, c, pred, since)

    def _out_of_reach(self, inp: RuleInput, c: Controls, pred: float | None, since: float) -> Proposal:
        """The best setting is the current one and it misses the zone band."""
        levels = sorted(c.levels) if c.levels else [self.level_of(c)]
        level = self.current(c).level
        top = level == levels[-1] and c.index == len(c.speeds) - 1
        bottom = level == levels[0] and c.index == 0
        text = f"predicted {pred:.0f} bpm" if pred is not None else "no prediction"
        if self.noticed is None and since >= self.settle and pred is not None:
            if top and inp.hr < inp.zone.low and pred < inp.zone.low:
                self.noticed = OUT_OF_REACH_BELOW
                return Proposal(0, f"{text}: below the zone with every control at its limit",
                                notice=OUT_OF_REACH_BELOW)
            if bottom and inp.hr > inp.zone.high and pred > inp.zone.high:
                self.noticed = OUT_OF_REACH_ABOVE
                return Proposal(0, f"{text}: above the zone with every control at its lowest",
                                notice=OUT_OF_REACH_ABOVE)
        return Proposal(0, f"{text}: the closest setting already")

"""The ``adaptive`` policy: identify the person online, keep the predicted band in the zone, never sit above.

It keeps what ``predictive`` does with the routine (the warm-up runs as written and shows the
response to marching and stepping, the conditioning's setting is chosen one lag before it starts,
activities of the routine with a stated cost can run in place of a slot's own, the cool-down runs the
easiest setting) and changes how it learns and decides:

* **Online identification with uncertainty.** Every rule update re-fits
  :class:`~hri_physio_coach.policies.identification.ResponseEstimator` to all the windows seen: per
  activity (by name; activities with the same stated cost are tied a priori, as the label is only a
  population mean) a fast and a slow gain, the slow time constant (a continuous estimate with a prior,
  no list of candidates) and the drift, each with its uncertainty. A setting's prediction is a band:
  the settled heart rate +/- ``z`` standard deviations. A setting's activity cost stands for the
  activities the coach may run at it in this phase (``Controls.runs_at``): their mean gain, the band
  widened by half their spread.
* **Choosing.** A setting is scored by the distance of its predicted mean from the target and by how
  far its band pokes out of the zone (out of the top counts ``over_weight`` times more).
* **Overshoot guard.** When the window's heart rate is above the zone, or the fitted trajectory of the
  current setting crosses the zone's top within ``horizon`` s (the top of its band: every gain ``z``
  SDs up, so an activity barely seen counts as uncertain), the policy acts at this rule update,
  whatever the hold: it moves to an easier setting (the one scored best among those easier by label
  or predicted lower than the current one by a difference worth a switch: ``switch_gain`` more chance
  of settling in the zone, or ``z`` SDs). It never holds while heart rate is above the zone.
* **Stall guard.** Heart rate below the zone for ``stall`` s after the last change, and not predicted
  to get in within ``horizon`` s: a harder setting (by label, unless its own fit predicts it lower; or
  predicted higher by a difference worth a switch), even if the model predicted this one in the
  zone. A re-plan never picks a setting predicted lower while HR is below, nor another activity for a
  difference not worth a switch.
* **Labels until seen.** A level's gain is kept at least that of a level with a lower stated cost until
  it has been performed for ``trusted`` (120) s; after that its own fit counts (some people march harder
  than they step).
* **Gap strategy.** When no single setting is predicted inside the zone but one settles above and one
  below, the two alternate at the rule updates with a sigma-delta duty cycle on their predicted
  settled heart rates, so the mean sits at the target; the first switch carries the ``zone_gap``
  notice (an event of the coach, and in the report).
"""

from __future__ import annotations

import math
from collections.abc import Hashable

from hri_physio_coach.policies.identification import Estimate, ResponseEstimator
from hri_physio_coach.policies.predictive import PredictivePolicy, Setting
from hri_physio_coach.policies.types import COOL_DOWN, WARM_UP, ZONE_GAP, Controls, Proposal, RuleInput

__all__ = ["ZONE_GAP", "AdaptivePolicy"]


class AdaptivePolicy(PredictivePolicy):
    """Online-identified response, banded predictions, overshoot and stall guards, duty-cycled gaps."""

    name = "adaptive"
    chooses_activity = True

    def __init__(self, target: float = 0.5, z: float = 1.0, margin: float = 0.1, hold: float = 60.0,
                 lead: float = 60.0, settle: float = 90.0, horizon: float = 30.0, stall: float = 90.0,
                 over_weight: float = 3.0, switch_gain: float = 0.25) -> None:
        super().__init__(target=target, band=margin, hold=hold, lead=lead, settle=settle)
        self.z = z
        self.margin = margin  # fraction of the zone's width kept free at each side by the band
        self.horizon = horizon
        self.stall = stall
        self.over_weight = over_weight
        self.switch_gain = switch_gain  # gain in the chance of settling in the zone a switch must bring
        self.model = ResponseEstimator(rest=70.0)  # type: ignore[assignment]
        self.fit: Estimate | None = None  # type: ignore[assignment]
        self.gap: tuple[Setting, Setting] | None = None  # (above, below) alternated
        self.gap_acc = 0.0  # sigma-delta integral of (predicted settled HR - target) * s
        self.gap_last: float | None = None
        self.gap_said = False
        self.trusted = 120.0  # s of a level performed after which its own fit is trusted over its label
        self.now = 0.0  # time of the rule update being decided
        self.runs_at: dict[Hashable, tuple[Hashable, ...]] = {}  # cost -> activities that may run at it
        self._runs_at_seen: tuple[tuple[str, float], ...] = ()

    # --- the identified response ------------------------------------------------------------------
    def observe(self, t: float, c: Controls) -> None:
        """Identify each activity on its own (its name; its stated cost ties it to the others a priori)."""
        self._see(c)
        level = self.level_of(c)
        if level is None:
            return
        key = c.activity if c.activity is not None else level
        self.model.set(t, key, self.drive(c, c.index), cost=c.mets)  # type: ignore[call-arg]

    def _see(self, c: Controls) -> None:
        """Which activities may run at each cost in this phase (the coach's choice of activity)."""
        if c.runs_at and c.runs_at != self._runs_at_seen:
            self._runs_at_seen = c.runs_at
            by_level: dict[Hashable, list[Hashable]] = {}
            for name, cost in c.runs_at:
                by_level.setdefault(cost, []).append(name)
                self.model.costs.setdefault(name, cost)
            self.runs_at = {lv: tuple(names) for lv, names in by_level.items()}

    def fit_now(self, t: float) -> Estimate | None:  # type: ignore[override]
        self.now = t
        self.fit = self.model.fit(t)
        return self.fit

    def keys(self, level: Hashable) -> tuple[Hashable, ...]:
        """The identified activities a setting's level stands for: those that may run at that cost now,
        else those seen with that cost, else the level itself."""
        if level in self.runs_at:
            return self.runs_at[level]
        seen = tuple(k for k in self.model.levels_seen() if k != level and self.model.cost_of(k) == level)
        return seen or (level,)

    def _activity(self, key: Hashable) -> tuple[float, float] | None:
        """(gain, sd) of one activity: its fit, or, not performed yet, the nearest performed one by stated
        cost scaled by the net METs (the labels are rough: 15 % more spread)."""
        est = self.fit
        if est is None:
            return None
        g, sd = est.gain(key), est.gain_sd(key)
        if g is not None and sd is not None:
            return g, sd
        cost = self.model.cost_of(key)
        known = [(c, k) for k in est.levels if (c := self.model.cost_of(k)) is not None]
        if cost is None or not known:
            return None
        ref_cost, ref = min(known, key=lambda ck: abs(ck[0] - cost))
        ratio = (cost - 1.0) / (ref_cost - 1.0)
        g, sd = est.gain(ref), est.gain_sd(ref)
        assert g is not None and sd is not None
        return g * ratio, math.hypot(sd * ratio, 0.15 * g * ratio)

    def _level(self, level: Hashable) -> tuple[float, float] | None:
        """(gain, sd) of a level: the mean of its activities', the sd widened by half their spread (which
        of them runs depends on the slot)."""
        parts = [a for k in self.keys(level) if (a := self._activity(k)) is not None]
        if not parts:
            return None
        gains = [g for g, _ in parts]
        sd = math.sqrt(sum(s * s for _, s in parts) / len(parts))
        return sum(gains) / len(gains), math.hypot(sd, 0.5 * (max(gains) - min(gains)))

    def _raw_gain(self, level: Hashable) -> float | None:
        found = self._level(level)
        return None if found is None else found[0]

    def seen_for(self, level: Hashable, now: float) -> float:
        """Seconds ``level`` (any of its activities) has been performed so far."""
        keys = set(self.keys(level))
        settings = self.model.settings
        total = 0.0
        for i, (t0, lv, _) in enumerate(settings):
            if lv in keys:
                t1 = settings[i + 1][0] if i + 1 < len(settings) else now
                total += max(0.0, min(t1, now) - t0)
        return total

    def gain(self, level: Hashable) -> float | None:
        """The level's gain; until it has been performed for ``trusted`` s, never below that of a level with
        a lower stated cost (a level seen briefly, early, can fit low; a long-seen one is what it is:
        some people march harder than they step)."""
        g = self._raw_gain(level)
        if g is None or not isinstance(level, int | float) or self.fit is None:
            return g
        if self.seen_for(level, self.now) >= self.trusted:
            return g
        costs = {c for k in self.fit.levels if (c := self.model.cost_of(k)) is not None} | set(self.runs_at)
        for lv in costs:
            if isinstance(lv, int | float) and lv < level:
                other = self._raw_gain(lv)
                if other is not None:
                    g = max(g, other)
        return g

    def gain_sd(self, level: Hashable) -> float | None:
        found = self._level(level)
        return None if found is None else found[1]

    def drift_now(self, t: float) -> float:
        """Drift reached by now (bpm): the fitted rate times the minutes of exercise, never negative."""
        if self.fit is None or not self.model.settings:
            return 0.0
        minutes = (t - self.model.settings[0][0]) / 60.0
        return max(self.fit.drift, 0.0) * max(minutes, 0.0)

    def predict(self, inp: RuleInput, c: Controls, s: Setting) -> float | None:
        self._see(c)
        g = self.gain(s.level)
        if g is None:
            return None
        offset = self.fit.offset if self.fit is not None else 0.0
        return inp.zone.hr_rest + g * self.drive(c, s.index) + self.drift_now(inp.t) + offset

    def nominal(self, c: Controls, s: Setting) -> float:
        """How hard a setting is by its label alone: net METs times the ladder's drive (guards' ordering)."""
        mets = float(s.level) if isinstance(s.level, int | float) else 2.0
        return (mets - 1.0) * self.drive(c, s.index)

    def spread(self, c: Controls, s: Setting) -> float:
        """SD (bpm) of a setting's predicted settled heart rate."""
        self._see(c)
        sd = self.gain_sd(s.level)
        noise = self.fit.sigma if self.fit is not None else 0.0
        return math.hypot((sd or 0.0) * self.drive(c, s.index), noise)

    def candidates(self, c: Controls) -> list[Setting]:
        levels: list[Hashable] = list(c.levels) if c.levels else [self.level_of(c)]
        return [Setting(lv, k) for lv in levels for k in range(len(c.speeds))]

    def current(self, c: Controls) -> Setting:
        """What is performed now (this policy never hands the activities back to the routine's mix)."""
        return Setting(c.chosen if c.chosen is not None else self.level_of(c), c.index)

    def _move(self, inp: RuleInput, c: Controls, s: Setting, why: str) -> Proposal:
        """Run ``s`` from now on; a level the routine only happens to run now is taken over (held)."""
        pred = self.predict(inp, c, s)
        text = f"{why}: predicted {pred:.0f} bpm" if pred is not None else why
        level = float(s.level) if c.levels else None  # type: ignore[arg-type]
        if s.index == c.index and (level is None or (c.chosen is not None and level == c.chosen)):
            return Proposal(0, f"{text} with the current setting")
        self.last_change = inp.t
        return Proposal(s.index - c.index, f"{text} (level {s.level}, step {s.index})", level=level)

    # --- choosing ---------------------------------------------------------------------------------
    def _scored(self, inp: RuleInput, c: Controls,
                settings: list[Setting]) -> list[tuple[float, float, Setting]]:
        zone, current = inp.zone, self.current(c)
        target = self.target_hr(inp)
        out = []
        for s in settings:
            m = self.predict(inp, c, s)
            if m is None:
                continue
            band = self.z * self.spread(c, s)
            over = max(0.0, m + band - zone.high)
            under = 0.5 * max(0.0, zone.low - (m - band))
            switch = 0.0 if s.level == current.level else 1.0
            score = abs(m - target) + self.over_weight * over + under + switch + 0.2 * abs(s.index - c.index)
            out.append((score, m, s))
        return out

    def best(self, inp: RuleInput, c: Controls) -> Setting:
        """The best single setting (the gap strategy is decided in :meth:`_choose`)."""
        scored = self._scored(inp, c, self.candidates(c))
        return min(scored, key=lambda x: x[0])[2] if scored else self.current(c)

    def _in_zone(self, inp: RuleInput, m: float) -> bool:
        return inp.zone.low + 1.0 <= m <= inp.zone.high - 1.0

    def _gap_pair(self, inp: RuleInput, c: Controls) -> tuple[Setting, Setting] | None:
        """(closest above, closest below) the zone when no single setting is predicted inside it."""
        preds = [(m, s) for s in self.candidates(c) if (m := self.predict(inp, c, s)) is not None]
        if not preds or any(self._in_zone(inp, m) for m, _ in preds):
            return None
        above = [(m, s) for m, s in preds if m > inp.zone.high - 1.0]
        below = [(m, s) for m, s in preds if m < inp.zone.low + 1.0]
        if not above or not below:
            return None
        switch = self.current(c).level
        hi = min(above, key=lambda x: (x[0], x[1].level != switch))[1]
        lo = max(below, key=lambda x: (x[0], x[1].level == switch))[1]
        return hi, lo

    def _choose(self, inp: RuleInput, c: Controls, why: str) -> Proposal:
        pair = self._gap_pair(inp, c)
        if pair is not None:
            if self.gap != pair:
                self.gap, self.gap_acc, self.gap_last = pair, 0.0, None
            return self._gap_step(inp, c)
        self.gap = None
        return self._move(inp, c, self.best(inp, c), why)

    def _gap_step(self, inp: RuleInput, c: Controls) -> Proposal:
        """Alternate the gap's two settings so that the predicted settled heart rate averages the target."""
        assert self.gap is not None
        above, below = self.gap
        target = self.target_hr(inp)
        m_hi, m_lo = self.predict(inp, c, above), self.predict(inp, c, below)
        if m_hi is None or m_lo is None or not m_hi > target > m_lo:
            self.gap = None
            return self._move(inp, c, self.best(inp, c), "gap closed: re-plan")
        running = self.current(c)
        if self.gap_last is not None and running in (above, below):
            m = m_hi if running == above else m_lo
            self.gap_acc += (m - target) * (inp.t - self.gap_last)
            limit = (m_hi - m_lo) * 60.0
            self.gap_acc = min(max(self.gap_acc, -limit), limit)
        self.gap_last = inp.t
        nxt = above if inp.hr <= inp.zone.high and self.gap_acc < 0 else below
        duty = (target - m_lo) / (m_hi - m_lo)
        why = (f"gap: no single setting lands in the zone; alternating step {above.index} of level "
               f"{above.level} "
               f"({m_hi:.0f} bpm) and step {below.index} of level {below.level} ({m_lo:.0f} bpm), "
               f"{100 * duty:.0f} % of the time on the harder")
        proposal = self._move(inp, c, nxt, why)
        if proposal.delta == 0 and proposal.level is None:
            return proposal
        if not self.gap_said:
            self.gap_said = True
            return Proposal(proposal.delta, proposal.reason, level=proposal.level, notice=ZONE_GAP)
        return proposal

    def _easier(self, inp: RuleInput, c: Controls, why: str) -> Proposal:
        """The overshoot guard: the best setting predicted lower than the current one (acts now)."""
        current = self.current(c)
        now = self.predict(inp, c, current)
        if self.gap is not None and current == self.gap[0]:
            return self._gap_step(inp, c)
        # Easier by label, whatever the model predicts (it just missed), or predicted lower by a difference
        # worth a switch.
        lower = [s for s in self.candidates(c) if self.nominal(c, s) < self.nominal(c, current) - 1e-9
                 or self._apart(inp, c, current, s) < 0]
        scored = self._scored(inp, c, lower)
        if not scored:
            return self._out_of_reach(inp, c, now, inp.t - self.last_change)
        self.gap = None
        return self._move(inp, c, min(scored, key=lambda x: x[0])[2], why)

    def _in_zone_chance(self, inp: RuleInput, c: Controls, s: Setting, m: float) -> float:
        """Probability that ``s`` settles inside the zone, its prediction ``m`` +/- its spread (normal)."""
        sd = max(self.spread(c, s), 1e-6)

        def below(x: float) -> float:
            return 0.5 * (1.0 + math.erf((x - m) / (sd * math.sqrt(2.0))))

        return below(inp.zone.high) - below(inp.zone.low)

    def _apart(self, inp: RuleInput, c: Controls, current: Setting, s: Setting) -> int:
        """+1 / -1 when moving to ``s`` is worth its transient: predicted higher / lower than ``current``
        by 1 bpm at least, and either ``switch_gain`` likelier to settle in the zone, or ``z`` SDs of the
        difference away and no less likely; else 0 (a guess 1 bpm apart that changes little, or a sure
        move out of the zone, is no reason to switch)."""
        m, now = self.predict(inp, c, s), self.predict(inp, c, current)
        if m is None or now is None or abs(m - now) <= 1.0:
            return 0
        gain = self._in_zone_chance(inp, c, s, m) - self._in_zone_chance(inp, c, current, now)
        need = self.z * math.hypot(self.spread(c, s), self.spread(c, current))
        if gain < self.switch_gain and (abs(m - now) <= need or gain < -0.05):
            return 0
        return 1 if m > now else -1

    def _lower(self, inp: RuleInput, c: Controls, s: Setting, now: float | None) -> bool:
        """``s`` is predicted to settle more than 1 bpm below ``now`` (the current setting's prediction)."""
        m = self.predict(inp, c, s)
        return m is not None and now is not None and m < now - 1.0

    def _harder(self, inp: RuleInput, c: Controls, why: str) -> Proposal:
        """The stall guard: the best setting predicted higher than the current one."""
        current = self.current(c)
        now = self.predict(inp, c, current)
        # Harder by label unless the fit says confidently lower (a level's own fit counts once seen:
        # "labels until seen"), or worth it by prediction.
        higher = [s for s in self.candidates(c)
                  if (self.nominal(c, s) > self.nominal(c, current) + 1e-9
                      and not self._lower(inp, c, s, now)) or self._apart(inp, c, current, s) > 0]
        scored = self._scored(inp, c, higher)
        if not scored:
            return self._out_of_reach(inp, c, now, inp.t - self.last_change)
        return self._move(inp, c, min(scored, key=lambda x: x[0])[2], why)

    # --- a rule update ----------------------------------------------------------------------------
    def plan(self, inp: RuleInput) -> Proposal | None:
        c = inp.controls
        if c is None:
            return None
        self._see(c)
        if inp.phase == COOL_DOWN:
            self.gap = None
            return super().plan(inp)
        if inp.phase != WARM_UP and not self.prepared and self.fit_now(inp.t) is not None:
            self.prepared = True
            return self._choose(inp, c, "plan for the conditioning")
        return None

    def _decide(self, inp: RuleInput, c: Controls) -> Proposal:
        self._see(c)
        zone = inp.zone
        est = self.fit_now(inp.t)
        if est is None:
            return Proposal(0, "no heart-rate response to go on yet")
        # The guard looks at the top of the band: a response barely seen (a new activity) is uncertain.
        ahead, ahead_top = self.model.trajectory_band(est, inp.t, self.horizon, self.z)
        ahead_text = f"{ahead:.0f} bpm in {self.horizon:g} s" if ahead is not None else "no trajectory"
        above = inp.hr > zone.high or (ahead_top is not None and ahead_top > zone.high)
        if ahead_top is not None and ahead is not None and ahead_top > zone.high >= ahead:
            ahead_text += f" (band top {ahead_top:.0f})"
        measuring = inp.phase == WARM_UP and inp.t < inp.phase_end - self.lead - 1e-6
        if measuring:
            if above:
                return self._easier(inp, c, f"overshoot guard (warm-up): HR {inp.hr:.0f}, {ahead_text}")
            return Proposal(0, "warm-up: measuring the response, not climbing the ladder")
        if not self.prepared:
            self.prepared = True
            return self._choose(inp, c, "plan for the conditioning")
        if above:
            return self._easier(inp, c, f"overshoot guard: HR {inp.hr:.0f} (top {zone.high:.0f}), "
                                        f"{ahead_text}")
        if self.gap is not None:
            return self._gap_step(inp, c)
        since = inp.t - self.last_change
        current = self.current(c)
        pred = self.predict(inp, c, current)
        if inp.hr < zone.low and since >= self.stall and (ahead is None or ahead < zone.low + 2.0):
            return self._harder(inp, c, f"stall guard: HR {inp.hr:.0f} below {zone.low:.0f} for "
                                        f"{since:.0f} s, "
                                        f"{ahead_text}")
        width = zone.high - zone.low
        lo, hi = zone.low + self.margin * width, zone.high - self.margin * width
        if pred is not None and lo <= pred <= hi:
            return Proposal(0, f"predicted {pred:.0f} bpm, inside [{lo:.0f}, {hi:.0f}]; {ahead_text}")
        if since < self.hold:
            return Proposal(0, f"holding: {since:.0f} s since the last change < {self.hold:g} s; "
                               f"{ahead_text}")
        best = self.best(inp, c)
        # Never re-plan against the heart rate seen: below the zone nothing predicted easier.
        best_pred = self.predict(inp, c, best)
        if inp.hr < zone.low and best_pred is not None and pred is not None and best_pred < pred:
            best = current
        # Another activity only for a difference worth its transient (as the guards).
        if best.level != current.level and self._apart(inp, c, current, best) == 0:
            best = current
        if best != current or self._gap_pair(inp, c) is not None:
            return self._choose(inp, c, "re-plan")
        return self._out_of_reach(inp, c, pred, since)

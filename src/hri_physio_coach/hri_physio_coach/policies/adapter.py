"""The :class:`Adapter`: any policy plus the thesis's proposed fixes, applied to the speed ladder.

The fixes (refractory period, conditioning-only adaptation, scheduled cool-down, warm-up
speed-up cap) work with every policy; the adapter applies the policy's step to the ladder
within its limits and returns a :class:`~hri_physio_coach.policies.types.Decision` that says
what happened and why, so a recording explains every update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hri_physio_coach import gates
from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.policies.types import (
    AT_LIMIT,
    CHANGE_ACTIVITY,
    CONDITIONING,
    COOL_DOWN,
    ENCOURAGE,
    FOLLOW_ROUTINE,
    GATED,
    HOLD,
    OUT_OF_REACH,
    SCHEDULED_SLOW_DOWN,
    SLOW_DOWN,
    SPEED_UP,
    WARM_UP,
    Controls,
    Decision,
    Policy,
    Proposal,
    RuleInput,
)

_UNCHANGED = object()  # a decision that did not change the activity cost


@dataclass(frozen=True)
class AdapterOptions:
    """The thesis's proposed fixes, usable with any policy (all off by default = the thesis run).

    The coach builds them from its ``adapt_*`` options (:meth:`CoachConfig.adapter_options`), where
    their defaults are declared.
    """

    refractory_period: float | None = None  # None: no refractory period
    conditioning_only: bool = False
    cooldown_schedule: bool = False
    warmup_max_speedups: int | None = None  # None: no cap

    def __post_init__(self) -> None:
        period = self.refractory_period
        if period is not None and not (math.isfinite(period) and period >= 0):
            raise ValueError(f"refractory period must be >= 0 s, got {self.refractory_period}")
        if self.warmup_max_speedups is not None and self.warmup_max_speedups < 0:
            raise ValueError(f"warm-up speed-up cap must be >= 0 (or none), got {self.warmup_max_speedups}")


class Adapter:
    """A policy plus options, applied to a speed ladder; keeps the state the options need."""

    def __init__(self, policy: Policy, ladder: SpeedLadder, options: AdapterOptions | None = None) -> None:
        self.policy = policy
        self.ladder = ladder
        self.options = options or AdapterOptions()
        self.last_adaptation: float | None = None
        self.warmup_speedups = 0
        self._cooldown_from: int | None = None
        self.level: float | None = None  # activity cost the policy holds (None: the routine's activities)

    @property
    def chooses_activity(self) -> bool:
        """True when the policy may run other activities of the routine in place of the routine's own."""
        return self.policy.chooses_activity

    def observe(self, t: float, controls: Controls) -> None:
        """What is performed from ``t`` on (activity start or switch, ladder step), for learning policies."""
        self.policy.observe(t, controls)

    def _decision(self, inp: RuleInput | None, t: float, action: str, reason: str, before: int,
                  proposal: Proposal | None = None, gate: str | None = None,
                  level_before: float | object | None = _UNCHANGED) -> Decision:
        return Decision(
            t=t, policy=self.policy.name, action=action, delta=self.ladder.index - before,
            proposed=proposal.delta if proposal else 0, reason=reason,
            hr=inp.hr if inp else None, zone_state=inp.zone.classify(inp.hr) if inp else None,
            index_before=before, index_after=self.ladder.index,
            p=proposal.p if proposal else None, draw=proposal.draw if proposal else None, gate=gate,
            level_before=self.level if level_before is _UNCHANGED else level_before,  # type: ignore[arg-type]
            level_after=self.level,
            notice=proposal.notice if proposal else None,
        )

    def plan(self, inp: RuleInput) -> Decision | None:
        """At a phase start, what a policy that plans phases wants for it (None: nothing changes)."""
        proposal = self.policy.plan(inp)
        if proposal is None:
            return None
        before, level_before = self.ladder.index, self.level
        if proposal.level is not None:
            self.level = None if proposal.level == FOLLOW_ROUTINE else proposal.level
        self.ladder.step(proposal.delta)
        if self.ladder.index == before and self.level == level_before:
            return None
        self.last_adaptation = inp.t
        if inp.phase == COOL_DOWN and self.ladder.index <= before:
            action = SCHEDULED_SLOW_DOWN
        elif self.level != level_before:
            action = CHANGE_ACTIVITY
        else:
            action = SPEED_UP if self.ladder.index > before else SLOW_DOWN
        return self._decision(inp, inp.t, action, proposal.reason, before, proposal,
                              level_before=level_before)

    def gated(self, t: float, reason: str, hr: float | None = None, gate: str | None = None) -> Decision:
        """A rule update that could not run (no trustworthy heart rate); ``gate`` is its code."""
        i = self.ladder.index
        return Decision(t, self.policy.name, GATED, 0, 0, reason, hr, None, i, i, gate=gate)

    def update(self, inp: RuleInput) -> Decision:
        opts, before = self.options, self.ladder.index
        if opts.cooldown_schedule and inp.phase == COOL_DOWN:
            return self._scheduled(inp, before)
        if opts.conditioning_only and inp.phase != CONDITIONING:
            reason = f"adaptation restricted to conditioning (phase {inp.phase})"
            return self._decision(inp, inp.t, HOLD, reason, before, gate=gates.CONDITIONING_ONLY)
        if opts.refractory_period is not None and self.last_adaptation is not None:
            since = inp.t - self.last_adaptation
            if since < opts.refractory_period:
                return self._decision(
                    inp, inp.t, HOLD,
                    f"refractory: {since:.0f} s since the last update < {opts.refractory_period:g} s", before,
                    gate=gates.REFRACTORY,
                )
        proposal = self.policy.propose(inp)
        level_before = self.level
        level = None if proposal.level == FOLLOW_ROUTINE else proposal.level
        if proposal.level is not None and level != self.level:
            return self._change_activity(inp, proposal, before, level_before)
        if proposal.delta == 0:
            action = OUT_OF_REACH if proposal.notice else ENCOURAGE
            return self._decision(inp, inp.t, action, proposal.reason, before, proposal)
        cap = opts.warmup_max_speedups
        if proposal.delta > 0 and inp.phase == WARM_UP and cap is not None and self.warmup_speedups >= cap:
            return self._decision(inp, inp.t, HOLD, f"{proposal.reason}; warm-up speed-up cap {cap} reached",
                                  before, proposal, gate=gates.WARMUP_CAP)
        if not self.ladder.step(proposal.delta):
            end = "fastest" if proposal.delta > 0 else "slowest"
            return self._decision(inp, inp.t, AT_LIMIT, f"{proposal.reason}; already at the {end} step",
                                  before, proposal)
        self.last_adaptation = inp.t
        if proposal.delta > 0 and inp.phase == WARM_UP:
            self.warmup_speedups += 1
        action = SPEED_UP if proposal.delta > 0 else SLOW_DOWN
        return self._decision(inp, inp.t, action, proposal.reason, before, proposal)

    def _change_activity(self, inp: RuleInput, proposal: Proposal, before: int,
                         level_before: float | None) -> Decision:
        """Another activity cost, or the routine's own (and maybe another step, kept within the ladder)."""
        self.level = None if proposal.level == FOLLOW_ROUTINE else proposal.level
        target = min(max(before + proposal.delta, 0), len(self.ladder) - 1)
        self.ladder.step(target - before)
        self.last_adaptation = inp.t
        return self._decision(inp, inp.t, CHANGE_ACTIVITY, proposal.reason, before, proposal,
                              level_before=level_before)

    def _scheduled(self, inp: RuleInput, before: int) -> Decision:
        """Cool-down: the ladder falls linearly from its cool-down start to the bottom by the end."""
        if self._cooldown_from is None:
            self._cooldown_from = before
        duration = max(inp.phase_end - inp.phase_start, 1e-9)
        remaining = min(max(inp.phase_end - inp.t, 0.0), duration)
        target = math.floor(self._cooldown_from * remaining / duration + 1e-9)
        if target >= before:
            return self._decision(inp, inp.t, HOLD, f"cool-down schedule: step {before} is on schedule "
                                  f"(target {target})", before, gate=gates.COOLDOWN_SCHEDULE)
        self.ladder.step(target - before)
        return self._decision(inp, inp.t, SCHEDULED_SLOW_DOWN,
                              f"cool-down schedule: step {before} -> {target} "
                              f"({remaining:.0f} s of {duration:.0f} s left)", before)

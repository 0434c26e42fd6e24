"""Adaptation policies: what a rule update does with the mean heart rate of the last 30 s.

A *policy* is the core algorithm (thesis ch. 4) and only proposes a step on the speed
ladder: ``threshold`` (Algorithm 1), ``fuzzy`` (Algorithm 2, seeded) or ``static`` (never
adapts: the control condition). :class:`Adapter` wraps any policy with the thesis's
proposed fixes (refractory period, conditioning-only adaptation, scheduled cool-down,
warm-up speed-up cap), applies the step to the ladder within its limits, and returns a
:class:`Decision` that says what happened and why, so a recording explains every update.
"""

from __future__ import annotations

import math
import random
from dataclasses import asdict, dataclass
from typing import Protocol

from hri_physio_coach import gates
from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.zones import HeartRateZone, fuzzy_probability

# Decision actions.
SPEED_UP = "speed_up"
SLOW_DOWN = "slow_down"
ENCOURAGE = "encourage"  # the policy saw no reason to change pace
HOLD = "hold"  # an option suppressed adaptation (refractory, phase restriction, cap)
AT_LIMIT = "at_limit"  # the policy asked for a step beyond the end of the ladder
SCHEDULED_SLOW_DOWN = "scheduled_slow_down"  # cool-down schedule
GATED = "gated"  # no trustworthy heart rate: no update at all (decided by the coach)
CHANGE_ACTIVITY = "change_activity"  # a policy that picks activities chose another one (maybe another step)
#: A proposal's ``level`` that hands the choice of activity back to the routine (no cost is below 1 MET).
FOLLOW_ROUTINE = 0.0
OUT_OF_REACH = "out_of_reach"  # the zone cannot be reached with the controls at hand (said once)

_UNCHANGED = object()  # a decision that did not change the activity cost

# Phase kinds the options refer to.
WARM_UP = "warm_up"
CONDITIONING = "conditioning"
COOL_DOWN = "cool_down"


@dataclass(frozen=True)
class Controls:
    """What the participant is doing and what the coach may change (for policies that use it)."""

    activity: str | None  # the activity being performed (the routine's, or the one run in its place)
    mets: float | None  # its stated cost (None: the routine states none)
    chosen: float | None  # the activity cost the policy holds (None: the routine's activities)
    levels: tuple[float, ...]  # activity costs the coach can run (empty: no activity choice)
    speeds: tuple[float, ...]  # the ladder's gesture speeds ...
    tempos: tuple[float | None, ...]  # ... and music tempos
    index: int  # the ladder step
    window_start: float  # the rule update's HR mean covers (window_start, t]
    # Per phase kind, the (duration, cost) of the routine's own activities that state a cost.
    routine_costs: tuple[tuple[str, tuple[tuple[float, float], ...]], ...] = ()


@dataclass(frozen=True)
class RuleInput:
    """What a rule update knows: the time, the buffer's mean HR, the zone and the phase."""

    t: float
    hr: float
    zone: HeartRateZone
    phase: str
    phase_start: float
    phase_end: float
    controls: Controls | None = None


@dataclass(frozen=True)
class Proposal:
    """A policy's proposal: a ladder step (-1, 0, +1) and why.

    Policies that pick activities may also give the activity cost to run from now on
    (``level``, METs) and a one-off ``notice`` (e.g. the zone is out of reach).
    """

    delta: int
    reason: str
    p: float | None = None
    draw: float | None = None
    level: float | None = None
    notice: str | None = None


class Policy(Protocol):
    name: str

    def propose(self, inp: RuleInput) -> Proposal: ...


class ThresholdPolicy:
    """Algorithm 1: below the zone speed up, above it slow down, inside it encourage."""

    name = "threshold"

    def propose(self, inp: RuleInput) -> Proposal:
        zone = inp.zone
        if inp.hr < zone.low:
            return Proposal(+1, f"HR {inp.hr:.1f} < zone low {zone.low:.1f}")
        if inp.hr > zone.high:
            return Proposal(-1, f"HR {inp.hr:.1f} > zone high {zone.high:.1f}")
        return Proposal(0, f"HR {inp.hr:.1f} within [{zone.low:.1f}, {zone.high:.1f}]")


class FuzzyPolicy:
    """Algorithm 2: adapt towards the zone centre with probability p(HR) (seeded draws)."""

    name = "fuzzy"

    def __init__(self, seed: int | None = 0) -> None:
        self.rng = random.Random(seed)

    @staticmethod
    def probability(hr: float, zone: HeartRateZone) -> float:
        """p(HR) of thesis Fig. 4.13."""
        return fuzzy_probability(hr, zone)

    def propose(self, inp: RuleInput) -> Proposal:
        p = self.probability(inp.hr, inp.zone)
        draw = self.rng.random()
        target = inp.zone.target
        if draw < p:
            delta = 1 if inp.hr < target else -1
            return Proposal(delta, f"draw {draw:.3f} < p {p:.3f} (HR {inp.hr:.1f}, target {target:.1f})",
                            p, draw)
        return Proposal(0, f"draw {draw:.3f} >= p {p:.3f} (HR {inp.hr:.1f}, target {target:.1f})", p, draw)


class StaticPolicy:
    """Never adapts: the control condition of the thesis's proposed study."""

    name = "static"

    def propose(self, inp: RuleInput) -> Proposal:
        return Proposal(0, "static policy never adapts")


POLICY_NAMES = ("threshold", "fuzzy", "static", "predictive")


def make_policy(name: str, seed: int | None = 0) -> Policy:
    """A policy by name (``threshold``, ``fuzzy``, ``static``, ``predictive``)."""
    if name == "threshold":
        return ThresholdPolicy()
    if name == "fuzzy":
        return FuzzyPolicy(seed)
    if name == "static":
        return StaticPolicy()
    if name == "predictive":
        from hri_physio_coach.predictive import PredictivePolicy  # it builds on this module's types

        return PredictivePolicy()
    raise ValueError(f"unknown adaptation policy {name!r}; choose one of {', '.join(POLICY_NAMES)}")


@dataclass(frozen=True)
class AdapterOptions:
    """The thesis's proposed fixes, usable with any policy (all off by default = the thesis run)."""

    refractory: bool = False
    refractory_period: float = 60.0
    conditioning_only: bool = False
    cooldown_schedule: bool = False
    warmup_max_speedups: int | None = None  # None: no cap

    def __post_init__(self) -> None:
        if not (math.isfinite(self.refractory_period) and self.refractory_period >= 0):
            raise ValueError(f"refractory period must be >= 0 s, got {self.refractory_period}")
        if self.warmup_max_speedups is not None and self.warmup_max_speedups < 0:
            raise ValueError(f"warm-up speed-up cap must be >= 0 (or none), got {self.warmup_max_speedups}")


@dataclass(frozen=True)
class Decision:
    """The outcome of one rule update."""

    t: float
    policy: str
    action: str
    delta: int  # applied step
    proposed: int  # the policy's proposal (0 when it was not consulted)
    reason: str
    hr: float | None
    zone_state: str | None
    index_before: int
    index_after: int
    p: float | None = None
    draw: float | None = None
    gate: str | None = None  # gated or held: why, as a code of hri_physio_coach.gates
    level_before: float | None = None  # activity cost held by the policy (None: the routine's)
    level_after: float | None = None
    notice: str | None = None

    @property
    def changed(self) -> bool:
        return self.delta != 0 or self.level_before != self.level_after

    def as_dict(self) -> dict[str, object]:
        return {**asdict(self), "changed": self.changed}


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
        return bool(getattr(self.policy, "chooses_activity", False))

    def observe(self, t: float, controls: Controls) -> None:
        """What is performed from ``t`` on (activity start or switch, ladder step), for learning policies."""
        observe = getattr(self.policy, "observe", None)
        if observe is not None:
            observe(t, controls)

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
        plan = getattr(self.policy, "plan", None)
        proposal = plan(inp) if plan is not None else None
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
        if opts.refractory and self.last_adaptation is not None:
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

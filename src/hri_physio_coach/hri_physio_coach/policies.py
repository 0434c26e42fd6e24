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

# Phase kinds the options refer to.
WARM_UP = "warm_up"
CONDITIONING = "conditioning"
COOL_DOWN = "cool_down"


@dataclass(frozen=True)
class RuleInput:
    """What a rule update knows: the time, the buffer's mean HR, the zone and the phase."""

    t: float
    hr: float
    zone: HeartRateZone
    phase: str
    phase_start: float
    phase_end: float


@dataclass(frozen=True)
class Proposal:
    """A policy's proposal: a ladder step (-1, 0, +1) and why."""

    delta: int
    reason: str
    p: float | None = None
    draw: float | None = None


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


POLICY_NAMES = ("threshold", "fuzzy", "static")


def make_policy(name: str, seed: int | None = 0) -> Policy:
    """A policy by name (``threshold``, ``fuzzy``, ``static``)."""
    if name == "threshold":
        return ThresholdPolicy()
    if name == "fuzzy":
        return FuzzyPolicy(seed)
    if name == "static":
        return StaticPolicy()
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

    @property
    def changed(self) -> bool:
        return self.delta != 0

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

    def _decision(self, inp: RuleInput | None, t: float, action: str, reason: str, before: int,
                  proposal: Proposal | None = None) -> Decision:
        return Decision(
            t=t, policy=self.policy.name, action=action, delta=self.ladder.index - before,
            proposed=proposal.delta if proposal else 0, reason=reason,
            hr=inp.hr if inp else None, zone_state=inp.zone.classify(inp.hr) if inp else None,
            index_before=before, index_after=self.ladder.index,
            p=proposal.p if proposal else None, draw=proposal.draw if proposal else None,
        )

    def gated(self, t: float, reason: str, hr: float | None = None) -> Decision:
        """A rule update that could not run (no trustworthy heart rate)."""
        i = self.ladder.index
        return Decision(t, self.policy.name, GATED, 0, 0, reason, hr, None, i, i)

    def update(self, inp: RuleInput) -> Decision:
        opts, before = self.options, self.ladder.index
        if opts.cooldown_schedule and inp.phase == COOL_DOWN:
            return self._scheduled(inp, before)
        if opts.conditioning_only and inp.phase != CONDITIONING:
            reason = f"adaptation restricted to conditioning (phase {inp.phase})"
            return self._decision(inp, inp.t, HOLD, reason, before)
        if opts.refractory and self.last_adaptation is not None:
            since = inp.t - self.last_adaptation
            if since < opts.refractory_period:
                return self._decision(
                    inp, inp.t, HOLD,
                    f"refractory: {since:.0f} s since the last update < {opts.refractory_period:g} s", before,
                )
        proposal = self.policy.propose(inp)
        if proposal.delta == 0:
            return self._decision(inp, inp.t, ENCOURAGE, proposal.reason, before, proposal)
        cap = opts.warmup_max_speedups
        if proposal.delta > 0 and inp.phase == WARM_UP and cap is not None and self.warmup_speedups >= cap:
            return self._decision(inp, inp.t, HOLD, f"{proposal.reason}; warm-up speed-up cap {cap} reached",
                                  before, proposal)
        if not self.ladder.step(proposal.delta):
            end = "fastest" if proposal.delta > 0 else "slowest"
            return self._decision(inp, inp.t, AT_LIMIT, f"{proposal.reason}; already at the {end} step",
                                  before, proposal)
        self.last_adaptation = inp.t
        if proposal.delta > 0 and inp.phase == WARM_UP:
            self.warmup_speedups += 1
        action = SPEED_UP if proposal.delta > 0 else SLOW_DOWN
        return self._decision(inp, inp.t, action, proposal.reason, before, proposal)

    def _scheduled(self, inp: RuleInput, before: int) -> Decision:
        """Cool-down: the ladder falls linearly from its cool-down start to the bottom by the end."""
        if self._cooldown_from is None:
            self._cooldown_from = before
        duration = max(inp.phase_end - inp.phase_start, 1e-9)
        remaining = min(max(inp.phase_end - inp.t, 0.0), duration)
        target = math.floor(self._cooldown_from * remaining / duration + 1e-9)
        if target >= before:
            return self._decision(inp, inp.t, HOLD, f"cool-down schedule: step {before} is on schedule "
                                  f"(target {target})", before)
        self.ladder.step(target - before)
        return self._decision(inp, inp.t, SCHEDULED_SLOW_DOWN,
                              f"cool-down schedule: step {before} -> {target} "
                              f"({remaining:.0f} s of {duration:.0f} s left)", before)

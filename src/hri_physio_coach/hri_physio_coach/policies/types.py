"""What policies and the adapter exchange: rule inputs, controls, proposals, decisions, the protocol.

A *policy* is the core algorithm of a rule update (thesis ch. 4): from a :class:`RuleInput` it
proposes one step on the speed ladder (and, for policies that pick activities, an activity
cost) as a :class:`Proposal`. The :class:`~hri_physio_coach.policies.adapter.Adapter` applies it
and returns a :class:`Decision`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Protocol

from hri_physio_coach.zones import HeartRateZone

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
#: A decision's notice: no single setting lands in the zone, two alternate (the coach emits ``zone_gap``).
ZONE_GAP = "zone_gap"

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
    # (name, cost) of the activities that may run at each of ``levels`` in this phase (the coach's choice).
    runs_at: tuple[tuple[str, float], ...] = ()


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
        # Every field is a number, a string or None: no deep copy (dataclasses.asdict) needed.
        return {**{f.name: getattr(self, f.name) for f in fields(self)}, "changed": self.changed}



class Policy(Protocol):
    """What the adapter calls. :class:`BasePolicy` gives the optional parts their do-nothing defaults."""

    name: str
    #: True when the policy may run other activities of the routine in place of the routine's own.
    chooses_activity: bool

    def propose(self, inp: RuleInput) -> Proposal:
        """A rule update: the step (and activity cost) the policy wants."""
        ...

    def observe(self, t: float, controls: Controls) -> None:
        """What is performed from ``t`` on (activity start or switch, ladder step)."""
        ...

    def plan(self, inp: RuleInput) -> Proposal | None:
        """At a phase start, what the policy wants for the phase (None: nothing changes)."""
        ...

    def warm_up(self) -> None:
        """Load now what the first decision needs (libraries a policy imports on first use): a coach
        calls this before its session starts, so that no rule update stalls on an import."""
        ...


class BasePolicy:
    """A policy that neither learns from what is performed nor plans phases: it only proposes."""

    name = "base"
    chooses_activity = False

    def propose(self, inp: RuleInput) -> Proposal:
        raise NotImplementedError

    def observe(self, t: float, controls: Controls) -> None:
        return None

    def plan(self, inp: RuleInput) -> Proposal | None:
        return None

    def warm_up(self) -> None:
        return None

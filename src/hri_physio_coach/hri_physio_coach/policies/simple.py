"""The thesis's policies: ``threshold`` (Algorithm 1), ``fuzzy`` (Algorithm 2, seeded) and ``static``
(never adapts: the control condition)."""

from __future__ import annotations

import random

from hri_physio_coach.policies.types import BasePolicy, Proposal, RuleInput
from hri_physio_coach.zones import HeartRateZone, fuzzy_probability


class ThresholdPolicy(BasePolicy):
    """Algorithm 1: below the zone speed up, above it slow down, inside it encourage."""

    name = "threshold"

    def propose(self, inp: RuleInput) -> Proposal:
        zone = inp.zone
        if inp.hr < zone.low:
            return Proposal(+1, f"HR {inp.hr:.1f} < zone low {zone.low:.1f}")
        if inp.hr > zone.high:
            return Proposal(-1, f"HR {inp.hr:.1f} > zone high {zone.high:.1f}")
        return Proposal(0, f"HR {inp.hr:.1f} within [{zone.low:.1f}, {zone.high:.1f}]")


class FuzzyPolicy(BasePolicy):
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


class StaticPolicy(BasePolicy):
    """Never adapts: the control condition of the thesis's proposed study."""

    name = "static"

    def propose(self, inp: RuleInput) -> Proposal:
        return Proposal(0, "static policy never adapts")

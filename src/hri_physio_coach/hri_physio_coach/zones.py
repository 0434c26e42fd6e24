"""Heart-rate zone maths of the exercise coach (thesis ch. 4).

* HR_max = 208 − 0.7·age (Tanaka, Monahan & Seals 2001).
* HRR = HR_max − HR_rest (heart-rate reserve, Karvonen).
* Zone = [HR_rest + low·HRR, HR_rest + high·HRR], by default 40 % and 70 % of HRR.
* Algorithm 2 (fuzzy): HR_target = mid-zone and the probability of adapting
  p(HR) = |HR − HR_target| / (HR_target − HRR40), clipped to [0, 1] (Fig. 4.13).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

TANAKA_INTERCEPT = 208.0
TANAKA_SLOPE = 0.7
DEFAULT_LOW_FRACTION = 0.40
DEFAULT_HIGH_FRACTION = 0.70


def tanaka_hr_max(age: float) -> float:
    """Age-predicted maximal heart rate in bpm (Tanaka et al. 2001)."""
    if not 0 < age <= 120:
        raise ValueError(f"age must be in (0, 120] years, got {age}")
    return TANAKA_INTERCEPT - TANAKA_SLOPE * age


@dataclass(frozen=True)
class HeartRateZone:
    """The target zone of one participant, from resting and maximal heart rate."""

    hr_rest: float
    hr_max: float
    low_fraction: float = DEFAULT_LOW_FRACTION
    high_fraction: float = DEFAULT_HIGH_FRACTION

    def __post_init__(self) -> None:
        if not (math.isfinite(self.hr_rest) and math.isfinite(self.hr_max)):
            raise ValueError(f"heart rates must be finite, got rest {self.hr_rest}, max {self.hr_max}")
        if self.hr_rest >= self.hr_max:
            raise ValueError(
                f"resting heart rate {self.hr_rest:.1f} bpm must be below the maximum {self.hr_max:.1f} bpm"
            )
        if not 0.0 <= self.low_fraction < self.high_fraction <= 1.0:
            raise ValueError(
                "zone bounds must satisfy 0 <= low < high <= 1 (fractions of HRR), "
                f"got low {self.low_fraction}, high {self.high_fraction}"
            )

    @classmethod
    def from_age(cls, age: float, hr_rest: float, low_fraction: float = DEFAULT_LOW_FRACTION,
                 high_fraction: float = DEFAULT_HIGH_FRACTION) -> HeartRateZone:
        return cls(hr_rest, tanaka_hr_max(age), low_fraction, high_fraction)

    @property
    def hrr(self) -> float:
        """Heart-rate reserve, bpm."""
        return self.hr_max - self.hr_rest

    def at_fraction(self, fraction: float) -> float:
        """Heart rate at a fraction of the reserve (Karvonen)."""
        return self.hr_rest + fraction * self.hrr

    @property
    def low(self) -> float:
        """Lower bound (HRR40 by default)."""
        return self.at_fraction(self.low_fraction)

    @property
    def high(self) -> float:
        """Upper bound (HRR70 by default)."""
        return self.at_fraction(self.high_fraction)

    @property
    def target(self) -> float:
        """Centre of the zone: Algorithm 2's HR_target."""
        return 0.5 * (self.low + self.high)

    def fraction_of_reserve(self, hr: float) -> float:
        return (hr - self.hr_rest) / self.hrr

    def classify(self, hr: float) -> str:
        """``below``, ``in`` or ``above`` the zone (bounds belong to the zone)."""
        if hr < self.low:
            return "below"
        if hr > self.high:
            return "above"
        return "in"

    def adaptation_probability(self, hr: float) -> float:
        """Algorithm 2's p(HR): 0 at the zone centre, rising linearly to 1 at the bounds and beyond."""
        return fuzzy_probability(hr, self)

    def as_dict(self) -> dict[str, float]:
        return {
            "hr_rest": self.hr_rest, "hr_max": self.hr_max, "hrr": self.hrr,
            "low_fraction": self.low_fraction, "high_fraction": self.high_fraction,
            "low": self.low, "high": self.high, "target": self.target,
        }


def fuzzy_probability(hr: float, zone: HeartRateZone) -> float:
    """p(HR) = |HR − HR_target| / (HR_target − low), clipped to [0, 1] (thesis Fig. 4.13).

    The zone is symmetric about its centre, so the same half-width serves both sides.
    A non-finite heart rate has no defined distance: it raises.
    """
    if not math.isfinite(hr):
        raise ValueError(f"heart rate must be finite, got {hr}")
    half_width = zone.target - zone.low
    return min(1.0, max(0.0, abs(hr - zone.target) / half_width))

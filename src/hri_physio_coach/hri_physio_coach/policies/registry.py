"""Policies by name: what ``--policy`` accepts."""

from __future__ import annotations

from hri_physio_coach.policies.adaptive import AdaptivePolicy
from hri_physio_coach.policies.predictive import PredictivePolicy
from hri_physio_coach.policies.simple import FuzzyPolicy, StaticPolicy, ThresholdPolicy
from hri_physio_coach.policies.types import Policy

POLICY_NAMES = ("threshold", "fuzzy", "static", "predictive", "adaptive")


def make_policy(name: str, seed: int | None = 0) -> Policy:
    """A policy by name (``threshold``, ``fuzzy``, ``static``, ``predictive``, ``adaptive``); ``seed`` for
    fuzzy's draws."""
    if name == "threshold":
        return ThresholdPolicy()
    if name == "fuzzy":
        return FuzzyPolicy(seed)
    if name == "static":
        return StaticPolicy()
    if name == "predictive":
        return PredictivePolicy()
    if name == "adaptive":
        return AdaptivePolicy()
    raise ValueError(f"unknown adaptation policy {name!r}; choose one of {', '.join(POLICY_NAMES)}")

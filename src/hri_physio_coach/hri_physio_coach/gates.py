"""Why a rule update did not adapt, as machine-readable codes defined once.

Every ``rule_update`` event whose decision was gated (no trustworthy heart rate: the policy was
not consulted) or held by an adapter option carries one of these codes in ``decision.gate``
next to the prose ``reason``; tools group and count by the code, never by parsing the prose.
"""

from __future__ import annotations

from dataclasses import dataclass

# --- the heart rate cannot be trusted: no update at all (action "gated") -------------------------
NO_ZONE = "no_zone"
NO_HR_DATA = "no_hr_data"
TOO_FEW_SAMPLES = "too_few_samples"
SIGNAL_FLAGGED = "signal_flagged"
# --- an adapter option held the pace (action "hold") ---------------------------------------------
REFRACTORY = "refractory"
CONDITIONING_ONLY = "conditioning_only"
WARMUP_CAP = "warmup_cap"
COOLDOWN_SCHEDULE = "cooldown_schedule"

#: What each code means, for summaries.
LABELS: dict[str, str] = {
    NO_ZONE: "no heart-rate zone yet",
    NO_HR_DATA: "no heart-rate data (adaptation paused)",
    TOO_FEW_SAMPLES: "too few valid HR samples",
    SIGNAL_FLAGGED: "signal flagged (too many invalid or flagged samples)",
    REFRACTORY: "refractory period after the last adaptation",
    CONDITIONING_ONLY: "adaptation restricted to conditioning",
    WARMUP_CAP: "warm-up speed-up cap reached",
    COOLDOWN_SCHEDULE: "cool-down schedule: pace already on schedule",
}


def label(code: str) -> str:
    """The summary text of a gate code (the code itself when it is not one of ours)."""
    return LABELS.get(code, code)


@dataclass(frozen=True)
class Gate:
    """A gate that closed: its code and the reason in words, with the numbers that tripped it."""

    code: str
    reason: str

"""Per-session metrics, from what the coach recorded and the participant's heart rate.

Heart rate is the participant's true heart rate (the model's, at the strap's 1 Hz report times):
what the coach controls. The strap's value (what the coach receives: jitter, artefacts, dropouts)
smoothed over the last 5 s is kept beside it as ``in_zone_strap``, what a study that has only the
strap would measure. The zone is the one the coach announced (its calibrated HR_rest and
age-predicted HR_max).
Every sample stands for one second. Phases come from the coach's ``phase`` events;
adaptations are the coach's decisions that changed the ladder step or the activity cost it
holds (rule updates and phase plans), counted in the phase they were made in.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from hri_physio_coach.evaluate.reach import Reach
from hri_physio_coach.evaluate.simulation import SessionRun

EXERCISE = ("warm_up", "conditioning", "cool_down")
SMOOTHING_S = 5


def smoothed(hr: np.ndarray, n: int = SMOOTHING_S) -> np.ndarray:
    """Trailing mean over the last ``n`` samples (fewer at the start)."""
    if len(hr) == 0:
        return hr
    c = np.concatenate([[0.0], np.cumsum(hr)])
    idx = np.arange(1, len(hr) + 1)
    lo = np.maximum(idx - n, 0)
    return (c[idx] - c[lo]) / (idx - lo)


def phase_spans(run: SessionRun) -> dict[str, tuple[float, float]]:
    """Phase kind -> (start, end) in session time."""
    return {str(e["kind"]): (float(e["t"]), float(e["ends_at"])) for e in run.of("phase")}


def adaptations(run: SessionRun) -> list[tuple[str, float, int]]:
    """(phase kind, time, direction +1/-1) of every decision that changed a control."""
    kinds = {str(e["phase"]): str(e["kind"]) for e in run.of("phase")}
    out = []
    for e in run.events:
        if e.get("event") == "rule_update":
            kind = e["inputs"].get("phase_kind")
        elif e.get("event") == "plan":
            kind = kinds.get(str(e.get("phase")))
        else:
            continue
        d = e["decision"]
        if not d.get("changed"):
            continue
        before, after = d.get("level_before"), d.get("level_after")
        if after is not None and before is not None and after != before:
            direction = 1 if after > before else -1
        else:
            direction = 1 if d["delta"] > 0 else -1
        out.append((str(kind), float(e["t"]), direction))
    return out


def session_metrics(run: SessionRun, reach: Reach | None = None) -> dict[str, Any]:
    """One row of sessions.csv."""
    zone = run.of("zone")[-1]
    low, high, rest, hrr = float(zone["low"]), float(zone["high"]), float(zone["hr_rest"]), float(zone["hrr"])
    centre = 0.5 * (low + high)
    spans = phase_spans(run)
    hr = run.model_hr
    inside = (hr >= low) & (hr <= high)
    strap = smoothed(run.hr)
    strap_inside = (strap >= low) & (strap <= high)
    p = run.spec.params
    row: dict[str, Any] = {
        "model": p.model, "variant": run.spec.variant, "policy": run.spec.policy,
        "participant": run.spec.participant,
        "age": round(p.age, 2), "female": p.female, "hr_rest_true": round(p.hr_rest, 2),
        "hr_max_true": round(p.hr_max_true, 2), "vo2max": round(p.vo2max, 2),
        "zone_low": round(low, 2), "zone_high": round(high, 2),
    }
    ex_start = spans["warm_up"][0] if "warm_up" in spans else math.inf
    ex_end = spans["cool_down"][1] if "cool_down" in spans else -math.inf
    for kind in EXERCISE:
        start, end = spans.get(kind, (math.nan, math.nan))
        mask = (run.t >= start) & (run.t < end)
        row[f"in_zone_{kind}"] = float(inside[mask].mean()) if mask.any() else math.nan
    row["in_zone"] = row["in_zone_conditioning"]
    c0, c1 = spans.get("conditioning", (math.nan, math.nan))
    cond = (run.t >= c0) & (run.t < c1)
    row["in_zone_strap"] = float(strap_inside[cond].mean()) if cond.any() else math.nan
    exercise = (run.t >= ex_start) & (run.t < ex_end)
    first = np.flatnonzero(exercise & inside)
    row["time_to_zone_s"] = float(run.t[first[0]] - ex_start) if len(first) else math.nan
    row["above_hrr70_s"] = int(np.sum(exercise & (hr > high)))
    row["above_85_hrmax_s"] = int(np.sum(exercise & (hr > 0.85 * p.hr_max_true)))
    row["rms_to_centre_bpm"] = float(np.sqrt(np.mean((hr[cond] - centre) ** 2))) if cond.any() else math.nan
    changes = adaptations(run)
    for kind in EXERCISE:
        row[f"adaptations_{kind}"] = sum(1 for k, _, _ in changes if k == kind)
    minutes = (c1 - c0) / 600.0 if cond.any() else math.nan
    row["adaptations_per_10min"] = row["adaptations_conditioning"] / minutes if minutes else math.nan
    directions = [d for _, _, d in changes]
    row["reversals"] = sum(1 for a, b in itertools.pairwise(directions) if a != b)
    d1 = spans.get("cool_down", (math.nan, math.nan))[1]
    tail = (run.t >= d1 - SMOOTHING_S) & (run.t < d1)
    end_hr = float(hr[tail].mean()) if tail.any() else math.nan
    row["cooldown_end_hr"] = end_hr
    row["cooldown_end_frac_hrr"] = (end_hr - rest) / hrr
    row["activity_substitutions"] = len(run.of("activity_choice"))
    notices = run.of("zone_out_of_reach")
    row["out_of_reach_said"] = notices[0]["direction"] if notices else ""
    if reach is not None:
        row["reach"] = reach.verdict
        row["reachable"] = reach.reachable
        row["settled_hr_lowest"] = round(reach.lowest, 2)
        row["settled_hr_highest"] = round(reach.highest, 2)
    return row

"""Do two recordings of a session take the same decisions? (closed loop vs discrete-event)

The closed loop (ROS 2, LSL, sim time) and the discrete-event evaluation run the same coach on
the same participant model, but heart-rate samples reach the coach at slightly different
moments, so a 30-s mean can differ by a fraction of a bpm and a decision near a threshold may
fall one rule update earlier or later. Two recordings agree when they make the same control
changes (ladder step and activity cost after each change), in the same order, each within
``tolerance_s`` of the other. Times are taken from each session's own ``session_start``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Change:
    """One decision that changed a control: when (from session start), what, and the result."""

    t: float
    action: str
    index: int
    level: float | None


def changes(events: Iterable[Mapping[str, Any]]) -> list[Change]:
    """The control changes of one session's coach events (rule updates and phase plans)."""
    events = list(events)
    start = next((float(e["t"]) for e in events if e.get("event") == "session_start"), 0.0)
    out = []
    for e in events:
        if e.get("event") not in ("rule_update", "plan"):
            continue
        d = e["decision"]
        if d.get("changed"):
            out.append(Change(round(float(e["t"]) - start, 3), str(d["action"]), int(d["index_after"]),
                              d.get("level_after")))
    return out


def compare_changes(a: list[Change], b: list[Change], tolerance_s: float = 30.0) -> list[str]:
    """What differs between two sessions' changes (empty: they agree within ``tolerance_s``)."""
    problems = []
    if len(a) != len(b):
        problems.append(f"{len(a)} control changes vs {len(b)}")
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if (x.action, x.index, x.level) != (y.action, y.index, y.level):
            problems.append(f"change {i}: {x.action} to step {x.index}, level {x.level} at {x.t:.0f} s vs "
                            f"{y.action} to step {y.index}, level {y.level} at {y.t:.0f} s")
        elif abs(x.t - y.t) > tolerance_s:
            problems.append(f"change {i} ({x.action}): at {x.t:.0f} s vs {y.t:.0f} s "
                            f"(> {tolerance_s:g} s apart)")
    return problems

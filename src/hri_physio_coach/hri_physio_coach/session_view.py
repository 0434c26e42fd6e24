"""What the session launcher knows and prints, and the sim clock it drives (no rclpy).

:class:`SessionView` is filled from the session's topics (coach state and events, heart rate,
participant model, mock robot events) and turns them into progress lines and a summary;
:class:`SimClock` says which ``/clock`` values are due, on an injected wall clock.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

#: Sim seconds per /clock message: no larger than any sim-time node's timer period
#: (coach tick, participant update and the mock's joint states), or timers skip periods.
CLOCK_STEP = 0.1
EXERCISE_PHASES = ("warm_up", "conditioning", "cool_down")


@dataclass
class SessionView:
    """What the launcher has seen of the session, from the ROS 2 topics."""

    state: dict = field(default_factory=dict)
    hr: float = math.nan
    hr_seen: int = 0  # on the coach's HR topic, since launch
    hr_samples: int = 0  # on the coach's HR topic, between session start and end
    strap_samples: int = 0  # on the strap's HR topic: proves the LSL -> ROS 2 path at start-up
    model_hr: float = math.nan
    zone: tuple[float, float] | None = None
    events: Counter[str] = field(default_factory=Counter)
    adaptations: int = 0
    gated: Counter[str] = field(default_factory=Counter)  # rule updates that could not run, by reason
    exercise_hr: int = 0
    exercise_in_zone: int = 0
    robot_actions: int = 0
    started_at: float | None = None  # sim time of the coach's session_start / session_end
    ended_at: float | None = None

    def on_event(self, event: dict) -> None:
        kind = str(event.get("event"))
        self.events[kind] += 1
        if kind == "session_start":
            self.started_at = float(event["t"])
        elif kind == "session_end":
            self.ended_at = float(event["t"])
        elif kind == "zone":
            self.zone = (float(event["low"]), float(event["high"]))
        elif kind == "rule_update":
            decision = event.get("decision", {})
            self.adaptations += int(bool(decision.get("changed")))
            if decision.get("action") == "gated":
                reason = re.sub(r"\d+(\.\d+)?", "N", str(decision.get("reason")))  # one line per kind
                self.gated[reason] += 1

    def on_hr(self, bpm: float) -> None:
        self.hr = bpm
        self.hr_seen += 1
        if self.started_at is not None and self.ended_at is None:
            self.hr_samples += 1
        if self.zone is not None and self.state.get("phase_kind") in EXERCISE_PHASES:
            self.exercise_hr += 1
            self.exercise_in_zone += int(self.zone[0] <= bpm <= self.zone[1])

    def progress(self, now: float) -> str:
        t0 = self.started_at
        elapsed = "--:--" if t0 is None else f"{int(now - t0) // 60:02d}:{int(now - t0) % 60:02d}"
        where = "ended" if self.ended_at is not None else (
            f"{self.state.get('phase') or 'waiting'}/{self.state.get('activity') or '-'}")
        zone = f"{self.zone[0]:.0f}-{self.zone[1]:.0f}" if self.zone else "not yet"
        speed = self.state.get("ladder_speed")
        pace = f"speed {speed:.2f} tempo {self.state.get('ladder_tempo')}" if speed is not None else "pace -"
        return (f"[session] {elapsed} {where:32s} HR {self.hr:5.1f} bpm (model {self.model_hr:5.1f})  "
                f"zone {zone}  {pace}  adaptations {self.adaptations}  robot actions {self.robot_actions}")


class SimClock:
    """Sim time advancing at ``speed`` x wall time, in steps of CLOCK_STEP sim seconds."""

    def __init__(self, start: float, speed: float, monotonic: Callable[[], float] = time.monotonic) -> None:
        self.t = start
        self.speed = speed
        self._base = start
        self._monotonic = monotonic
        self._wall = monotonic()

    def due_steps(self) -> list[float]:
        """The clock values to publish now, to keep up with the wall clock."""
        target = self._base + (self._monotonic() - self._wall) * self.speed
        steps = []
        while self.t + CLOCK_STEP <= target:
            self.t += CLOCK_STEP
            steps.append(self.t)
        return steps


def summary(view: SessionView, wall: float, bag: str | None, now: float | None = None) -> str:
    """The closing lines; ``now`` (sim time) measures a session stopped before its end."""
    t0, t1 = view.started_at, view.ended_at
    end = t1 if t1 is not None else now
    sim = (end - t0) if t0 is not None and end is not None else 0.0
    if t0 is None:
        head = f"[session] stopped before the session started, after {wall:.0f} s wall"
    else:
        how = "done" if t1 is not None else "stopped before its end"
        factor = sim / wall if wall else 0.0
        head = f"[session] {how}: {sim / 60:.1f} min of session in {wall:.0f} s wall ({factor:.0f}x)"
    in_zone = (f"{100.0 * view.exercise_in_zone / view.exercise_hr:.0f} % of {view.exercise_hr} exercise HR "
               f"samples in the zone" if view.exercise_hr else "no exercise HR samples")
    zone = f"{view.zone[0]:.1f}-{view.zone[1]:.1f} bpm" if view.zone else "never set"
    updates, behaviours = view.events.get("rule_update", 0), view.events.get("behaviour", 0)
    return "\n".join([
        head,
        f"[session] zone {zone}; {in_zone}; {view.adaptations} adaptations in {updates} rule updates; "
        f"{behaviours} behaviours; {view.robot_actions} robot actions",
        *(f"[session] {n} rule update(s) gated: {reason}" for reason, n in sorted(view.gated.items())),
        f"[session] heart-rate samples on the coach's input during the session: {view.hr_samples}"
        + (f"; recorded to {bag}" if bag else ""),
    ])

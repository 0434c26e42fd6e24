"""What the session launcher knows and prints (no rclpy).

:class:`SessionView` is filled from the session's topics (coach state and events, heart rate,
participant model, mock robot events) and turns them into progress lines and a summary; the sim
clock the launcher drives is :mod:`hri_physio_bringup.clock`.

Events arrive as text: :meth:`SessionView.on_event_text` takes every message of
``/coach/events``; one that is not a JSON object with an ``event`` (or whose fields do not fit
its kind) is counted by what is wrong with it and logged, rate-limited, never dropped silently.
Rule updates that did not adapt are counted by their ``decision.gate`` code.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_coach.gates import label

EXERCISE_PHASES = ("warm_up", "conditioning", "cool_down")
#: What can be wrong with a message on /coach/events (keys of :attr:`SessionView.malformed`).
NOT_JSON, NOT_OBJECT, NO_EVENT, BAD_FIELDS = "not_json", "not_object", "no_event", "bad_fields"
_MALFORMED_TEXT = {NOT_JSON: "is not JSON", NOT_OBJECT: "is not a JSON object",
                   NO_EVENT: "has no \"event\" name", BAD_FIELDS: "has fields that do not fit its kind"}


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@dataclass
class SessionView:
    """What the launcher has seen of the session, from the ROS 2 topics."""

    state: dict = field(default_factory=dict)
    hr: float = math.nan
    hr_seen: int = 0  # on the coach's HR topic, since launch
    #: Source times of every HR value on the coach's HR topic (the strap's clock: LSL time), counted
    #: against the session's start and end (sim time) only when asked, because under load a value can
    #: arrive after the event that bounds it.
    hr_times: list[float] = field(default_factory=list, repr=False)
    #: Source clock minus sim time, from the fastest-delivered value: a value never arrives before it
    #: was sampled, so ``source_t - arrival`` is at most the offset and the largest is the best estimate.
    hr_clock_offset: float = -math.inf
    strap_samples: int = 0  # on the strap's HR topic: proves the LSL -> ROS 2 path at start-up
    model_hr: float = math.nan
    zone: tuple[float, float] | None = None
    events: Counter[str] = field(default_factory=Counter)
    adaptations: int = 0
    gated: Counter[str] = field(default_factory=Counter)  # rule updates that could not run, by gate code
    held: Counter[str] = field(default_factory=Counter)  # rule updates an adapter option held, by gate code
    malformed: Counter[str] = field(default_factory=Counter)  # event messages that could not be used, by kind
    exercise_hr: int = 0
    exercise_in_zone: int = 0
    robot_actions: int = 0
    started_at: float | None = None  # sim time of the coach's session_start / session_end
    ended_at: float | None = None
    duration: float | None = None  # of the routine, from session_start
    stopped: str | None = None  # why the coach stopped before the routine's end (session_stopped)
    conflict: str | None = None  # the coach found another session on its topics (its reason)
    #: The last status of each receiver (``/<node>/status``): samples received, published, gaps.
    receivers: dict[str, dict] = field(default_factory=dict)
    #: The last status of polar_streamer (a real or replayed strap): samples, gaps, stalls, reconnects.
    strap_status: dict = field(default_factory=dict)
    #: Where malformed-event lines go (rate-limited), and the clock of the rate limit.
    warn: Callable[[str], None] = field(default=_stderr, repr=False, compare=False)
    monotonic: Callable[[], float] = field(default=time.monotonic, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._log = RateLimitedLog(self.warn, monotonic=self.monotonic)

    def on_event_text(self, text: str) -> bool:
        """One message of /coach/events; False (counted, logged) when it could not be used."""
        try:
            event: Any = json.loads(text)
        except (ValueError, TypeError):  # JSONDecodeError, or bytes that are not text
            return self._malformed(NOT_JSON, text)
        if not isinstance(event, dict):
            return self._malformed(NOT_OBJECT, text)
        if not isinstance(event.get("event"), str) or not event["event"]:
            return self._malformed(NO_EVENT, text)
        try:
            self.on_event(event)
        except (KeyError, TypeError, ValueError, AttributeError):
            return self._malformed(BAD_FIELDS, text)
        return True

    def _malformed(self, kind: str, text: Any) -> bool:
        self.malformed[kind] += 1
        sample = str(text)[:80]
        self._log.report(kind, f"[session] ignoring a message on the coach's events that "
                         f"{_MALFORMED_TEXT[kind]}: {sample!r}", "such message(s)")
        return False

    def on_event(self, event: dict) -> None:
        """One decoded event; raises KeyError/TypeError/ValueError when its fields do not fit its kind."""
        kind = str(event.get("event"))
        if kind == "session_start":
            self.started_at = float(event["t"])
            self.duration = float(event["duration"]) if event.get("duration") is not None else None
        elif kind == "session_end":
            self.ended_at = float(event["t"])
        elif kind == "zone":
            self.zone = (float(event["low"]), float(event["high"]))
        elif kind == "session_stopped":
            self.stopped = str(event.get("reason") or "stopped")
        elif kind == "conflict":
            self.conflict = str(event.get("reason") or event.get("conflict") or "conflict")
        elif kind == "rule_update":
            decision = event["decision"]
            changed, action = bool(decision.get("changed")), decision.get("action")
            self.adaptations += int(changed)
            if action == "gated":
                self.gated[str(decision.get("gate") or "unspecified")] += 1
            elif action == "hold":
                self.held[str(decision.get("gate") or "unspecified")] += 1
        self.events[kind] += 1

    @property
    def hr_samples(self) -> int:
        """HR values on the coach's input sampled in the session (start <= t < end, in sim time)."""
        if self.started_at is None or not math.isfinite(self.hr_clock_offset):
            return 0
        start = self.started_at + self.hr_clock_offset
        end = math.inf if self.ended_at is None else self.ended_at + self.hr_clock_offset
        return sum(start <= t < end for t in self.hr_times)

    def on_hr(self, bpm: float, source_t: float, arrival: float) -> None:
        """One HR value: its source timestamp and the sim time it arrived at (NaN: not known yet)."""
        self.hr = bpm
        self.hr_seen += 1
        self.hr_times.append(source_t)
        if math.isfinite(arrival):
            self.hr_clock_offset = max(self.hr_clock_offset, source_t - arrival)
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


def counted(n: int, noun: str) -> str:
    """``1 adaptation``, ``2 adaptations``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def summary(view: SessionView, wall: float, bag: str | None, now: float | None = None,
            restarts: dict[str, int] | None = None) -> str:
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
        f"[session] zone {zone}; {in_zone}; {counted(view.adaptations, 'adaptation')} in "
        f"{counted(updates, 'rule update')}; {counted(behaviours, 'behaviour')}; "
        f"{counted(view.robot_actions, 'robot action')}",
        *(f"[session] {n} rule update(s) gated: {label(code)} ({code})"
          for code, n in sorted(view.gated.items())),
        *(f"[session] {n} rule update(s) held: {label(code)} ({code})"
          for code, n in sorted(view.held.items())),
        *([f"[session] {sum(view.malformed.values())} malformed event message(s) ignored: "
           + ", ".join(f"{n} {kind}" for kind, n in sorted(view.malformed.items()))]
          if view.malformed else []),
        *([f"[session] the coach stopped: another session shared its topics ({view.conflict})"]
          if view.conflict else []),
        f"[session] heart-rate samples on the coach's input during the session: {view.hr_samples}"
        + (f"; recorded to {bag}" if bag else ""),
        *(f"[session] {node}: {receiver_text(status, (restarts or {}).get(node, 0))}"
          for node, status in sorted(view.receivers.items())),
        *([f"[session] polar_streamer: {strap_text(view.strap_status)}"] if view.strap_status else []),
    ])


def receiver_text(status: dict, restarts: int = 0) -> str:
    """A receiver's last status in words: what it received, published, and what went missing.

    The status is its last process's: after ``restarts`` restarts it counts since the last one (what
    its source sent while it was down is on the launcher's restarts line)."""
    received, published = status.get("received_samples"), status.get("published_samples")
    text = f"{received} samples received, {published} published"
    lost = [f"{status[k]} {k.replace('_', ' ')}" for k in ("gaps", "missing_samples", "rejected_chunks")
            if status.get(k)]
    text += f" ({', '.join(lost)})" if lost else ", nothing lost"
    return text + (f" (counted since its restart {restarts}; what its source sent while it was down: "
                   "the restarts line)" if restarts else "")


def strap_text(status: dict) -> str:
    """polar_streamer's last status in words: reconnects and the watchdog's stalls."""
    return (f"{status.get('stalls', 0)} stall(s) of a stream ({status.get('stall_reconnects', 0)} ended in a "
            f"reconnection), {status.get('reconnects', 0)} reconnection(s) in all")


def overdue(view: SessionView, now: float, duration: float, margin: float) -> bool:
    """The coach should have ended the session by now (sim time): it ran ``margin`` past the routine."""
    if view.started_at is None or view.ended_at is not None:
        return False
    return now - view.started_at > (view.duration if view.duration is not None else duration) + margin


def session_counts(view: SessionView) -> dict[str, Any]:
    """The session's numbers for ``summary.json`` (the same the closing lines say)."""
    return {
        "started_at": view.started_at, "ended_at": view.ended_at, "routine_duration": view.duration,
        "outcome": "finished" if view.ended_at is not None else ("conflict" if view.conflict else
                                                                 "stopped" if view.started_at is not None
                                                                 else "not started"),
        "stop_reason": view.conflict or view.stopped,
        "zone": None if view.zone is None else {"low": view.zone[0], "high": view.zone[1]},
        "rule_updates": view.events.get("rule_update", 0), "adaptations": view.adaptations,
        "behaviours": view.events.get("behaviour", 0), "robot_actions": view.robot_actions,
        "gated": dict(view.gated), "held": dict(view.held), "malformed_events": dict(view.malformed),
        "hr_samples": view.hr_samples, "exercise_hr_samples": view.exercise_hr,
        "exercise_hr_in_zone": view.exercise_in_zone, "events": dict(view.events),
        "receivers": {node: dict(status) for node, status in view.receivers.items()},
        "polar_streamer": dict(view.strap_status) if view.strap_status else None,
    }


def every_listener_matched(matched: int | None, listeners: int) -> bool:
    """The coach's command publisher has matched every subscription on its topic. A reliable message
    reaches a subscription its publisher had matched when sending it, even one whose own side of the
    match comes later (the middleware repairs it); one sent before that match is lost to it: the
    session's first commands (the welcome, the music) would never reach the robot."""
    return isinstance(matched, int) and listeners > 0 and matched >= listeners

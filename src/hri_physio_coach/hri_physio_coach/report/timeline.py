"""The session as the coach ran it: its clock, phases, activities, zone, rule updates, pace.

Coach events carry the coach's own time ``t`` (ROS time: sim time under ``hri_physio_session``,
wall time in a lab), while the recorder stamps every message with its wall-clock receive time.
:class:`SessionClock` maps receive times onto the coach's clock through the recorded ``/clock``
(or leaves them as they are when the bag has no ``/clock``: the coach then ran on wall time), so
the heart rate the coach received and the events it emitted share one time axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from hri_physio_coach.report.bagdata import BagTables, JsonMessage


class RuleOutcome(StrEnum):
    """What a rule update did, as the thesis's figures name it (the values are the labels)."""

    SPEED_UP = "speed up"
    SLOW_DOWN = "slow down"
    NO_CHANGE = "no change"
    NO_UPDATE = "no update (no HR)"


EXERCISE_KINDS = ("warm_up", "conditioning", "cool_down")


class SessionClock:
    """Receive time (ns, recorder's wall clock) -> the coach's clock (s)."""

    def __init__(self, receive_ns: np.ndarray | None = None, clock_s: np.ndarray | None = None) -> None:
        self.mapped = receive_ns is not None and clock_s is not None and len(receive_ns) >= 2
        if self.mapped:
            assert receive_ns is not None and clock_s is not None
            self._base = int(receive_ns[0])
            self._x = (np.asarray(receive_ns, dtype=np.int64) - self._base) * 1e-9
            self._y = np.asarray(clock_s, dtype=np.float64)
            span = self._x[-1] - self._x[0]
            self._slope = (self._y[-1] - self._y[0]) / span if span > 0 else 1.0

    @property
    def last(self) -> float:
        """The last recorded /clock time (inf when there is no /clock to map by)."""
        return float(self._y[-1]) if self.mapped else math.inf

    @classmethod
    def from_tables(cls, tables: BagTables) -> SessionClock:
        return cls(*tables.clock) if tables.clock is not None else cls()

    def __call__(self, receive_ns: np.ndarray | int) -> np.ndarray:
        ns = np.asarray(receive_ns, dtype=np.int64)
        if not self.mapped:
            return ns * 1e-9
        x = (ns - self._base) * 1e-9
        y = np.interp(x, self._x, self._y)
        # Outside the recorded /clock (before the launcher drove it, after it stopped): the
        # session's average speed, not a clamp that would pile samples onto one instant.
        before, after = x < self._x[0], x > self._x[-1]
        y = np.where(before, self._y[0] + (x - self._x[0]) * self._slope, y)
        return np.where(after, self._y[-1] + (x - self._x[-1]) * self._slope, y)


@dataclass(frozen=True)
class Span:
    name: str
    kind: str
    label: str
    start: float
    end: float
    planned_end: float

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class RuleUpdate:
    t: float
    phase: str | None
    phase_kind: str | None
    action: str  # the coach's own action name
    outcome: RuleOutcome
    delta: int
    hr: float | None
    p: float | None
    draw: float | None
    reason: str
    #: The decision changed the setting: a ladder step (delta) or the activity (the coach's ``changed``).
    changed: bool = False


@dataclass(frozen=True)
class Zone:
    hr_rest: float
    hr_max: float
    low: float
    high: float
    target: float
    low_fraction: float
    high_fraction: float
    hr_rest_source: str | None


@dataclass
class Timeline:
    """What the coach's events say about the session (times on the coach's clock, seconds)."""

    t0: float
    end: float
    outcome: str  # finished | stopped | incomplete
    stop_reason: str | None
    participant: str | None
    policy: str | None
    routine: str | None
    planned_duration: float | None
    phases: list[Span]
    activities: list[Span]
    zone: Zone | None
    calibration: dict[str, Any] | None
    rule_updates: list[RuleUpdate]
    behaviours: list[dict[str, Any]]
    hr_gaps: list[dict[str, Any]]
    pace: list[tuple[float, float, float]]  # (t, gesture speed, music tempo) steps
    events: list[dict[str, Any]] = field(default_factory=list)
    hr_topic: str | None = None  # if the coach said so in its events/state
    #: The session launcher's events (node restarts, receiver gaps, the loss of a node), by time.
    session_events: list[dict[str, Any]] = field(default_factory=list)


def outcome_of(decision: dict[str, Any]) -> RuleOutcome:
    action = str(decision.get("action", ""))
    if action == "gated":
        return RuleOutcome.NO_UPDATE
    delta = int(decision.get("delta") or 0)
    return (RuleOutcome.SPEED_UP if delta > 0 else RuleOutcome.SLOW_DOWN if delta < 0
            else RuleOutcome.NO_CHANGE)


def _num(value: Any) -> float | None:
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _spans(starts: list[dict[str, Any]], name_key: str, kind_key: str, label_key: str,
           stop_at: float, parents: list[Span] | None = None) -> list[Span]:
    spans = []
    for i, ev in enumerate(starts):
        start = float(ev["t"])
        duration = _num(ev.get("duration"))
        planned = start + duration if duration is not None else math.inf  # then: until the next one
        end = min(planned, stop_at)
        if i + 1 < len(starts):
            end = min(end, float(starts[i + 1]["t"]))
        if parents:  # an activity ends with its phase at the latest
            parent = next((p for p in parents if p.start <= start < p.end), None)
            if parent is not None:
                end = min(end, parent.end)
        spans.append(Span(str(ev.get(name_key)), str(ev.get(kind_key) or ev.get(name_key)),
                          str(ev.get(label_key) or ev.get(name_key)), start, max(end, start), planned))
    return spans


def build_timeline(tables: BagTables, events_topic: str, state_topic: str,
                   clock: SessionClock, session_topic: str | None = None) -> Timeline | None:
    """The coach's session from its events (``None``: the bag holds no coach events), with the
    launcher's events on ``session_topic`` (its sim time ``t``, the coach's clock)."""
    messages: list[JsonMessage] = [m for m in tables.json.get(events_topic, []) if "event" in m.data]
    if not messages:
        return None
    events = []
    for m in messages:
        ev = dict(m.data)
        if _num(ev.get("t")) is None:  # an event without the coach's time: use its receive time
            ev["t"] = float(clock(m.log_ns))
        events.append(ev)
    events.sort(key=lambda e: float(e["t"]))
    states = [m.data for m in tables.json.get(state_topic, []) if _num(m.data.get("t")) is not None]
    by_kind: dict[str, list[dict[str, Any]]] = {}
    for ev in events:
        by_kind.setdefault(str(ev["event"]), []).append(ev)

    starts = by_kind.get("session_start", [])
    t0 = float(starts[0]["t"]) if starts else float(events[0]["t"])
    finished = by_kind.get("session_end", [])
    stopped = by_kind.get("session_stopped", [])
    if finished:
        end, outcome, reason = float(finished[0]["t"]), "finished", None
    elif stopped:
        end, outcome, reason = float(stopped[0]["t"]), "stopped", str(stopped[0].get("reason", ""))
    else:
        last_seen = [float(events[-1]["t"])]
        if tables.end_ns is not None:
            # Session time does not pass once its /clock stops: what the nodes published as they
            # stopped (seconds of wall time after it) is not projected at the session's speed.
            last_seen.append(min(float(clock(tables.end_ns)), clock.last))
        end, outcome, reason = max(last_seen), "incomplete", None
    phases = _spans(by_kind.get("phase", []), "phase", "kind", "phase", end)
    activities = _spans(by_kind.get("activity", []), "activity", "phase", "label", end, phases)

    zone = None
    zones = by_kind.get("zone", [])
    calib = by_kind.get("calibration", [])
    if zones:
        z = zones[-1]
        zone = Zone(float(z["hr_rest"]), float(z["hr_max"]), float(z["low"]), float(z["high"]),
                    float(z.get("target", 0.5 * (float(z["low"]) + float(z["high"])))),
                    float(z.get("low_fraction", math.nan)), float(z.get("high_fraction", math.nan)),
                    str(calib[-1].get("source")) if calib else None)

    updates = []
    for ev in by_kind.get("rule_update", []):
        d = ev.get("decision") or {}
        inputs = ev.get("inputs") or {}
        hr = _num(d.get("hr"))
        if hr is None:
            hr = _num(inputs.get("hr_mean"))
        updates.append(RuleUpdate(
            float(ev["t"]), inputs.get("phase"), inputs.get("phase_kind"), str(d.get("action", "")),
            outcome_of(d), int(d.get("delta") or 0), hr, _num(d.get("p")), _num(d.get("draw")),
            str(d.get("reason", "")), bool(d.get("changed", int(d.get("delta") or 0) != 0))))

    policy = next((str(u.get("decision", {}).get("policy")) for u in by_kind.get("rule_update", [])
                   if u.get("decision", {}).get("policy")), None)
    if policy is None:
        policy = next((str(s["policy"]) for s in states if s.get("policy")), None)
    participant = next((str(e["participant"]) for e in events if e.get("participant")), None)
    hr_topic = next((str(e["hr_topic"]) for e in events + states if e.get("hr_topic")), None)
    return Timeline(
        t0=t0, end=end, outcome=outcome, stop_reason=reason, participant=participant, policy=policy,
        routine=str(starts[0].get("routine")) if starts else None,
        planned_duration=_num(starts[0].get("duration")) if starts else None,
        phases=phases, activities=activities, zone=zone, calibration=calib[-1] if calib else None,
        rule_updates=updates, behaviours=by_kind.get("behaviour", []),
        hr_gaps=_hr_gaps(by_kind, end), pace=_pace(states, by_kind.get("rule_update", [])),
        events=events, hr_topic=hr_topic, session_events=_session_events(tables, session_topic, clock),
    )


def _session_events(tables: BagTables, topic: str | None, clock: SessionClock) -> list[dict[str, Any]]:
    """The launcher's events in time order (one without a time: its receive time)."""
    out = []
    for m in tables.json.get(topic, []) if topic else []:
        if "event" not in m.data:
            continue
        ev = dict(m.data)
        if _num(ev.get("t")) is None:
            ev["t"] = float(clock(m.log_ns))
        out.append(ev)
    return sorted(out, key=lambda e: float(e["t"]))


def _hr_gaps(by_kind: dict[str, list[dict[str, Any]]], end: float) -> list[dict[str, Any]]:
    """Spells without heart rate at the coach (hr_lost .. hr_resumed), on the coach's clock."""
    marks = sorted([(float(e["t"]), "lost", e) for e in by_kind.get("hr_lost", [])]
                   + [(float(e["t"]), "resumed", e) for e in by_kind.get("hr_resumed", [])],
                   key=lambda m: m[0])
    gaps: list[dict[str, Any]] = []
    open_gap: dict[str, Any] | None = None
    for t, kind, ev in marks:
        if kind == "lost" and open_gap is None:
            since = _num(ev.get("silent_since"))
            open_gap = {"silent_since": since if since is not None else t, "detected": t}
        elif kind == "resumed" and open_gap is not None:
            open_gap["resumed"] = t
            gaps.append(open_gap)
            open_gap = None
    if open_gap is not None:
        open_gap["resumed"] = None
        gaps.append(open_gap)
    for g in gaps:
        g["seconds"] = (g["resumed"] if g["resumed"] is not None else end) - g["silent_since"]
    return gaps


def _pace(states: list[dict[str, Any]], updates: list[dict[str, Any]]) -> list[tuple[float, float, float]]:
    """(t, gesture speed, tempo) whenever the coach's speed ladder was seen or changed."""
    points = []
    for s in states:
        speed, tempo = _num(s.get("ladder_speed")), _num(s.get("ladder_tempo"))
        if speed is not None and tempo is not None:
            points.append((float(s["t"]), speed, tempo))
    for u in updates:
        ladder = u.get("ladder") or {}
        speed, tempo = _num(ladder.get("speed")), _num(ladder.get("tempo"))
        if speed is not None and tempo is not None:
            points.append((float(u["t"]), speed, tempo))
    points.sort(key=lambda p: p[0])
    steps: list[tuple[float, float, float]] = []
    for p in points:
        if not steps or (p[1], p[2]) != steps[-1][1:]:
            steps.append(p)
    return steps

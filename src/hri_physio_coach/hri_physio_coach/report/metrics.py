"""The report's numbers, from the bag alone (docs/REPORT.md says what each one means).

Heart-rate numbers use the HR the coach received (its input topic), each sample placed at the
time the recorder received it, mapped onto the coach's clock; a sample counts when the coach
would have used it: finite, within the plausible range and not flagged by its source.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from hri_physio_coach.report.bagdata import BagTables, FrameStream
from hri_physio_coach.report.timeline import EXERCISE_KINDS, RuleOutcome, SessionClock, Timeline

HR_CHANNELS = ("hr", "bpm", "heart_rate")
FLAG_CHANNEL = "flag"
HRV_FEATURES = ("lf", "hf", "lfhf")
#: A gap in a stream: consecutive source timestamps further apart than this many periods.
GAP_FACTOR = 1.5
_RAW_STREAM = re.compile(r"^/physio/[^/]+/[^/]+$")
_FEATURE = re.compile(r"^(/physio/[^/]+/[^/]+)/(?:.+/)?([^/]+)$")


@dataclass
class HeartRate:
    """The coach's input heart rate on the session's time axis."""

    topic: str
    t: np.ndarray  # coach clock, s
    bpm: np.ndarray
    valid: np.ndarray  # bool
    period: float  # nominal sampling period, s (from the source timestamps)

    @classmethod
    def from_stream(cls, stream: FrameStream, clock: SessionClock, valid_min: float,
                    valid_max: float) -> HeartRate:
        bpm = stream.column(HR_CHANNELS)
        lower = [c.lower() for c in stream.channels]
        flagged = (stream.values[:, lower.index(FLAG_CHANNEL)] != 0.0 if FLAG_CHANNEL in lower
                   else np.zeros(bpm.shape, dtype=bool))
        valid = np.isfinite(bpm) & (bpm >= valid_min) & (bpm <= valid_max) & ~flagged
        return cls(stream.topic, clock(stream.log_ns), bpm, valid, nominal_period(stream.source_t))


def nominal_period(source_t: np.ndarray) -> float:
    """Median spacing of a stream's own timestamps (NaN with fewer than two samples)."""
    d = np.diff(np.asarray(source_t, dtype=np.float64))
    d = d[np.isfinite(d) & (d > 0)]
    return float(np.median(d)) if d.size else math.nan


def _clean(value: float | None, digits: int = 4) -> float | None:
    if value is None or not math.isfinite(value):
        return None
    return round(float(value), digits)


def stream_accounting(stream: FrameStream) -> dict[str, Any]:
    """Samples expected (nominal rate x span of the stream's own timestamps) vs received."""
    t = np.asarray(stream.source_t, dtype=np.float64)
    t = t[np.isfinite(t)]
    period = nominal_period(t)
    out: dict[str, Any] = {"frames": stream.frames, "received": int(stream.num_samples),
                           "malformed_frames": stream.bad_frames}
    if t.size < 2 or not math.isfinite(period):
        out.update(expected=None, missing=None, loss_fraction=None, rate_hz=None, gaps=0)
        return out
    order = np.sort(t)
    d = np.diff(order)
    gap_mask = d > GAP_FACTOR * period
    # Each step counted in periods: the median period's float error does not add up over a session.
    expected = int(np.sum(np.round(d[d > 0] / period))) + 1
    missing = max(expected - int(np.unique(order).size), 0)
    longest = float(d[gap_mask].max()) if gap_mask.any() else 0.0
    out.update(
        rate_hz=_clean(1.0 / period, 3), span_s=_clean(order[-1] - order[0], 3), expected=int(expected),
        missing=int(missing), loss_fraction=_clean(missing / expected if expected else 0.0, 5),
        gaps=int(gap_mask.sum()), longest_gap_s=_clean(longest, 3),
        duplicates=int(order.size - np.unique(order).size),
        out_of_order=int(np.sum(np.diff(t) < 0)),
    )
    return out


def _phase_hr(hr: HeartRate, start: float, end: float, low: float | None,
              high: float | None) -> dict[str, Any]:
    inside = (hr.t >= start) & (hr.t < end)
    n_all = int(inside.sum())
    sel = inside & hr.valid
    bpm = hr.bpm[sel]
    out: dict[str, Any] = {"hr_samples": int(sel.sum()), "invalid_samples": n_all - int(sel.sum()),
                           "hr_mean": _clean(float(bpm.mean()), 2) if bpm.size else None}
    if low is None or high is None or not bpm.size:
        out.update(in_zone_samples=None, in_zone_fraction=None, seconds_above_hrr70=None,
                   seconds_below_hrr40=None)
        return out
    period = hr.period if math.isfinite(hr.period) else 1.0
    in_zone = int(np.sum((bpm >= low) & (bpm <= high)))
    out.update(
        in_zone_samples=in_zone,
        in_zone_fraction=_clean(in_zone / bpm.size, 4),
        seconds_above_hrr70=_clean(float(np.sum(bpm > high)) * period, 1),
        seconds_below_hrr40=_clean(float(np.sum(bpm < low)) * period, 1),
    )
    return out


def compute(tables: BagTables, timeline: Timeline, clock: SessionClock,
            hr: HeartRate | None) -> dict[str, Any]:
    """Every number of report.json but the file list and provenance."""
    zone = timeline.zone
    low, high = (zone.low, zone.high) if zone else (None, None)
    phases = []
    by_kind: dict[str, list[dict[str, Any]]] = {}
    for span in timeline.phases:
        entry: dict[str, Any] = {
            "name": span.name, "kind": span.kind, "start_s": _clean(span.start - timeline.t0, 2),
            "end_s": _clean(span.end - timeline.t0, 2), "planned_s": _clean(span.planned_end - span.start, 2),
            "completed": span.end >= span.planned_end - 1e-6,
        }
        if hr is not None:  # the zone is not in force while calibration measures HR_rest
            in_force = span.kind != "calibration"
            entry.update(_phase_hr(hr, span.start, span.end, low if in_force else None,
                                   high if in_force else None))
        phases.append(entry)
        by_kind.setdefault(span.kind, []).append(entry)

    in_zone: dict[str, float | None] = {}
    above = 0.0
    for kind in EXERCISE_KINDS:
        entries = [e for e in by_kind.get(kind, []) if e.get("in_zone_fraction") is not None]
        n = sum(e["hr_samples"] for e in entries)
        in_zone[kind] = _clean(sum(e["in_zone_samples"] for e in entries) / n, 4) if n else None
        above += sum(e["seconds_above_hrr70"] for e in entries)
    exercise_seen = any(by_kind.get(k) for k in EXERCISE_KINDS) and hr is not None and zone is not None

    report: dict[str, Any] = {
        "hr_rest": _clean(zone.hr_rest, 2) if zone else None,
        "hr_rest_source": zone.hr_rest_source if zone else None,
        "hr_max": _clean(zone.hr_max, 2) if zone else None,
        "zone": ({"low": _clean(zone.low, 2), "high": _clean(zone.high, 2), "target": _clean(zone.target, 2),
                  "low_fraction": _clean(zone.low_fraction), "high_fraction": _clean(zone.high_fraction)}
                 if zone else None),
        "in_zone_fraction": in_zone,
        "seconds_above_hrr70": _clean(above, 1) if exercise_seen else None,
        "phases": phases,
        "adaptations": _adaptations(timeline),
        "behaviours": _behaviours(timeline),
        "robot": _robot(tables, timeline),
        "signal_quality": _signal_quality(tables, timeline, clock),
        "streams": {topic: stream_accounting(s) for topic, s in sorted(tables.frames.items())
                    if _RAW_STREAM.match(topic)},
        "receivers": _receivers(tables),
        "recorder_lost_messages": tables.custom_data.get("lost_messages"),
        "hrv": hrv_summary(tables),
        "hrv_method": hrv_method(tables),
        "session_events": session_events(timeline),
    }
    if hr is not None:
        in_session = (hr.t >= timeline.t0) & (hr.t <= timeline.end)
        report["hr_input"] = {"topic": hr.topic, "samples_in_session": int(in_session.sum()),
                              "valid_in_session": int((in_session & hr.valid).sum()),
                              "period_s": _clean(hr.period, 4)}
    return report


def session_events(timeline: Timeline) -> list[dict[str, Any]]:
    """The launcher's events (restarts, receiver gaps, a lost node), ``t_s`` from the session's start."""
    keys = ("event", "node", "exit_status", "restart", "down_s", "reason", "missing")
    return [{"t_s": _clean(float(ev["t"]) - timeline.t0, 2), **{k: ev[k] for k in keys if k in ev}}
            for ev in timeline.session_events]


def _adaptations(timeline: Timeline) -> dict[str, Any]:
    """Adaptations as the coach and the evaluation count them: every decision that changed the setting
    (a ladder step or the activity), at a rule update or in a phase's plan (predictive, adaptive)."""
    per_phase: dict[str, dict[str, int]] = {}

    def row_of(phase: str | None) -> dict[str, int]:
        return per_phase.setdefault(phase or "(none)", {"rule_updates": 0, "adaptations": 0,
                                                        **dict.fromkeys(RuleOutcome, 0)})

    for u in timeline.rule_updates:
        row = row_of(u.phase)
        row["rule_updates"] += 1
        row["adaptations"] += int(u.changed)
        row[u.outcome] += 1
    plans = [e for e in timeline.events
             if e.get("event") == "plan" and (e.get("decision") or {}).get("changed")]
    for e in plans:
        row_of(str(e["phase"]) if e.get("phase") is not None else None)["adaptations"] += 1
    actions = Counter(u.action for u in timeline.rule_updates)
    # What the coach said about the zone itself: out of reach, or a gap bridged by alternating two settings.
    notices = [{"t": e.get("t"), "event": e.get("event"), "reason": e.get("reason")} for e in timeline.events
               if e.get("event") in ("zone_out_of_reach", "zone_gap")]
    return {"total": sum(int(u.changed) for u in timeline.rule_updates) + len(plans),
            "planned_changes": len(plans),
            "rule_updates": len(timeline.rule_updates), "per_phase": per_phase, "actions": dict(actions),
            "zone_notices": notices}


def _behaviours(timeline: Timeline) -> dict[str, Any]:
    kinds = Counter(str(b.get("kind")) for b in timeline.behaviours)
    fallbacks = sum(1 for b in timeline.behaviours if b.get("fallback_from"))
    skipped = sum(1 for e in timeline.events if e.get("event") == "hook_skipped")
    return {"total": sum(kinds.values()), "by_kind": dict(kinds), "hr_report_fallbacks": fallbacks,
            "skipped_for_rule_update": skipped}


def _robot(tables: BagTables, timeline: Timeline) -> dict[str, Any]:
    commands = Counter()
    failed = unanswered = 0
    for e in timeline.events:
        if e.get("event") == "command":
            words = str(e.get("command", "")).split()
            commands[" ".join(words[:2]) if len(words) >= 2 else (words[0] if words else "?")] += 1
        elif e.get("event") == "command_failed":
            failed += 1
        elif e.get("event") == "command_unanswered":
            unanswered += 1
    mock = Counter()
    for topic, msgs in tables.json.items():
        if topic.endswith("/mock/events"):
            mock.update(str(m.data.get("event")) for m in msgs)
    return {"commands": dict(commands), "commands_failed": failed, "commands_unanswered": unanswered,
            "robot_events": dict(mock)}


def _signal_quality(tables: BagTables, timeline: Timeline, clock: SessionClock) -> dict[str, Any]:
    gated = Counter(re.sub(r"\d+(\.\d+)?", "N", u.reason) for u in timeline.rule_updates
                    if u.outcome == RuleOutcome.NO_UPDATE)
    gaps = [{"start_s": _clean(g["silent_since"] - timeline.t0, 1),
             "end_s": _clean(g["resumed"] - timeline.t0, 1) if g["resumed"] is not None else None,
             "seconds": _clean(g["seconds"], 1)} for g in timeline.hr_gaps]
    processor: dict[str, Any] = {}
    for topic, msgs in sorted(tables.json.items()):
        windows = [m.data for m in msgs if m.data.get("event") == "window"]
        discontinuities = [m.data for m in msgs if m.data.get("event") == "discontinuity"]
        if not windows and not discontinuities:
            continue
        flags = Counter()
        for w in windows:
            for f in w.get("flags") or []:
                flags[str(f.get("code") or f.get("reason")) if isinstance(f, dict) else str(f)] += 1
        processor[topic] = {
            "windows": len(windows), "windows_flagged": sum(1 for w in windows if not w.get("ok", True)),
            "windows_inverted": sum(1 for w in windows if w.get("inverted")),
            "flags": dict(flags), "discontinuities": len(discontinuities),
            "missing_samples_reported": int(sum(int(d.get("missing_samples") or 0) for d in discontinuities)),
        }
    lost = _clean(sum(g["seconds"] for g in timeline.hr_gaps), 1)
    return {"coach_hr_gaps": gaps, "coach_hr_gap_seconds": lost, "rule_updates_gated": dict(gated),
            "processor": processor}


def _receivers(tables: BagTables) -> dict[str, Any]:
    keys = ("received_samples", "published_samples", "gaps", "missing_samples", "nonfinite_samples",
            "rejected_chunks", "reconnects", "publish_errors")
    out: dict[str, Any] = {}
    for topic, msgs in sorted(tables.json.items()):
        last = next((m.data for m in reversed(msgs) if "received_samples" in m.data), None)
        if last is not None:
            out[str(last.get("node") or topic)] = {k: last.get(k) for k in keys if k in last}
    return out


def source_to_session(tables: BagTables, topic: str, clock: SessionClock) -> tuple[float, str]:
    """Offset from a stream's source clock to the coach's clock, and how it was found.

    Processor outputs are stamped with the source time of their window; received late when the
    processor lags (or in bursts under fast sim time), their receive times would misplace them.
    The offset comes from the raw stream they were computed from: the 5th percentile of
    (receive time on the coach's clock - source time) is the delivery delay without the backlog.
    """
    m = _FEATURE.match(topic)
    raw = tables.frames.get(m.group(1)) if m else None
    if raw is None or raw.num_samples < 2:
        return math.nan, "receive time"
    delay = clock(raw.log_ns) - raw.source_t
    delay = delay[np.isfinite(delay)]
    if not delay.size:
        return math.nan, "receive time"
    return float(np.percentile(delay, 5)), f"source time of {raw.topic}"


def feature_times(tables: BagTables, topic: str, clock: SessionClock) -> np.ndarray:
    """Times of a processor feature's samples on the coach's clock (see :func:`source_to_session`)."""
    stream = tables.frames[topic]
    offset, _ = source_to_session(tables, topic, clock)
    return stream.source_t + offset if math.isfinite(offset) else clock(stream.log_ns)


def hrv_series(tables: BagTables) -> dict[str, FrameStream]:
    """Frequency-domain HRV streams of the processor (``.../lf``, ``.../hf``, ``.../lfhf``)."""
    out = {}
    for topic, stream in sorted(tables.frames.items()):
        m = _FEATURE.match(topic)
        if m and m.group(2) in HRV_FEATURES and stream.num_samples:
            out[topic] = stream
    return out


def hrv_summary(tables: BagTables) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for topic, stream in hrv_series(tables).items():
        v = stream.values[:, 0]
        finite = v[np.isfinite(v)]
        out[topic] = {"windows": int(v.size), "finite": int(finite.size),
                      "median": _clean(float(np.median(finite))) if finite.size else None,
                      "mean": _clean(float(finite.mean())) if finite.size else None,
                      "last": _clean(float(finite[-1])) if finite.size else None}
        reason = _nan_reason(tables, topic)
        if not finite.size and reason:
            out[topic]["nan_reason"] = reason
    return out


def hrv_method(tables: BagTables) -> dict[str, Any]:
    """How the processor computed LF, HF, LF/HF, and over how long a window: what its status says.

    ``method``: the processor's ``hrv_method`` sentence (None from a processor that did not publish
    one: before it computed LF and HF in ms^2). ``window_seconds``: the longest ``hrv_window`` any
    status reported (the configured ``hrv_window_seconds`` once the beat series is that long); None
    for LF/HF on each window itself.
    """
    method, seconds = None, []
    for topic, msgs in tables.json.items():
        if not topic.startswith("/physio/"):
            continue
        for m in msgs:
            if isinstance(m.data.get("hrv_method"), str):
                method = m.data["hrv_method"]
            window = m.data.get("hrv_window")
            if isinstance(window, dict) and window.get("seconds"):
                seconds.append(float(window["seconds"]))
    return {"method": method, "window_seconds": _clean(max(seconds), 1) if seconds else None}


def hrv_method_text(method: dict[str, Any]) -> str:
    window = method.get("window_seconds")
    where = (f"over the last {window:g} s of clean beats before each window's end" if window
             else "over each processing window")
    how = method.get("method") or ("method not in the recording (a processor before LF and HF in ms^2: "
                                    "NeuroKit2's hrv_frequency, scaled to its maximum)")
    return f"{how}; {where}."


def _nan_reason(tables: BagTables, topic: str) -> str | None:
    """Why the processor published NaN for a feature (from its status topic)."""
    m = _FEATURE.match(topic)
    if m is None:
        return None
    root, feature = m.group(1), m.group(2)
    for status_topic, msgs in tables.json.items():
        if not status_topic.startswith(root + "/"):
            continue
        for m in reversed(msgs):
            reasons = m.data.get("nan")
            if isinstance(reasons, dict) and reasons.get(feature):
                return str(reasons[feature])
    return None

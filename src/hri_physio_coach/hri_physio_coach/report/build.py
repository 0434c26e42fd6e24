"""make_report: a session bag -> hr_session.png, fuzzy figures, report.json and report.html."""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from hri_physio_bridge import topics
from hri_physio_bridge.json_files import json_safe, write_text_atomic
from hri_physio_coach.report import figures as plots
from hri_physio_coach.report import metrics, page
from hri_physio_coach.report.bagdata import BagTables, ReportError, read_bag
from hri_physio_coach.report.inputs import ReportInput, config_value, resolve
from hri_physio_coach.report.metrics import HeartRate
from hri_physio_coach.report.timeline import SessionClock, Timeline, build_timeline

REPORT_JSON = "report.json"
REPORT_HTML = "report.html"
FIGURE_FILES = {"hr_session": "hr_session.png", "fuzzy_probability": "fuzzy_probability.png",
                "fuzzy_overlay": "fuzzy_overlay.png", "hrv": "hrv.png"}
#: The coach's plausible heart-rate range when no configuration says otherwise (CoachConfig's defaults).
DEFAULT_VALID_RANGE = (30.0, 230.0)
_HR_FROM_LOG = re.compile(r"HR from (/[A-Za-z0-9_/]+)")


@dataclass
class ReportResult:
    out_dir: Path
    files: dict[str, Path]
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)  # the bag's own (killed recorder, lost messages)
    missing: list[str] = field(default_factory=list)  # what the report could not show, and why


def choose_hr_topic(tables: BagTables, timeline: Timeline, configs: dict[str, str],
                    explicit: str | None) -> tuple[str | None, str]:
    """The coach's HR input topic and where that came from."""
    if explicit:
        return explicit, "--hr-topic"
    if timeline.hr_topic:
        return timeline.hr_topic, "coach events"
    found = config_value(configs, "hr_topic")
    if found is not None:
        return str(found[0]), f"configs/{found[1]}"
    for _ns, _logger, text in tables.log_lines:
        m = _HR_FROM_LOG.search(text)
        if m:
            return m.group(1), "coach log (/rosout)"
    for candidate in (topics.POLAR_H10_HR, topics.POLAR_H10_ECG_HR):
        if candidate in tables.frames:
            return candidate, "default (the coach's configuration is not in the bag)"
    return None, "none"


def _valid_range(configs: dict[str, str]) -> tuple[float, float]:
    lo, hi = DEFAULT_VALID_RANGE
    for key, default in (("hr_valid_min", lo), ("hr_valid_max", hi)):
        found = config_value(configs, key)
        value = default
        if found is not None:
            try:
                value = float(found[0])
            except (TypeError, ValueError):
                value = default
        if key == "hr_valid_min":
            lo = value
        else:
            hi = value
    return lo, hi


def _figures(out_dir: Path, timeline: Timeline, tables: BagTables, clock: SessionClock, hr: HeartRate | None,
             who: str, when: str, missing: list[str]) -> dict[str, Path]:
    title = f"Heart rate during the session — {who} — {when}"
    files = {"hr_session": plots.hr_session_figure(out_dir / FIGURE_FILES["hr_session"], timeline, hr, title)}
    if timeline.policy == "fuzzy":
        if timeline.zone is not None:
            files["fuzzy_probability"] = plots.fuzzy_probability_figure(
                out_dir / FIGURE_FILES["fuzzy_probability"], timeline,
                f"Fuzzy rule: probability of a pace change p(HR) — {who}")
            files["fuzzy_overlay"] = plots.fuzzy_overlay_figure(
                out_dir / FIGURE_FILES["fuzzy_overlay"], timeline, hr,
                f"Update probability along the heart-rate trace — {who}")
        else:
            missing.append("fuzzy figures: no zone to draw p(HR) for")
    hrv_path = plots.hrv_figure(out_dir / FIGURE_FILES["hrv"], timeline, tables, clock,
                                f"Frequency-domain HRV — {who}")
    if hrv_path is not None:
        files["hrv"] = hrv_path
    return files


def make_report(path: Path | str, out: Path | str | None = None, hr_topic: str | None = None,
                figures: bool = True) -> ReportResult:
    """Read the bag of a session folder / bag directory / .mcap file and write the report files.

    ``figures=False`` writes report.json and report.html only (numbers for many sessions, fast).
    Raises :class:`ReportError` (one line) when the input cannot give a report.
    """
    where: ReportInput = resolve(Path(path), Path(out) if out is not None else None)
    tables = read_bag(where.bag)
    clock = SessionClock.from_tables(tables)
    timeline = build_timeline(tables, topics.COACH_EVENTS, topics.COACH_STATE, clock, topics.SESSION_EVENTS)
    if timeline is None:
        raise ReportError(f"{where.bag} holds no coach events on {topics.COACH_EVENTS}: not a recording of a "
                          "qt_physio_coach session")
    missing: list[str] = []
    topic, topic_from = choose_hr_topic(tables, timeline, where.configs, hr_topic)
    hr: HeartRate | None = None
    if topic is None:
        missing.append("no heart-rate topic in the bag: no heart-rate numbers")
    elif topic not in tables.frames or tables.frames[topic].num_samples == 0:
        missing.append(f"the coach's heart-rate input {topic} holds no frames in the bag")
    else:
        lo, hi = _valid_range(where.configs)
        hr = HeartRate.from_stream(tables.frames[topic], clock, lo, hi)
    if timeline.zone is None:
        missing.append("no zone: the session ended before calibration set HR_rest and the zone")
    if not tables.clock and any(k == "/clock" for k in tables.topic_types):
        missing.append("/clock holds fewer than 2 messages: receive times used as the coach's clock")
    if timeline.outcome != "finished":
        why = f": {timeline.stop_reason}" if timeline.stop_reason else ""
        missing.append(f"the session did not finish ({timeline.outcome}{why}): the report covers what ran")
    if not timeline.rule_updates:
        missing.append("no rule updates in the bag")
    for ev in timeline.session_events:
        if ev.get("event") == "node_died":
            missing.append(f"the session ended early: {ev.get('node')} died (exit status "
                           f"{ev.get('exit_status')}, {ev.get('reason')})")

    numbers = metrics.compute(tables, timeline, clock, hr)
    hrv_series = metrics.hrv_series(tables)
    if not hrv_series:
        missing.append("no LF/HF from the processor in the bag (ECG not recorded or not processed)")
    elif not any(v["finite"] for v in numbers["hrv"].values()):
        missing.append("LF/HF: every window NaN (" + "; ".join(
            sorted({v["nan_reason"] for v in numbers["hrv"].values() if v.get("nan_reason")})) + ")")

    try:
        where.out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReportError(f"cannot create {where.out_dir}: {exc.strerror}") from None
    started = datetime.fromtimestamp(timeline.t0, UTC).astimezone() if math.isfinite(timeline.t0) else None
    who = f"participant {timeline.participant or '?'}, {timeline.policy or '?'} policy"
    when = started.strftime("%Y-%m-%d %H:%M") if started else ""
    out_dir = where.out_dir
    for name in FIGURE_FILES.values():  # a figure of an earlier run must not pass for this one's
        (out_dir / name).unlink(missing_ok=True)
    files: dict[str, Path] = {}
    if figures:
        files.update(_figures(out_dir, timeline, tables, clock, hr, who, when, missing))

    report: dict[str, Any] = {
        "generated_by": "hri_physio_report",
        "bag": str(where.bag),
        "bag_complete": tables.complete,
        "bag_warnings": tables.warnings,
        "participant": timeline.participant,
        "policy": timeline.policy,
        "routine": timeline.routine,
        "session": {
            "start_unix": timeline.t0, "start": started.isoformat() if started else None,
            "duration_s": round(timeline.end - timeline.t0, 2),
            "planned_duration_s": timeline.planned_duration,
            "outcome": timeline.outcome, "stop_reason": timeline.stop_reason,
        },
        "time_base": "/clock (sim time)" if clock.mapped else "recorder receive time",
        "hr_topic": topic, "hr_topic_from": topic_from,
        **numbers,
        "missing": missing,
        "figures": {k: p.name for k, p in files.items()},
    }
    json_path = out_dir / REPORT_JSON
    report = json_safe(report)  # the page is rendered from the same safe values
    write_text_atomic(json_path, json.dumps(report, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    html_path = out_dir / REPORT_HTML
    write_text_atomic(html_path, page.render(report, files, where.configs))
    files["report_json"] = json_path
    files["report_html"] = html_path
    return ReportResult(out_dir, files, report, list(tables.warnings), missing)

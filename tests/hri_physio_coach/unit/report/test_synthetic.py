"""hri_physio_report on session bags written for the test: every number known by construction."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from helpers.session_bags import BagBuilder, clock_msg, frame_msg, log_msg, string_msg
from hri_physio_bridge import topics
from hri_physio_coach.report import ReportError, make_report
from hri_physio_coach.report.cli import main

WALL0 = 1_700_000_000 * 10**9  # recorder clock (ns)
SIM0 = 1_800_000_000.0  # the coach's sim clock (s)
SPEED = 10.0  # sim seconds per wall second
HR_REST, HR_MAX = 70.0, 190.0  # zone 118-154 (HRR40-70 of 120 bpm)
LOW, HIGH = HR_REST + 0.4 * 120, HR_REST + 0.7 * 120
PHASES = [("calibration", 0, 30), ("warm_up", 30, 80), ("conditioning", 80, 140), ("cool_down", 140, 180)]
DROPPED = range(90, 95)  # HR samples lost between source and bag (a gap of 5 s)
ECG_RATE, ECG_GAP = 130.0, (2600, 2730)  # ECG sample indexes lost (1 s at 20 s)


def wall(sim: float) -> int:
    """Receive time of something the coach did at sim second ``sim`` of the session."""
    return WALL0 + round(sim / SPEED * 1e9)


def hr_value(k: int) -> float:
    """The HR sample of sim second k (designed per phase, see the expectations below)."""
    if k < 30:
        return 72.0
    if k < 80:
        return 100.0 if k < 50 else 130.0  # warm-up: 20 below, 30 in -> 0.6
    if k < 140:
        return 140.0 if k < 125 else 160.0  # conditioning: 45 in (5 lost), 15 above -> 40/55
    if k < 150:
        return LOW  # cool-down: bounds belong to the zone
    if k < 160:
        return HIGH
    return 0.0 if k == 179 else 110.0  # 19 below, one invalid (0 bpm) -> 20/39


def session(*, clock: bool = True, stop_at: float | None = None, policy: str = "threshold",
            ecg: bool = True, rosout: bool = True, killed: bool = False) -> BagBuilder:
    """``killed``: the coach died at ``stop_at`` (no end event) and the launcher stopped its /clock there."""
    b = BagBuilder()
    end = 180.0 if stop_at is None else stop_at
    to_sim = (lambda s: SIM0 + s) if clock else (lambda s: wall(s) / 1e9)
    if clock:
        for i in range(0, 1901 if not killed else int(end * 10) + 1):
            b.add("/clock", "rosgraph_msgs/msg/Clock", wall(i / 10), clock_msg(SIM0 + i / 10))
    if rosout:
        b.add("/rosout", "rcl_interfaces/msg/Log", wall(0) - 10**8,
              log_msg("qt_physio_coach", f"participant P-test, HR from {topics.POLAR_H10_HR}: waiting"))
    ev = b.event
    ev(wall(0), {"t": to_sim(0), "participant": "P-test", "event": "session_start", "routine": "r",
                 "duration": 180.0, "phases": [p[0] for p in PHASES]})
    for i, (name, a, z) in enumerate(PHASES):
        if a >= end:
            break
        ev(wall(a), {"t": to_sim(a), "event": "phase", "phase": name, "kind": name, "index": i,
                     "duration": float(z - a), "activities": [f"{name}_act"]})
        ev(wall(a), {"t": to_sim(a), "event": "activity", "phase": name, "activity": f"{name}_act",
                     "label": f"{name} activity", "index": 0, "duration": float(z - a)})
        if name == "warm_up":
            ev(wall(a), {"t": to_sim(a), "event": "calibration", "hr_rest": HR_REST, "source": "measured",
                         "reason": "mean", "n_samples": 30, "age": 25.7})
            ev(wall(a), {"t": to_sim(a), "event": "zone", "hr_rest": HR_REST, "hr_max": HR_MAX,
                         "hrr": 120.0, "low_fraction": 0.4, "high_fraction": 0.7, "low": LOW, "high": HIGH,
                         "target": 0.5 * (LOW + HIGH)})
    updates = [(40, "warm_up", "speed_up", 1, 100.0, 0.9, 0.1),
               (60, "warm_up", "encourage", 0, 130.0, 0.5, 0.7),
               (90, "conditioning", "gated", 0, None, None, None),
               (100, "conditioning", "slow_down", -1, 150.0, 0.95, 0.2),
               (120, "conditioning", "change_activity", 0, 140.0, 0.8, 0.4),  # no ladder step, a change
               (150, "cool_down", "at_limit", 0, 118.0, 1.0, 0.3)]
    speed, tempo = 1.0, 120.0
    for t, phase, action, delta, hr, p, draw in updates:
        if t >= end:
            continue
        speed, tempo = speed + 0.05 * delta, tempo + 5 * delta
        ev(wall(t), {"t": to_sim(t), "event": "rule_update",
                     "inputs": {"hr_mean": hr, "phase": phase, "phase_kind": phase},
                     "decision": {"t": to_sim(t), "policy": policy, "action": action, "delta": delta,
                                  "proposed": delta, "reason": "no heart-rate data for 12 s" if hr is None
                                  else f"HR {hr:.1f}", "hr": hr, "p": p, "draw": draw,
                                  "changed": delta != 0 or action == "change_activity"},
                     "ladder": {"index": 2 + delta, "speed": speed, "tempo": tempo}})
    if end > 70:  # a phase's plan that changed the setting (predictive, adaptive): an adaptation too
        ev(wall(70), {"t": to_sim(70), "event": "plan", "phase": "conditioning",
                      "decision": {"t": to_sim(70), "policy": policy, "action": "plan", "delta": 0,
                                   "changed": True, "reason": "planned"}})
    for t, kind in ((45, "motivation"), (75, "emotion"), (110, "motivation")):
        if t < end:
            ev(wall(t), {"t": to_sim(t), "event": "behaviour", "kind": kind})
    if end > 95:
        ev(wall(95), {"t": to_sim(95), "event": "hr_lost", "silent_since": to_sim(89.5), "timeout": 5.0})
        ev(wall(95.5), {"t": to_sim(95.5), "event": "hr_resumed"})
    b.add(topics.COACH_STATE, "std_msgs/msg/String", wall(30), string_msg(json.dumps(
        {"t": to_sim(30), "policy": policy, "ladder_speed": 1.0, "ladder_tempo": 120.0})))
    if stop_at is None:
        ev(wall(180), {"t": to_sim(180), "event": "session_end", "duration": 180.0})
    elif not killed:
        ev(wall(stop_at), {"t": to_sim(stop_at), "event": "session_stopped", "reason": "SIGINT"})
    for k in range(0, 190):
        if k in DROPPED or k + 0.5 > end + 5:
            continue
        b.add(topics.POLAR_H10_HR, "std_msgs/msg/Float64MultiArray", wall(k + 0.5),
              frame_msg(np.array([1000.0 + k + 0.5]), np.array([hr_value(k)]), ("hr",)))
    if ecg:
        idx = np.array([i for i in range(0, int(60 * ECG_RATE)) if not ECG_GAP[0] <= i < ECG_GAP[1]])
        for chunk in np.array_split(idx, len(idx) // 13):
            ts = 1000.0 + chunk / ECG_RATE
            b.add(topics.POLAR_H10_ECG, "std_msgs/msg/Float64MultiArray",
                  wall(float(chunk[-1] / ECG_RATE) + 0.05), frame_msg(ts, np.sin(ts), ("ecg",)))
        for j, t in enumerate((70.0, 100.0, 130.0, 160.0)):  # processor windows, stamped in source time
            for feature, value in (("lf", 400.0 + j), ("hf", 300.0 + j), ("lfhf", math.nan)):
                b.add(f"{topics.POLAR_H10_ECG}/{feature}", "std_msgs/msg/Float64MultiArray", wall(t + 40),
                      frame_msg(np.array([1000.0 + t]), np.array([value]), (feature,)))
            status = {"t": 1000.0 + t, "event": "window", "ok": True, "flags": [], "inverted": j >= 2,
                      "nan": {"lfhf": "window 60 s shorter than the 300 s LFHF needs"},
                      "hrv_window": {"t_start": 1000.0, "t_end": 1000.0 + t, "seconds": t, "beats": 80},
                      "hrv_method": "Task Force (1996): Welch, LF 0.04-0.15 Hz and HF 0.15-0.40 Hz in ms^2"}
            b.add(f"{topics.POLAR_H10_ECG}/status", "std_msgs/msg/String", wall(t + 40),
                  string_msg(json.dumps(status)))
    return b


@pytest.fixture(scope="module")
def full(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("synthetic")
    bag = session().write(folder / "bag_full")
    return make_report(bag, out=folder / "report")


def test_in_zone_fractions_and_seconds_above_by_construction(full) -> None:
    r = full.report
    assert r["hr_rest"] == HR_REST and r["hr_max"] == HR_MAX
    assert r["zone"]["low"] == pytest.approx(LOW) and r["zone"]["high"] == pytest.approx(HIGH)
    assert r["in_zone_fraction"] == {"warm_up": 0.6, "conditioning": round(40 / 55, 4),
                                     "cool_down": round(20 / 39, 4)}
    assert r["seconds_above_hrr70"] == 15.0
    cool = next(p for p in r["phases"] if p["kind"] == "cool_down")
    assert cool["hr_samples"] == 39 and cool["invalid_samples"] == 1 and cool["seconds_below_hrr40"] == 19.0
    assert r["time_base"].startswith("/clock")
    assert r["hr_topic"] == topics.POLAR_H10_HR and r["hr_topic_from"] == "coach log (/rosout)"


def test_adaptations_behaviours_and_signal_quality(full) -> None:
    r = full.report
    per = r["adaptations"]["per_phase"]
    # An adaptation is a decision that changed the setting: a ladder step, or (here) the activity.
    assert r["adaptations"]["total"] == 4 and r["adaptations"]["rule_updates"] == 6
    assert per["conditioning"]["adaptations"] == 3 and r["adaptations"]["actions"]["change_activity"] == 1
    assert r["adaptations"]["planned_changes"] == 1
    assert per["warm_up"]["speed up"] == 1 and per["warm_up"]["no change"] == 1
    assert per["conditioning"]["slow down"] == 1 and per["conditioning"]["no update (no HR)"] == 1
    assert per["cool_down"]["no change"] == 1
    assert r["behaviours"]["by_kind"] == {"motivation": 2, "emotion": 1}
    sq = r["signal_quality"]
    assert sq["coach_hr_gaps"] == [{"start_s": 89.5, "end_s": 95.5, "seconds": 6.0}]
    assert sq["rule_updates_gated"] == {"no heart-rate data for N s": 1}
    processor = sq["processor"][f"{topics.POLAR_H10_ECG}/status"]
    assert (processor["windows"], processor["windows_flagged"], processor["windows_inverted"]) == (4, 0, 2)
    assert "Turned over" in full.files["report_html"].read_text()


def test_samples_expected_vs_received_per_stream(full) -> None:
    hr = full.report["streams"][topics.POLAR_H10_HR]
    # samples k = 0..184, 5 of them lost
    assert (hr["expected"], hr["received"], hr["missing"], hr["gaps"]) == (185, 180, 5, 1)
    assert hr["rate_hz"] == 1.0 and hr["longest_gap_s"] == 6.0
    ecg = full.report["streams"][topics.POLAR_H10_ECG]
    n = int(60 * ECG_RATE)
    assert (ecg["expected"], ecg["received"], ecg["missing"], ecg["gaps"]) == (n, n - 130, 130, 1)
    assert ecg["loss_fraction"] == pytest.approx(130 / n, abs=1e-5)


def test_hrv_summary_and_figure(full) -> None:
    hrv = full.report["hrv"]
    assert hrv[f"{topics.POLAR_H10_ECG}/lf"] == {"windows": 4, "finite": 4, "median": 401.5, "mean": 401.5,
                                                 "last": 403.0}
    lfhf = hrv[f"{topics.POLAR_H10_ECG}/lfhf"]
    assert lfhf["finite"] == 0 and "300 s" in lfhf["nan_reason"]
    assert full.files["hrv"].stat().st_size > 10_000
    # which method and window: in report.json and on the page
    assert full.report["hrv_method"]["window_seconds"] == 160.0
    assert "ms^2" in full.report["hrv_method"]["method"] and "Welch" in full.report["hrv_method"]["method"]
    page = full.files["report_html"].read_text()
    assert "LF and HF in ms²" in page and "over the last 160 s of clean beats" in page
    assert "fuzzy_probability" not in full.files  # threshold policy: no fuzzy figures


def test_a_wall_clock_session_needs_no_clock(tmp_path: Path) -> None:
    bag = session(clock=False, policy="fuzzy", ecg=False).write(tmp_path / "bag")
    result = make_report(bag, figures=False)
    assert result.report["policy"] == "fuzzy" and result.report["figures"] == {}
    assert result.report["time_base"] == "recorder receive time"
    assert result.report["in_zone_fraction"]["warm_up"] == 0.6
    assert result.out_dir == tmp_path


def test_a_killed_coachs_session_ends_at_the_last_clock_not_at_the_last_message(tmp_path: Path) -> None:
    """The coach died at 100 s: no end event; the launcher's clock stopped there while the nodes went on
    publishing for a few wall seconds as they stopped. Those seconds are not session time (before,
    they were projected at the session's speed: 3 wall seconds made 130 s of a 100-s session)."""
    b = session(stop_at=100.0, ecg=False, killed=True)
    b.add(topics.POLAR_H10_HR, "std_msgs/msg/Float64MultiArray", wall(130.0),
          frame_msg(np.array([1000.0 + 130.0]), np.array([150.0]), ("hr",)))
    r = make_report(b.write(tmp_path / "bag"), figures=False).report
    assert r["session"]["outcome"] == "incomplete"
    assert r["session"]["duration_s"] == 100.0


def test_stopped_session_reports_what_ran(tmp_path: Path) -> None:
    bag = session(stop_at=100.0, ecg=False).write(tmp_path / "bag")
    r = make_report(bag, figures=False).report
    assert r["session"]["outcome"] == "stopped" and r["session"]["stop_reason"] == "SIGINT"
    assert r["session"]["duration_s"] == 100.0
    assert r["in_zone_fraction"]["warm_up"] == 0.6
    assert r["in_zone_fraction"]["conditioning"] == 1.0  # 80..100 s: 140 bpm (5 samples lost)
    assert r["in_zone_fraction"]["cool_down"] is None
    cond = next(p for p in r["phases"] if p["kind"] == "conditioning")
    assert cond["completed"] is False and cond["end_s"] == 100.0


def test_hr_topic_option_and_missing_topic(tmp_path: Path, capsys) -> None:
    bag = session(ecg=False, rosout=False).write(tmp_path / "bag")
    r = make_report(bag, figures=False).report
    assert r["hr_topic"] == topics.POLAR_H10_HR and r["hr_topic_from"].startswith("default")
    assert main([str(bag), "--hr-topic", "/physio/other/hr", "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert "/physio/other/hr" in err  # said once, on its own line
    r = json.loads((tmp_path / "report.json").read_text())
    assert r["in_zone_fraction"] == {"warm_up": None, "conditioning": None, "cool_down": None}
    assert r["zone"]["low"] == pytest.approx(LOW)  # what the events hold is still reported


def test_bag_without_coach_events_is_refused(tmp_path: Path) -> None:
    b = BagBuilder()
    for k in range(10):
        b.add(topics.POLAR_H10_HR, "std_msgs/msg/Float64MultiArray", wall(k),
              frame_msg(np.array([float(k)]), np.array([80.0]), ("hr",)))
    bag = b.write(tmp_path / "bag")
    with pytest.raises(ReportError, match="no coach events"):
        make_report(bag)
    assert not (tmp_path / "report.json").exists()


def test_the_launchers_restarts_and_a_lost_node_are_listed_and_drawn(tmp_path: Path) -> None:
    b = session(stop_at=120.0, ecg=False)
    b.event(wall(64), {"t": SIM0 + 64, "event": "node_restarted", "node": "qt_controller", "exit_status": -9,
                       "down_s": 4.0, "restart": 1}, topic=topics.SESSION_EVENTS)
    b.event(wall(64), {"t": SIM0 + 64, "event": "receiver_gap", "node": "hr_receiver", "restart": 1,
                       "last_before": 1060.5, "first_after": 1066.5, "missing": 5},
            topic=topics.SESSION_EVENTS)
    b.event(wall(119), {"t": SIM0 + 119, "event": "node_died", "node": "qt_physio_coach", "exit_status": -9,
                        "restart": 0, "reason": "essential"}, topic=topics.SESSION_EVENTS)
    without = make_report(session(stop_at=120.0, ecg=False).write(tmp_path / "plain"), out=tmp_path / "r0")
    result = make_report(b.write(tmp_path / "bag"), out=tmp_path / "r1")
    events = result.report["session_events"]
    assert [(e["t_s"], e["event"], e["node"]) for e in events] == [
        (64.0, "node_restarted", "qt_controller"), (64.0, "receiver_gap", "hr_receiver"),
        (119.0, "node_died", "qt_physio_coach")]
    assert events[0]["down_s"] == 4.0 and events[1]["missing"] == 5 and events[2]["reason"] == "essential"
    assert "the session ended early: qt_physio_coach died (exit status -9, essential)" in result.missing
    html = (tmp_path / "r1" / "report.html").read_text()
    assert "Node restarts and losses" in html and "qt_controller" in html and "node_died" in html
    assert without.report["session_events"] == []
    assert "Node restarts" not in (tmp_path / "r0" / "report.html").read_text()


def test_the_timeline_figure_marks_a_restart_and_a_lost_node() -> None:
    from matplotlib.figure import Figure

    from hri_physio_coach.report.figures import _session_marks

    timeline = SimpleNamespace(session_events=[
        {"t": 100.0, "event": "node_restarted", "node": "qt_controller", "down_s": 5.0},
        {"t": 110.0, "event": "receiver_gap", "node": "hr_receiver"},
        {"t": 160.0, "event": "node_died", "node": "physio_recorder"}])
    ax = Figure().add_subplot()
    handles = _session_marks(ax, timeline, t0=40.0)
    assert [h.get_label() for h in handles] == ["Node restarted (1)", "Session ended: physio_recorder died"]
    assert [line.get_xdata()[0] for line in ax.get_lines()] == [1.0, 2.0]  # minutes from t0
    assert [t.get_text() for t in ax.texts] == ["qt_controller"]
    (band,) = ax.patches
    assert band.get_x() == pytest.approx(55 / 60) and band.get_width() == pytest.approx(5 / 60)

"""The session launcher's logic: the sim clock's steps and what it makes of the coach's events."""

from __future__ import annotations

import pytest

from hri_physio_coach.session_view import CLOCK_STEP, SessionView, SimClock, summary


def test_sim_clock_steps_keep_up_with_the_wall_clock_at_its_speed() -> None:
    wall = [100.0]
    clock = SimClock(start=1000.0, speed=30.0, monotonic=lambda: wall[0])
    assert clock.due_steps() == []
    wall[0] += 0.01  # 0.3 s of sim time: three steps
    steps = clock.due_steps()
    assert steps == pytest.approx([1000.0 + CLOCK_STEP * k for k in (1, 2, 3)])
    wall[0] += 0.001  # 0.03 s: not a whole step yet
    assert clock.due_steps() == []


def test_view_counts_adaptations_gated_updates_and_time_in_zone() -> None:
    view = SessionView()
    view.on_hr(85.0)  # before the session: seen, not counted
    view.on_event({"t": 10.0, "event": "session_start"})
    view.on_event({"t": 190.0, "event": "zone", "low": 125.0, "high": 155.0})
    view.state = {"phase": "warm_up", "phase_kind": "warm_up", "activity": "marching"}
    for bpm in (120.0, 130.0, 140.0, 160.0):
        view.on_hr(bpm)
    view.on_event({"t": 220.0, "event": "rule_update", "decision": {"changed": True, "action": "speed_up"}})
    for n in (4, 6):
        view.on_event({"t": 250.0, "event": "rule_update",
                       "decision": {"changed": False, "action": "gated",
                                    "reason": f"too few valid HR samples: {n} < 10"}})
    view.on_event({"t": 1390.0, "event": "session_end"})
    assert (view.hr_seen, view.hr_samples, view.exercise_hr, view.exercise_in_zone) == (5, 4, 4, 2)
    assert view.adaptations == 1 and view.gated == {"too few valid HR samples: N < N": 2}
    text = summary(view, wall=46.0, bag="bags/x")
    assert "23.0 min of session in 46 s wall (30x)" in text
    assert "50 % of 4 exercise HR samples in the zone; 1 adaptations in 3 rule updates" in text
    assert "2 rule update(s) gated: too few valid HR samples: N < N" in text
    assert "recorded to bags/x" in text
    assert "ended" in view.progress(1390.0)


def test_summary_of_a_session_stopped_before_its_end() -> None:
    view = SessionView()
    text = summary(view, wall=12.0, bag=None, now=5.0)
    assert "stopped before the session started, after 12 s wall" in text
    view.on_event({"t": 10.0, "event": "session_start"})
    text = summary(view, wall=255.0, bag=None, now=250.0)
    assert "[session] stopped before its end: 4.0 min of session in 255 s wall (1x)" in text

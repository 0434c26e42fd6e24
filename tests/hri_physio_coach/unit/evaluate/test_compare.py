"""Comparing two recordings' decisions: what the closed-loop end-to-end test will rely on."""

from __future__ import annotations

from dataclasses import replace

from hri_physio_coach.evaluate.compare import Change, changes, compare_changes
from hri_physio_coach.evaluate.simulation import SessionSpec, simulate_session
from hri_physio_coach.participant.physiology import ParticipantParams


def shifted(events: list[dict], offset: float) -> list[dict]:
    return [{**e, "t": e["t"] + offset} for e in events]


def test_changes_are_read_from_the_coach_events_relative_to_session_start() -> None:
    run = simulate_session(SessionSpec("predictive", 0, ParticipantParams(), 1, 2))
    found = changes(run.events)
    assert found and found == changes(shifted(run.events, 1.7e9))  # a sim-time epoch changes nothing
    assert [c.t for c in found] == sorted(c.t for c in found)
    assert found[-1].action == "scheduled_slow_down" and found[-1].index == 0 and found[-1].level == 3.5


def test_a_later_arrival_of_heart_rate_takes_the_same_decisions_within_a_rule_period() -> None:
    spec = SessionSpec("predictive", 0, ParticipantParams(), 1, 2)
    fast = changes(simulate_session(spec).events)
    slow = changes(simulate_session(replace(spec, hr_latency=0.8)).events)
    assert compare_changes(fast, slow) == []


def test_differences_are_named() -> None:
    a = [Change(420.0, "change_activity", 3, 5.8), Change(1080.0, "scheduled_slow_down", 0, 3.5)]
    assert compare_changes(a, a) == []
    later = [replace(a[0], t=480.0), a[1]]
    assert compare_changes(a, later, tolerance_s=30) == [
        "change 0 (change_activity): at 420 s vs 480 s (> 30 s apart)"]
    other = [replace(a[0], index=4), a[1]]
    assert "change 0: change_activity to step 3" in compare_changes(a, other)[0]
    assert compare_changes(a, a[:1])[0] == "2 control changes vs 1"

"""What the launcher concludes from the topics: the end watchdog, the numbers of summary.json (no ROS)."""

from __future__ import annotations

from hri_physio_bringup.view import (
    SessionView,
    every_listener_matched,
    overdue,
    receiver_text,
    session_counts,
    summary,
)


def started(duration: float | None = 270.0) -> SessionView:
    view = SessionView()
    event = {"t": 1000.0, "event": "session_start"}
    if duration is not None:
        event["duration"] = duration
    view.on_event(event)
    return view


def test_a_session_past_its_routine_is_overdue_after_the_margin() -> None:
    assert not overdue(SessionView(), 5000.0, 270.0, 60.0)  # not started
    view = started()
    assert not overdue(view, 1000.0 + 270.0 + 59.0, 999.0, 60.0)  # the routine's duration, from the coach
    assert overdue(view, 1000.0 + 270.0 + 61.0, 999.0, 60.0)
    view.on_event({"t": 1270.0, "event": "session_end"})
    assert not overdue(view, 9999.0, 270.0, 60.0)  # ended: never overdue
    assert overdue(started(None), 1000.0 + 100.0 + 61.0, 100.0, 60.0)  # no duration in the event: the plan's


def test_counts_say_how_the_session_ended() -> None:
    assert session_counts(SessionView())["outcome"] == "not started"
    view = started()
    assert session_counts(view)["outcome"] == "stopped"
    view.on_event({"t": 1100.0, "event": "session_stopped", "reason": "signal"})
    assert session_counts(view)["stop_reason"] == "signal"
    view.on_event({"t": 1100.0, "event": "conflict", "conflict": "second_clock", "reason": "two clocks"})
    counts = session_counts(view)
    assert (counts["outcome"], counts["stop_reason"]) == ("conflict", "two clocks")
    assert "another session shared its topics (two clocks)" in summary(view, 10.0, None, now=1100.0)
    view = started()
    view.on_event({"t": 1270.0, "event": "session_end"})
    view.robot_actions = 87
    view.receivers["hr_receiver"] = {"received_samples": 271, "published_samples": 271, "gaps": 0}
    counts = session_counts(view)
    assert counts["outcome"] == "finished" and counts["robot_actions"] == 87
    assert counts["receivers"]["hr_receiver"]["published_samples"] == 271


def test_receiver_lines_say_what_was_lost() -> None:
    assert receiver_text({"received_samples": 5, "published_samples": 5, "gaps": 0}) == \
        "5 samples received, 5 published, nothing lost"
    lossy = {"received_samples": 5, "published_samples": 4, "gaps": 1, "missing_samples": 3}
    assert receiver_text(lossy) == "5 samples received, 4 published (1 gaps, 3 missing samples)"
    view = started()
    view.receivers["hr_receiver"] = {"received_samples": 5, "published_samples": 5}
    assert "[session] hr_receiver: 5 samples received, 5 published, nothing lost" in summary(view, 1.0, None)
    # Restarted: the status is its last process's, and the samples lost meanwhile are elsewhere.
    line = next(x for x in summary(view, 1.0, None, restarts={"hr_receiver": 1}).splitlines()
                if x.startswith("[session] hr_receiver:"))
    assert line == ("[session] hr_receiver: 5 samples received, 5 published, nothing lost (counted since its "
                    "restart 1; what its source sent while it was down: the restarts line)")


def test_the_session_starts_once_the_coachs_commands_reach_every_listener() -> None:
    assert every_listener_matched(3, 3) and every_listener_matched(4, 3)  # a viewer the graph lists later
    assert not every_listener_matched(2, 3)  # the controller's subscription not matched yet: lost commands
    assert not every_listener_matched(None, 3)  # no state from the coach yet
    assert not every_listener_matched(0, 0)  # nobody listens yet

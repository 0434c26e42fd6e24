"""The coach node's control without ROS: control lines, the start on a whole second, heart-rate frames."""

from __future__ import annotations

import numpy as np
import pytest

from hri_physio_bridge.frames import Frame
from hri_physio_coach.coach import ExerciseCoach
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.control import Control, HrSample, SessionControl, hr_samples


def make(interactive: bool = True) -> tuple[SessionControl, list[dict]]:
    events: list[dict] = []
    clock = [0.0]
    coach = ExerciseCoach(CoachConfig(), lambda: clock[0], lambda _line: None, events.append)
    return SessionControl(coach, interactive), events


def test_hr_frames_take_the_named_column_and_the_optional_flag() -> None:
    one = Frame(np.array([12.5]), np.array([[131.0]]), ("hr",))
    assert hr_samples(one) == [HrSample(12.5, 131.0, False)]
    flagged = Frame(np.array([1.0, 2.0]), np.array([[0.0, 120.0], [1.0, 80.0]]), ("flag", "bpm"))
    assert hr_samples(flagged) == [HrSample(1.0, 120.0, False), HrSample(2.0, 80.0, True)]
    # Preference among names, any case; else the first channel.
    named = Frame(np.array([3.0]), np.array([[1.0, 70.0, 71.0]]), ("x", "Heart_Rate", "BPM"))
    assert hr_samples(named) == [HrSample(3.0, 71.0, False)]
    unnamed = Frame(np.array([4.0]), np.array([[66.0, 1.0]]), ("a", "b"))
    assert hr_samples(unnamed) == [HrSample(4.0, 66.0, False)]
    assert hr_samples(Frame(np.empty(0), np.empty((0, 1)), ("hr",))) == []


@pytest.mark.parametrize("line,control", [("start", Control.START), (" START\n", Control.START),
                                          ("stop", Control.STOP), ("exit", Control.STOP),
                                          ("go", Control.UNKNOWN), ("", Control.UNKNOWN)])
def test_control_lines_are_classified_and_counted(line: str, control: Control) -> None:
    ctl, _ = make()
    assert ctl.request(line) is control
    assert ctl.counts == {"received": 1, "unknown": int(control is Control.UNKNOWN)}
    assert ctl.finished is (control is Control.STOP)


def test_an_interactive_session_starts_on_the_whole_second_after_start() -> None:
    ctl, events = make()
    ctl.tick(5.2)
    assert not ctl.coach.started  # no start asked for
    ctl.request("start")
    ctl.tick(10.3)
    assert ctl.start_at == 11.0 and not ctl.coach.started
    ctl.tick(10.9)
    assert not ctl.coach.started
    ctl.tick(11.05)
    assert ctl.coach.started and events[0]["event"] == "session_start" and events[0]["t"] == 11.0


def test_nothing_starts_while_the_clock_reads_zero_and_a_non_interactive_session_starts_by_itself() -> None:
    ctl, _ = make(interactive=False)
    ctl.tick(0.0)
    assert ctl.start_at is None and not ctl.coach.started  # sim time before the first /clock
    ctl.tick(2.0)
    assert ctl.coach.started and ctl.start_at == 2.0  # already a whole second


def test_stop_before_the_start_ends_the_node_and_keeps_the_first_reason() -> None:
    ctl, _ = make()
    ctl.request("exit")
    ctl.stop("signal")
    assert ctl.finished and ctl.stop_reason == "exit requested"
    ctl.request("start")
    ctl.tick(3.0)
    assert not ctl.coach.started  # a finished control starts nothing
    assert ctl.end() == "idle"


def test_a_running_session_is_stopped_at_the_end_with_its_reason() -> None:
    ctl, events = make(interactive=False)
    ctl.tick(1.0)
    ctl.stop_reason = "signal"
    assert ctl.end() == "stopped"
    assert events[-1]["event"] == "session_stopped" and "signal" in str(events[-1])

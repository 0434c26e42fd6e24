"""When the simulated person takes up an instruction: on the next mark of ``reaction_period``.

The same change at the same model step whether the instruction arrived at once or a few seconds
late, so the closed loop (ROS, LSL, a loaded machine) and the evaluation run the same physiology.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hri_physio_bridge.config import ConfigError
from hri_physio_coach.coach import session_start_time
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.evaluate.simulation import SessionSpec, simulate_session
from hri_physio_coach.participant.cardiac import ParticipantSimulator
from hri_physio_coach.participant.physiology import TAKE_IN_TIME, Activity, ParticipantParams, takes_effect
from hri_physio_coach.participant.stream import StrapStream, strap_start
from hri_physio_coach.participant_config import ParticipantNodeConfig

STEP = Activity("step_up", tempo_bpm=125.0, gesture_speed=1.05)
EPOCH = 1795627085.0  # a sim clock's session start (ROS time, s): rounding of ~1e-7 s


@pytest.mark.parametrize("start", [0.0, EPOCH])
def test_an_instruction_is_taken_up_on_the_next_mark_from_the_session_start(start: float) -> None:
    # Sent at 420 s, heard up to TAKE_IN_TIME early (a listener's clock behind) or 3.5 s late: at 425 s.
    for late in (-TAKE_IN_TIME + 1e-3, -0.2, 0.0, 1e-7, 0.3, 2.5, 3.499):
        assert takes_effect(start + 420.0 + late, start, 5.0) == pytest.approx(start + 425.0, abs=1e-6)
    assert takes_effect(start + 423.5, start, 5.0) == pytest.approx(start + 430.0, abs=1e-6)
    assert takes_effect(start + 3.0, start, 10.0) == pytest.approx(start + 10.0, abs=1e-6)
    assert takes_effect(start + 9.0, start, 10.0) == pytest.approx(start + 20.0, abs=1e-6)


def test_at_once_before_the_session_start_is_known_or_with_no_period() -> None:
    assert takes_effect(421.0, None, 5.0) is None
    assert takes_effect(421.0, 0.0, 0.0) is None


def test_a_change_waits_for_its_step_and_is_listed_until_then() -> None:
    sim = ParticipantSimulator(ParticipantParams(), seed=3, ecg=False)
    sim.advance_hr(421.0)
    sim.set_activity(STEP, at=425.0)
    assert sim.pending == [(425.0, STEP)] and sim.activity.name == "rest"
    sim.advance_hr(424.95)
    assert sim.activity.name == "rest"
    sim.advance_hr(425.1)
    assert sim.activity == STEP and sim.pending == []


def test_two_changes_for_one_mark_apply_in_the_order_heard() -> None:
    sim = ParticipantSimulator(ParticipantParams(), seed=3, ecg=False)
    faster = STEP.with_(tempo_bpm=130.0)
    sim.set_activity(STEP, at=5.0)
    sim.set_activity(faster, at=5.0)
    sim.advance_hr(6.0)
    assert sim.activity == faster


def test_a_change_for_now_replaces_the_ones_still_waiting() -> None:
    sim = ParticipantSimulator(ParticipantParams(), seed=3, ecg=False)
    sim.set_activity(STEP, at=5.0)
    sim.set_activity(Activity("marching"))
    sim.advance_hr(6.0)
    assert sim.activity.name == "marching" and sim.pending == []


def test_the_heart_is_the_same_however_late_the_instruction_came_within_the_period() -> None:
    runs = []
    for heard in (420.0, 420.4, 423.4):
        sim = ParticipantSimulator(ParticipantParams(), seed=3, ecg=False)
        reports = sim.advance_hr(heard)
        sim.set_activity(STEP, at=takes_effect(heard, 0.0, 5.0))
        reports += sim.advance_hr(600.0)
        runs.append(np.array(reports))
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])
    # ... and a change taken up at once would have changed it.
    sim = ParticipantSimulator(ParticipantParams(), seed=3, ecg=False)
    reports = sim.advance_hr(420.4)
    sim.set_activity(STEP)
    reports += sim.advance_hr(600.0)
    assert not np.array_equal(runs[0], np.array(reports))


def test_an_instruction_heard_before_the_hand_over_is_taken_up_by_the_session_model() -> None:
    stream = StrapStream(ParticipantParams(), seed=2, t0=100.5)
    stream.advance(110.0)
    stream.start_session(110.0)
    stream.set_activity(STEP, at=120.0)  # heard at 110 s, taken up at the mark after the hand-over
    stream.advance(119.0)
    assert stream.in_session and stream.session_t0 is not None and stream.session_t0 < 119.0
    assert stream.sim.pending == [(120.0, STEP)]
    stream.advance(121.0)
    assert stream.sim.activity == STEP


@pytest.mark.parametrize(("now", "start"), [(10.0, 10.5), (10.2, 10.5), (10.5, 10.5), (10.7, 11.5)])
def test_a_strap_starts_its_timeline_on_the_next_half_second(now: float, start: float) -> None:
    assert strap_start(now) == start
    assert strap_start(EPOCH + now) == EPOCH + start


@pytest.mark.parametrize(("now", "start"), [(10.0, 10.0), (10.0000001, 10.0), (10.2, 11.0), (10.99, 11.0)])
def test_a_session_starts_on_the_next_whole_second(now: float, start: float) -> None:
    assert session_start_time(now) == start


def test_commands_seconds_late_change_nothing_in_the_evaluation() -> None:
    """The discrete-event session with prompt commands and with commands (and music, 3 s) late: marks
    are 5 s apart and the person takes 1.5 s to take an instruction in, so up to 3.5 s change nothing."""
    spec = SessionSpec("predictive", 0, ParticipantParams(age=33.0), participant_seed=1, coach_seed=0)
    coach = CoachConfig.from_mapping({"policy": "predictive"}, "test")
    prompt = simulate_session(spec, coach)
    late = simulate_session(replace(spec, command_latency=2.0, tempo_latency=1.0), coach)
    assert np.array_equal(prompt.hr, late.hr)
    assert prompt.decisions == late.decisions
    # Taken up at once (no period), the same latency does change the session.
    at_once = replace(spec, params=replace(spec.params, reaction_period=0.0))
    assert not np.array_equal(simulate_session(at_once, coach).hr,
                              simulate_session(replace(at_once, command_latency=2.0), coach).hr)


def test_a_negative_reaction_period_is_refused() -> None:
    with pytest.raises(ValueError, match="reaction_period"):
        ParticipantParams(reaction_period=-1.0).validate()
    with pytest.raises(ConfigError, match="reaction_period"):
        ParticipantNodeConfig.from_mapping({"reaction_period": -1.0}, "test")

"""The evaluation's transport (stalls, late commands, a later model start) and what a rule update does."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hri_physio_coach.config import CoachConfig
from hri_physio_coach.evaluate.simulation import SessionRun, SessionSpec, simulate_session
from hri_physio_coach.participant.physiology import ParticipantParams

SPEC = SessionSpec("predictive", 0, ParticipantParams(age=33.0), participant_seed=1, coach_seed=0)
#: Rule updates at 420 s (inside the warm-up's step-ups) and 360 s (where the step-ups start).
INSIDE, AT_BOUNDARY = 420.0, 360.0


def rule(run: SessionRun, t: float) -> dict:
    (event,) = [e for e in run.events if e["event"] == "rule_update" and e["t"] == t]
    return event


def coach(**options: object) -> CoachConfig:
    return CoachConfig.from_mapping({"policy": "predictive", **options}, "test")


@pytest.fixture(scope="module")
def prompt() -> SessionRun:
    return simulate_session(SPEC, coach())


def stalled_before(t: float) -> tuple[tuple[float, float], ...]:
    """The last 2.5 s of heart rate before ``t`` (and the first 0.5 s after) arrive together after it."""
    return ((t - 2.5, t + 0.5),)


def test_a_rule_update_waits_for_the_heart_rate_of_its_window(prompt: SessionRun) -> None:
    run = simulate_session(replace(SPEC, hr_stalls=stalled_before(INSIDE)), coach())
    waited, ref = rule(run, INSIDE), rule(prompt, INSIDE)
    assert waited["inputs"]["waited"] == pytest.approx(0.6)  # until the stalled samples came
    assert waited["inputs"]["n_valid"] == ref["inputs"]["n_valid"] == 30
    assert waited["inputs"]["hr_mean"] == ref["inputs"]["hr_mean"]
    assert waited["decision"]["action"] == ref["decision"]["action"]
    assert rule(prompt, INSIDE)["inputs"]["waited"] == 0.0


def test_without_waiting_the_stalled_samples_miss_their_window(prompt: SessionRun) -> None:
    run = simulate_session(replace(SPEC, hr_stalls=stalled_before(INSIDE)), coach(hr_wait=0.0))
    late, ref = rule(run, INSIDE), rule(prompt, INSIDE)
    assert late["inputs"]["waited"] == 0.0
    assert late["inputs"]["n_valid"] < ref["inputs"]["n_valid"]
    assert late["inputs"]["hr_mean"] != pytest.approx(ref["inputs"]["hr_mean"], abs=0.05)


def test_at_an_activity_end_the_routine_waits_for_the_heart_rate_and_decides_before_the_transition(
        prompt: SessionRun) -> None:
    """A rule update at an activity's end must be decided before the transition due then: the routine is
    held there (nothing at or after it runs) until the stalled samples come, and the decision and the
    next activity carry the times they carry when the heart rate is on time."""
    run = simulate_session(replace(SPEC, hr_stalls=stalled_before(AT_BOUNDARY)), coach())
    at_end, ref = rule(run, AT_BOUNDARY), rule(prompt, AT_BOUNDARY)
    assert at_end["inputs"]["waited"] == pytest.approx(0.6)  # until the stalled samples came
    assert at_end["inputs"]["activity"] == ref["inputs"]["activity"] == "basic_marching"
    assert at_end["inputs"]["n_valid"] == ref["inputs"]["n_valid"] == 30
    assert at_end["inputs"]["hr_mean"] == ref["inputs"]["hr_mean"]
    assert at_end["decision"] == ref["decision"]

    def next_activity(r: SessionRun) -> dict:
        return next(e for e in r.events if e["event"] == "activity" and e["t"] >= AT_BOUNDARY)

    assert next_activity(run) == next_activity(prompt)
    def then(r: SessionRun) -> list[str]:
        return [e["event"] for e in r.events if e["t"] == AT_BOUNDARY]

    assert then(run).index("rule_update") < then(run).index("activity")
    assert then(prompt).index("rule_update") < then(prompt).index("activity")


def test_a_routine_held_at_an_activity_end_goes_on_after_hr_wait_without_the_heart_rate(
        prompt: SessionRun) -> None:
    stall = ((AT_BOUNDARY - 2.5, AT_BOUNDARY + 10.0),)  # longer than the wait
    run = simulate_session(replace(SPEC, hr_stalls=stall), coach(hr_wait=2.0))
    at_end = rule(run, AT_BOUNDARY)
    assert at_end["inputs"]["waited"] == pytest.approx(2.0)
    assert at_end["inputs"]["n_valid"] < 30
    assert at_end["inputs"]["activity"] == "basic_marching"
    following = next(e for e in run.events if e["event"] == "activity" and e["t"] >= AT_BOUNDARY)
    assert following["t"] == AT_BOUNDARY


def test_a_wait_is_bounded_by_hr_wait(prompt: SessionRun) -> None:
    stall = ((INSIDE - 2.5, INSIDE + 10.0),)  # longer than the wait
    run = simulate_session(replace(SPEC, hr_stalls=stall), coach(hr_wait=2.0))
    assert rule(run, INSIDE)["inputs"]["waited"] == pytest.approx(2.0)
    assert rule(run, INSIDE)["inputs"]["n_valid"] < 30


def test_commands_reach_the_participant_late_and_music_later_still() -> None:
    """The warm-up starts at 180 s: marching to the music's tempo (a person who reacts at once)."""
    at_once = replace(SPEC, params=replace(SPEC.params, reaction_period=0.0))
    prompt = simulate_session(at_once, coach())
    run = simulate_session(replace(at_once, command_latency=2.0, tempo_latency=1.5), coach())

    def doing(r: SessionRun, t: float) -> str:
        return r.activity[list(r.t).index(t)]

    assert doing(prompt, 181.0) == "marching"
    # Sent at 180 s, seen at 182 s: the sample of 181 s (which arrives at 181.1 s) was still taken at rest.
    assert doing(run, 181.0) == "base" and doing(run, 182.0) == "marching"
    assert run.model_hr[list(run.t).index(200.0)] < prompt.model_hr[list(prompt.t).index(200.0)]


def test_a_person_takes_an_instruction_up_on_the_next_mark(prompt: SessionRun) -> None:
    """Marching is asked for at 180 s and taken up at 185 s (``reaction_period`` 5 s), late or not."""
    run = simulate_session(replace(SPEC, command_latency=2.0), coach())
    for r in (prompt, run):
        assert r.activity[list(r.t).index(184.0)] == "base"
        assert r.activity[list(r.t).index(186.0)] == "marching"
    assert np.array_equal(prompt.model_hr, run.model_hr)


def test_the_model_can_start_after_the_session(prompt: SessionRun) -> None:
    run = simulate_session(replace(SPEC, model_start=0.7), coach())
    assert run.t[0] == pytest.approx(1.7) and run.t[1] == pytest.approx(2.7)
    assert run.hr[:60] == pytest.approx(prompt.hr[:60], abs=1e-9)  # the same person at rest, 0.7 s later


def test_a_long_stall_in_the_calibration_changes_nothing(prompt: SessionRun) -> None:
    """12 s of heart rate arrive together (long enough to report the signal lost): HR_rest is the same."""
    run = simulate_session(replace(SPEC, hr_stalls=((8.0, 20.0),)), coach())
    assert run.of("hr_lost") and run.of("hr_resumed")
    (calib,), (ref,) = run.of("calibration"), prompt.of("calibration")
    assert (calib["n_samples"], calib["hr_rest"]) == (ref["n_samples"], ref["hr_rest"])
    assert run.decisions == prompt.decisions

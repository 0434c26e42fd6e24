"""Which activity runs in a routine's slot when a policy holds an activity cost (no clock, no coach)."""

from __future__ import annotations

import pytest

from hri_physio_coach.activity_choice import ActivityChoice
from hri_physio_coach.routine import RoutineError, parse_routine

ROUTINE = {
    "name": "r",
    "phases": [
        {"name": "warm", "activities": [
            {"name": "march", "duration": 60, "gesture": "marching", "mets": 3.5},
            {"name": "step", "duration": 60, "gesture": "step_up", "mets": 5.8},
        ]},
        {"name": "cond", "activities": [
            {"name": "march", "duration": 60, "gesture": "marching", "mets": 3.5},
            {"name": "knees", "duration": 60, "gesture": "lateral", "mets": 5.8},
            {"name": "arms", "duration": 60, "gesture": "arms_forward", "mets": 6.3},
            {"name": "rest", "duration": 60},
        ]},
    ],
}


@pytest.fixture
def routine():
    return parse_routine(ROUTINE)


def test_choices_and_levels_come_from_the_stated_costs(routine) -> None:
    assert [a.name for a in routine.choices("cond")] == ["march", "knees", "arms", "step"]  # phase first
    assert ActivityChoice(routine).levels(routine.phase("cond")) == (3.5, 5.8, 6.3)
    assert ActivityChoice(routine).levels(None) == ()


def test_slots_run_their_own_activity_unless_the_policy_holds_another_cost(routine) -> None:
    choice = ActivityChoice(routine)
    warm, cond = routine.phase("warm"), routine.phase("cond")
    march, step = warm.activities
    assert choice.slot_started(warm, march, None) is None  # routine's own
    assert choice.current is march
    assert choice.slot_started(warm, step, 5.8) is None  # same cost: its own
    c_march, knees, arms, rest = cond.activities
    # Holding stepping: the person keeps doing what they do (the warm-up's step-up) in a marching slot ...
    assert choice.slot_started(cond, c_march, 5.8) is step
    assert choice.slot_started(cond, knees, 5.8) is None  # ... and the slot's own when it has that cost
    assert choice.slot_started(cond, arms, 5.8) is knees
    assert choice.current is knees and choice.running is knees
    assert choice.slot_started(cond, rest, 5.8) is None  # a slot without a cost is never replaced


def test_a_switch_mid_slot_and_back(routine) -> None:
    choice = ActivityChoice(routine)
    cond = routine.phase("cond")
    c_march, knees, _, _ = cond.activities
    assert choice.slot_started(cond, c_march, None) is None
    assert choice.switch(cond, c_march, 5.8) is knees  # the phase's activity with that cost
    assert choice.running is knees
    assert choice.switch(cond, c_march, 5.8) is None  # already doing it
    assert choice.switch(cond, c_march, 3.5) is c_march  # back to the slot's own
    assert choice.running is None and choice.current is c_march
    assert choice.switch(cond, c_march, 9.9) is None  # no activity has that cost: stay


def test_a_cost_must_be_a_number_of_mets(routine) -> None:
    activity = {"name": "a", "duration": 5, "mets": "hard"}
    bad = {"name": "r", "phases": [{"name": "p", "activities": [activity]}]}
    with pytest.raises(RoutineError, match="mets must be a number"):
        parse_routine(bad)
    activity["mets"] = 0.5
    with pytest.raises(RoutineError, match="mets must be a number >= 1"):
        parse_routine(bad)


def test_what_may_run_at_each_cost_is_the_phases_own_and_what_is_performed_now(routine) -> None:
    choice = ActivityChoice(routine)
    warm, cond = routine.phase("warm"), routine.phase("cond")
    assert choice.runs_at(None) == ()
    assert choice.runs_at(warm) == (("march", 3.5), ("step", 5.8), ("arms", 6.3))  # arms: another phase's
    choice.slot_started(warm, warm.activities[1], None)  # stepping at the end of the warm-up ...
    # ... is kept in a conditioning slot of another cost while the policy holds 5.8: both may run at it.
    assert choice.runs_at(cond) == (("march", 3.5), ("knees", 5.8), ("step", 5.8), ("arms", 6.3))
    only_warm = parse_routine({"name": "r", "phases": [
        ROUTINE["phases"][0],
        {"name": "steps", "activities": [{"name": "knees", "duration": 60, "gesture": "lateral",
                                          "mets": 5.8}]}]})
    # A cost the phase has no activity for runs the routine's first with it (here the warm-up's march).
    assert ActivityChoice(only_warm).runs_at(only_warm.phase("steps")) == (("march", 3.5), ("knees", 5.8))

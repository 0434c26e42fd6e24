"""One discrete-event session: the nodes' coach and participant model, joined directly."""

from __future__ import annotations

import numpy as np
import pytest

from hri_physio_coach.config import CoachConfig
from hri_physio_coach.evaluate.simulation import SessionSpec, simulate_session
from hri_physio_coach.participant.cardiac import ParticipantSimulator
from hri_physio_coach.participant.physiology import Activity, ParticipantParams

TYPICAL = ParticipantParams()  # age 33, the demo's participant
VERY_FIT = ParticipantParams(vo2max=62.0, step_height=0.10, hr_rest=60.0, hr_max_true=190.0)


def commands_at(run, t: float) -> list[str]:
    return [e["command"] for e in run.of("command") if abs(e["t"] - t) < 1e-6]


def test_the_strap_heart_rate_is_the_same_model_run_as_the_node_streams() -> None:
    """advance() (the node: ECG, RR and HR arrays) and advance_hr() (here) step the same model."""
    plan = {0: Activity("rest"), 60: Activity("marching", 115, 0.95), 150: Activity("step_up", 130, 1.1)}
    node = ParticipantSimulator(TYPICAL, seed=7)
    here = ParticipantSimulator(TYPICAL, seed=7, ecg=False)
    streamed, reports = [], []
    for second in range(1, 301):
        if second - 1 in plan:
            node.set_activity(plan[second - 1])
        out = node.advance(float(second))
        streamed += list(zip(out.hr_t, out.hr_bpm, strict=True))
    cuts = sorted({*plan, *range(7, 300, 7), 300})  # other cuts of time, changes at the same model times
    for when in cuts:
        reports += [(t, bpm) for t, bpm, _ in here.advance_hr(float(when))]
        if when in plan:
            here.set_activity(plan[when])
    assert len(streamed) == 300
    np.testing.assert_array_equal(np.array(streamed), np.array(reports))


def test_sessions_are_seeded_and_policies_see_the_same_person() -> None:
    spec = SessionSpec("fuzzy", 0, TYPICAL, participant_seed=11, coach_seed=12)
    a, b = simulate_session(spec), simulate_session(spec)
    np.testing.assert_array_equal(a.hr, b.hr)
    assert a.decisions == b.decisions
    other = simulate_session(SessionSpec("threshold", 0, TYPICAL, 11, 12))
    calibration = a.t < 180
    np.testing.assert_array_equal(a.hr[calibration], other.hr[calibration])  # same heart, same noise
    reseeded = simulate_session(SessionSpec("fuzzy", 0, TYPICAL, 99, 12))
    assert not np.array_equal(a.hr[calibration], reseeded.hr[calibration])
    assert len(a.t) >= 1379 and np.all(np.diff(a.t) == 1.0)  # 1 Hz through the 23 min


def test_the_predictive_coach_runs_the_chosen_activity_and_says_so() -> None:
    run = simulate_session(SessionSpec("predictive", 0, TYPICAL, 1, 2))
    choices = run.of("activity_choice")
    assert choices
    slot_starts = {e["t"] for e in run.of("activity")}
    gestures = {"step_up_reach_pull": "step_up", "lateral_knees": "lateral",
                "both_arms_forward": "arms_forward", "marching": "marching", "basic_marching": "marching"}
    for e in choices:
        sent = commands_at(run, e["t"])
        assert any(c.startswith(f"set gesture {gestures[e['activity']]} ") for c in sent), (e, sent)
        assert any("switch to" in c for c in sent if c.startswith("set speech"))
        if e["t"] in slot_starts:  # in place of the slot's own: not its own gesture, not its own line
            assert not any(c.startswith(f"set gesture {gestures[e['slot']]} ") for c in sent
                           if gestures[e["slot"]] != gestures[e["activity"]])
    conditioning = (run.t >= 480) & (run.t < 1080)
    held = {e["level"] for e in choices if 480 <= e["t"] < 1080}
    if held and min(held) > 3.5:  # holding a stepping cost: nobody marches in the conditioning
        assert "marching" not in {a for a, c in zip(run.activity, conditioning, strict=True) if c}
    said = [c for c in (e["command"] for e in run.of("command")) if "Back to marching" in c]
    assert len(said) < 4  # the routine's marching lines are not said where another activity runs
    # Each rule update names the routine's slot (activity) and what the person does (performed).
    performed, seen = None, []
    for e in run.events:
        if e.get("event") in ("activity", "activity_choice"):  # a slot starts; another is run in it
            performed = e["activity"]
        elif e.get("event") == "rule_update" and e["inputs"]["phase_kind"] in ("warm_up", "conditioning"):
            assert e["inputs"]["performed"] == performed, (e["t"], e["inputs"])
            seen.append(e["inputs"]["performed"] != e["inputs"]["activity"])
    assert any(seen)  # some rule updates came while another activity ran in the slot


def test_out_of_reach_is_said_once_and_the_hardest_setting_kept() -> None:
    run = simulate_session(SessionSpec("predictive", 0, VERY_FIT, 1, 2))
    notices = run.of("zone_out_of_reach")
    assert len(notices) == 1 and notices[0]["direction"] == "below"
    line = CoachConfig().speech_out_of_reach_below
    assert sum(1 for e in run.of("command") if e["command"] == f"set speech {line}") == 1
    after = (run.t > notices[0]["t"]) & (run.t < 1080)
    assert set(run.ladder[after]) == {5}  # the fastest step, held: no cycling
    assert set(run.mets[after]) == {6.3}  # the hardest activity


@pytest.mark.parametrize("policy", ["threshold", "fuzzy", "static"])
def test_the_thesis_policies_run_the_routine_as_written(policy: str) -> None:
    run = simulate_session(SessionSpec(policy, 0, TYPICAL, 1, 2))
    assert not run.of("activity_choice") and not run.of("plan") and not run.of("zone_out_of_reach")
    # The conditioning's first slot, 480-540 s: marching, taken up on the person's next mark (485 s).
    marching = (run.t >= 486) & (run.t < 545)
    assert {a for a, m in zip(run.activity, marching, strict=True) if m} == {"marching"}
    assert run.of("session_end")
    assert all(e["inputs"]["performed"] == e["inputs"]["activity"] for e in run.of("rule_update"))

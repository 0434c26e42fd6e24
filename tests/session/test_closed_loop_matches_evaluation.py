"""The closed loop takes the decisions the discrete-event evaluation takes for the same person and seeds.

``hri_physio_session --policy predictive`` runs simulated participant -> LSL -> physio_receiver ->
qt_physio_coach -> qt_controller -> mock_qt_robot under sim time; its coach events are read back
from the session's bag. The evaluation (:func:`~hri_physio_coach.evaluate.simulation.simulate_session`)
is given what ran, read from the session folder's ``configs/``: the participant's model parameters
and seed, and the coach's options and seed. The participant is the demo's (``hri_physio_session``'s
defaults: age 33, participant seed 1). The two must make the same control changes (action, ladder
step, activity cost, in order) at the same rule update (``TOLERANCE_S``,
:func:`~hri_physio_coach.evaluate.compare.compare_changes`).

Why they can match: the closed loop's participant rests on a separate random stream during the
session's start-up and starts its seeded model when it hears the coach's ``session_start``
(docs/PARTICIPANT_MODEL.md, "Before the session"), as the evaluation starts it. The coach's rule
updates take the heart rate *taken* in their window (each sample's stamp mapped onto the coach's
clock, a late window waited for, ``hr_wait``), so heart-rate transport delay no longer moves them.

Why it stays opt-in (measured 2026-11-24, idle machine, 20x): calibration and the whole marching
warm-up matched (the strap's heart rate sample for sample during the calibration, the 30-s means of
the rule updates at 210-360 s within 0.01 bpm of an evaluation whose commands reach the participant
0.3 s late). After the step-ups begin (360 s) the model's heart rate still agreed within 0.06 bpm,
but the 30-s means differed by 0.23 and 0.83 bpm at 390 and 420 s: the participant applies a command
at its next 0.1-s tick after it arrives, and a change that lands in another 0.1-s model step moves
the beats by milliseconds (evaluations with commands 0.30 and 0.35 s late agree exactly, 0.5 s late
differ by up to 0.14 bpm in the warm-up's means; the per-beat noise draws then likely fall on other
beats). The
predictive plan at 420 s chooses between ladder steps whose predicted heart rates lie about 2 bpm
apart, so a few tenths of a bpm decide it: that run planned step 3 where the evaluation planned
step 4. In the evaluation itself (``SessionSpec.command_latency``, ``hr_latency``, ``model_start``),
none of 20 seeds at age 33 kept its decisions under every transport variant up to 3 s, and 6 of 10
kept them under variants up to 0.3 s. So an exact match needs the participant to react on a fixed
grid of the session clock (the same in the node and the evaluation) rather than at its next tick;
that is not built yet.

* ``SPEED`` = 20x, not 60x: at 60x the participant's 0.1-s ticks (600 a second) do not keep up on a
  loaded 2-core machine, commands reached it 3-12 s of sim time late and the 30-s means were
  1.0 bpm lower on average (up to 2.9 bpm), which flipped that plan.
* ``TOLERANCE_S`` = 1 s: rule updates fall every 30 s from the session start in both, so the same
  decision has the same time; a decision one rule update apart is a difference.

The test can fail: the same recording is checked against the evaluation of another policy
(threshold) and of another person (age 50), which take other decisions.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hri_physio_bridge import topics
from hri_physio_coach.config import COACH_NODE, CoachConfig, CoachNodeConfig
from hri_physio_coach.evaluate.compare import Change, changes, compare_changes
from hri_physio_coach.evaluate.simulation import SessionSpec, simulate_session
from hri_physio_coach.participant_config import PARTICIPANT_NODE, ParticipantNodeConfig
from hri_physio_coach.report.bagdata import read_bag

pytestmark = [
    pytest.mark.integration, pytest.mark.ros, pytest.mark.lsl,
    # Opt-in: the plan at 420 s turns on a few tenths of a bpm, which the participant's command timing
    # moves (see the module docstring).
    pytest.mark.skipif(os.environ.get("HRI_PHYSIO_E2E_EVALUATION") != "1",
                       reason="set HRI_PHYSIO_E2E_EVALUATION=1: a knife-edge decision (module docstring)"),
]

POLICY = "predictive"
AGE = 33.0
PARTICIPANT_SEED = 1
SPEED = 20.0  # see the module docstring
#: The same rule update: see the module docstring.
TOLERANCE_S = 1.0


def evaluation_spec(folder: Path, policy: str = POLICY,
                    age: float | None = None) -> tuple[SessionSpec, CoachConfig]:
    """The discrete-event session of what the closed loop ran (its configs/); or another policy or age."""
    configs = folder / "configs"
    part = ParticipantNodeConfig.from_file(configs / f"{PARTICIPANT_NODE}.yaml", PARTICIPANT_NODE)
    node = CoachNodeConfig.from_file(configs / f"{COACH_NODE}.yaml", COACH_NODE)
    shared = {k: v for k, v in node.as_dict().items() if k in CoachConfig.model_fields}
    coach = CoachConfig.from_mapping(shared, "the session's coach")
    params = part.params
    if age is not None:
        params = ParticipantNodeConfig.from_mapping({**part.as_dict(), "age": age}, "another person").params
    spec = SessionSpec(policy, 0, params, participant_seed=part.seed, coach_seed=coach.seed)
    return spec, coach


def evaluated_changes(folder: Path, policy: str = POLICY, age: float | None = None) -> list[Change]:
    spec, coach = evaluation_spec(folder, policy, age)
    return changes(simulate_session(spec, coach).events)


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory, session_tag: str) -> Path:
    out = tmp_path_factory.mktemp("closed_loop")
    command = [str(Path(sys.prefix) / "bin" / "hri_physio_session"), "--policy", POLICY,
               "--speed", f"{SPEED:g}", "--no-ecg", "--no-report", "--age", f"{AGE:g}",
               "--participant-seed", str(PARTICIPANT_SEED),
               "--device-id", f"SIM{session_tag}e2e", "--out", str(out)]
    run = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                         text=True, timeout=400, cwd=out)
    assert run.returncode == 0, run.stdout
    (folder,) = [p for p in out.iterdir() if p.is_dir()]
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["outcome"] == "finished", run.stdout
    return folder


def test_the_evaluation_runs_the_participant_and_coach_that_ran(session: Path) -> None:
    spec, coach = evaluation_spec(session)
    assert (spec.params.age, spec.participant_seed, spec.policy) == (AGE, PARTICIPANT_SEED, POLICY)
    assert coach.seed == spec.coach_seed


def test_the_participants_seeded_model_starts_with_the_session(session: Path) -> None:
    bag = read_bag(session / "bag")
    start = next(m.data["t"] for m in bag.json[topics.COACH_EVENTS] if m.data.get("event") == "session_start")
    states = [m.data for m in bag.json[topics.PARTICIPANT_STATE]]
    assert states[0]["session_model_t0"] is None  # resting on the pre-session stream first
    handover = states[-1]["session_model_t0"]
    # At or after the start, before the seated calibration that opens the session ends.
    _, coach = evaluation_spec(session)
    assert handover is not None and start <= handover < start + coach.calib_time, (start, handover)


def test_the_closed_loop_takes_the_evaluations_decisions(session: Path) -> None:
    events = [m.data for m in read_bag(session / "bag").json[topics.COACH_EVENTS]]
    recorded = changes(events)
    evaluated = evaluated_changes(session)
    detail = f"closed loop {recorded}\nevaluation  {evaluated}"
    assert recorded, detail  # the predictive policy plans the conditioning and the cool-down
    assert compare_changes(recorded, evaluated, TOLERANCE_S) == [], detail
    # The same comparison tells other decisions apart: another policy, another person.
    assert compare_changes(recorded, evaluated_changes(session, policy="threshold"), TOLERANCE_S), detail
    assert compare_changes(recorded, evaluated_changes(session, age=50.0), TOLERANCE_S), detail

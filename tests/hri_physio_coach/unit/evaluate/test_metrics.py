"""Per-session metrics on a hand-made session, and reachability on people whose answer is known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hri_physio_coach.coach import load_coach_routine
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.evaluate.metrics import adaptations, session_metrics, smoothed
from hri_physio_coach.evaluate.reach import ABOVE, BELOW, REACHABLE, reach
from hri_physio_coach.evaluate.simulation import SessionRun, SessionSpec
from hri_physio_coach.participant.physiology import ParticipantParams

ZONE = {"event": "zone", "t": 180.0, "hr_rest": 70.0, "hr_max": 190.0, "hrr": 120.0, "low": 118.0,
        "high": 154.0}
PHASES = [("calibration", 0, 180), ("warm_up", 180, 480), ("conditioning", 480, 1080),
          ("cool_down", 1080, 1380)]


def decision(t: float, delta: int, level: tuple[float | None, float | None] = (None, None)) -> dict:
    changed = delta != 0 or level[0] != level[1]
    return {"t": t, "delta": delta, "changed": changed, "level_before": level[0], "level_after": level[1]}


def hand_made_run() -> SessionRun:
    t = np.arange(1.0, 1381.0)
    hr = np.full_like(t, 70.0)
    hr[(t >= 180) & (t < 480)] = 100.0
    hr[(t >= 300) & (t < 330)] = 160.0  # 30 s above the zone in the warm-up
    hr[(t >= 480) & (t < 930)] = 130.0  # in the zone for 450 of the 600 s of conditioning
    hr[(t >= 930) & (t < 1080)] = 100.0
    hr[t >= 1080] = 106.0  # ends at HRR30
    events = [{"event": "phase", "t": float(a), "phase": k, "kind": k, "ends_at": float(b)}
              for k, a, b in PHASES]
    events.append(ZONE)
    for when, kind, d in ((240, "warm_up", decision(240, +1)), (510, "conditioning", decision(510, +1)),
                          (600, "conditioning", decision(600, -1)), (700, "conditioning", decision(700, 0))):
        events.append({"event": "rule_update", "t": float(when), "inputs": {"phase_kind": kind},
                       "decision": d})
    events.append({"event": "plan", "t": 1080.0, "phase": "cool_down",
                   "decision": decision(1080, -2, (5.8, 3.5))})
    events.append({"event": "activity_choice", "t": 1080.0})
    spec = SessionSpec("predictive", 4, ParticipantParams(hr_max_true=190.0), 1, 2)
    strap = hr.copy()
    strap[(t >= 600) & (t < 603)] = 190.0  # a strap artefact: the heart itself stays at 130
    return SessionRun(spec, events, [], t, strap, hr, np.zeros(len(t), int), np.full(len(t), np.nan))


def test_smoothing_is_a_trailing_five_second_mean() -> None:
    x = np.array([0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0])
    np.testing.assert_allclose(smoothed(x), [0, 2.5, 5, 7.5, 10, 15, 20])
    assert len(smoothed(np.array([]))) == 0


def test_metrics_of_a_hand_made_session() -> None:
    m = session_metrics(hand_made_run())
    assert m["in_zone"] == m["in_zone_conditioning"]
    assert m["in_zone"] == pytest.approx(450 / 600)  # the true heart rate: the strap's artefact is not in it
    # The strap's 5-s mean leaves the zone for the artefact (3 s, blurred to 5) and at the edges.
    assert m["in_zone_strap"] == pytest.approx((450 - 5) / 600, abs=4 / 600)
    assert m["in_zone_strap"] < m["in_zone"]
    assert m["in_zone_warm_up"] == 0.0  # the heart jumps from 100 to 160, over the zone
    assert m["time_to_zone_s"] == 300  # the conditioning's first second
    assert m["above_hrr70_s"] == 30
    assert m["above_85_hrmax_s"] == 0  # 160 < 0.85 * 190
    assert (m["adaptations_warm_up"], m["adaptations_conditioning"], m["adaptations_cool_down"]) == (1, 2, 1)
    assert m["adaptations_per_10min"] == 2.0
    assert m["reversals"] == 1  # up, up, down, down
    assert m["cooldown_end_frac_hrr"] == pytest.approx(0.3)
    assert m["activity_substitutions"] == 1
    assert m["rms_to_centre_bpm"] == pytest.approx(math.sqrt((450 * 6**2 + 150 * 36**2) / 600), rel=0.03)
    assert "reach" not in m


def test_adaptations_are_counted_in_the_phase_they_were_made_in() -> None:
    run = hand_made_run()
    assert adaptations(run) == [("warm_up", 240.0, 1), ("conditioning", 510.0, 1),
                                ("conditioning", 600.0, -1), ("cool_down", 1080.0, -1)]


@pytest.fixture(scope="module")
def routine():
    return load_coach_routine(CoachConfig())


def verdict(p: ParticipantParams, routine, **controls) -> str:
    cfg = CoachConfig()
    return reach(p, 118.0, 154.0, routine, "conditioning", tuple(cfg.speed_modifier), tuple(cfg.audio_suffix),
                 cfg.speed_idx, **controls).verdict


def test_reachability_depends_on_the_person_and_on_the_policy_controls(routine) -> None:
    base = dict(hr_rest=70.0, hr_max_true=190.0)
    very_fit = ParticipantParams(**base, vo2max=70.0, step_height=0.10)
    very_unfit = ParticipantParams(**base, vo2max=14.0, step_height=0.20)
    typical = ParticipantParams(**base, vo2max=38.0, step_height=0.15)
    for controls in ({"adapts": False, "chooses_activity": False},
                     {"adapts": True, "chooses_activity": False},
                     {"adapts": True, "chooses_activity": True}):
        assert verdict(very_fit, routine, **controls) == BELOW
        assert verdict(very_unfit, routine, **controls) == ABOVE
    # Someone whose stepping lands in the zone but whose routine (half marching) averages below it:
    stepper = ParticipantParams(**base, vo2max=44.0, step_height=0.15, tempo_compliance=0.3, gesture_gain=0.0)
    assert verdict(stepper, routine, adapts=True, chooses_activity=True) == REACHABLE
    assert verdict(stepper, routine, adapts=True, chooses_activity=False) == BELOW
    assert verdict(typical, routine, adapts=True, chooses_activity=True) == REACHABLE

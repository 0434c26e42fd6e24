"""The alternative participant models against the published facts they are built from."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hri_physio_coach.evaluate.cohort import make_cohort
from hri_physio_coach.participant.cardiac import ParticipantSimulator
from hri_physio_coach.participant.models import (
    MODEL_NAMES,
    VagalParams,
    Vo2Params,
    acsm_stepping_vo2,
    as_model,
    intrinsic_hr,
    model_info,
    sample_vagal,
    sample_vo2drive,
    tanaka_hr_max,
)
from hri_physio_coach.participant.physiology import REST_VO2, Activity, ParticipantParams
from hri_physio_coach.participant_config import ParticipantNodeConfig

STEP = Activity("step_up", 120.0, 1.0)
MARCH = Activity("marching", 120.0, 1.0)
ARMS = Activity("arms_forward", 120.0, 1.0)


def run(kinetics, activity: Activity, seconds: float) -> np.ndarray:
    """HR every 0.1 s while doing ``activity`` for ``seconds``."""
    kinetics.set_activity(activity)
    return np.array([kinetics.step() for _ in range(round(seconds / kinetics.dt))])


def test_acsm_stepping_equation() -> None:
    # ACSM: VO2 = 0.2 f + 1.33 (1.8 H f) + 3.5; 30 cycles/min on a 0.15 m step.
    assert acsm_stepping_vo2(0.15, 30.0) == pytest.approx(0.2 * 30 + 1.33 * 1.8 * 0.15 * 30 + 3.5, rel=1e-3)


def test_vagal_steady_state_is_the_acsm_hrr_vo2r_relation() -> None:
    p = VagalParams(age=30, hr_rest=65, hr_max_true=188, vo2max=42, step_height=0.15, tempo_compliance=1.0,
                    gesture_gain=0.0, stepping_cost=1.0, drift_rate=0.0, arrival_offset=0.0, tau_on=60.0)
    net = acsm_stepping_vo2(0.15, 120.0 / 4.0) - REST_VO2
    expected = 65 + net / (42 - REST_VO2) * (188 - 65)  # %HRR = %VO2R
    assert p.settled_hr(STEP) == pytest.approx(expected, rel=1e-9)
    hr = run(p.make_kinetics(0.1), STEP, 900.0)
    assert hr[-1] == pytest.approx(expected, abs=0.3)


def test_vagal_lateral_knee_lifts_cost_the_persons_own_share_of_a_step_up() -> None:
    """One label (5.8 METs), two movements: each person's lateral knee lifts cost their step-ups' times
    ``lateral_cost`` (sampled 1 +/- 0.1)."""
    base = dict(age=30, hr_rest=65, hr_max_true=188, vo2max=42, step_height=0.15, tempo_compliance=1.0,
                gesture_gain=0.0, drift_rate=0.0, arrival_offset=0.0, tau_on=60.0)
    lateral = Activity("lateral", 120.0, 1.0)
    same = VagalParams(**base)
    assert same.settled_hr(lateral) == pytest.approx(same.settled_hr(STEP), rel=1e-12)
    harder = VagalParams(lateral_cost=1.15, **base)
    assert harder.settled_hr(lateral) - 65 == pytest.approx(1.15 * (harder.settled_hr(STEP) - 65), rel=1e-9)
    assert harder.settled_hr(STEP) == same.settled_hr(STEP)
    people = sample_vagal(200, 1)
    spread = np.array([p.lateral_cost for p in people])
    assert 0.08 < spread.std() < 0.12 and spread.min() >= 0.8 and spread.max() <= 1.2


def test_vagal_fast_part_is_capped_at_the_intrinsic_heart_rate() -> None:
    base = dict(age=30, hr_max_true=188, vo2max=30, step_height=0.2, tempo_compliance=1.0, gesture_gain=0.0,
                drift_rate=0.0, arrival_offset=0.0, tau_on=80.0, dead_time=5.0, tau_vagal=3.0)
    low_rest = VagalParams(hr_rest=55, **base)  # room for vagal withdrawal: 118.1 - 0.57*30 - 55 = 46 bpm
    high_rest = VagalParams(hr_rest=95, **base)  # almost none: 6 bpm
    hr_low = run(low_rest.make_kinetics(0.1), STEP, 15.0)
    hr_high = run(high_rest.make_kinetics(0.1), STEP, 15.0)
    rise_low, rise_high = hr_low[-1] - 55, hr_high[-1] - 95
    for p, rise in ((low_rest, rise_low), (high_rest, rise_high)):
        room = intrinsic_hr(30) - p.hr_rest
        total = p.settled_hr(STEP) - p.hr_rest
        # The fast part reaches its cap; the slow part has run 10 s (15 s less the dead time) of its lag.
        slow = (total - room) * (1.0 - np.exp(-10.0 / 80.0))
        assert rise == pytest.approx(room * (1.0 - np.exp(-15.0 / 3.0)) + slow, abs=1.0)
    assert rise_low > 2 * rise_high


def test_vagal_off_response_is_slower_than_on() -> None:
    p = VagalParams(age=30, hr_rest=70, hr_max_true=188, vo2max=40, drift_rate=0.0, arrival_offset=0.0,
                    tau_on=60.0, off_factor=1.6)
    k = p.make_kinetics(0.1)
    on = run(k, STEP, 600.0)
    rise = on[-1] - 70
    off = run(k, Activity("rest"), 600.0)
    t_on = np.argmax(on - 70 >= 0.9 * rise)
    t_off = np.argmax(on[-1] - off >= 0.9 * rise)
    assert 1.2 * t_on < t_off < 2.2 * t_on


def test_vagal_drift_and_cadence_cap() -> None:
    p = VagalParams(age=30, hr_rest=70, hr_max_true=188, vo2max=40, drift_rate=0.25, arrival_offset=0.0,
                    tau_on=50.0, cadence_cap=125.0, tempo_compliance=1.0)
    hr = run(p.make_kinetics(0.1), STEP, 1200.0)
    slope = (hr[-1] - hr[-3001]) / 5.0  # bpm/min over the last 5 minutes (settled)
    intensity = (p.settled_hr(STEP) - 70) / (188 - 70)
    assert slope == pytest.approx(0.25 * min(intensity / 0.4, 1.0), abs=0.03)
    assert p.cadence(135.0) == 125.0 and p.settled_hr(Activity("step_up", 135.0)) == p.settled_hr(
        Activity("step_up", 125.0))


def test_arm_work_raises_hr_more_per_unit_of_oxygen() -> None:
    p = VagalParams(arm_work=0.1, arm_hr_gain=1.3)
    legs, arms = p.costs(ARMS)
    assert arms == pytest.approx(0.1 * legs)
    leg_only = (p.settled_hr(STEP) - p.hr_rest) / p.costs(STEP)[0]
    with_arms = (p.settled_hr(ARMS) - p.hr_rest) / (legs + arms)
    assert with_arms > leg_only


def test_vagal_cohort_hr_max_follows_tanaka_with_sd_10() -> None:
    people = sample_vagal(2000, 3)
    dev = np.array([p.hr_max_true - tanaka_hr_max(p.age) for p in people])
    assert abs(dev.mean()) < 1.0 and 8.5 < dev.std() < 11.0
    assert all(40 <= p.tau_on <= 90 and 1.2 <= p.off_factor <= 2.0 and 0.1 <= p.drift_rate <= 0.3
               and 2 <= p.dead_time <= 10 and 0 <= p.arrival_offset <= 10 for p in people)


def test_vo2drive_hr_follows_swain_below_the_ventilatory_threshold() -> None:
    p = Vo2Params(age=30, hr_rest=65, hr_max_true=190, vo2max=45, vt_fraction=0.6, drift_gain=0.0,
                  calibration_offset=0.0, tempo_compliance=1.0, preferred_cadence=120.0)
    vo2 = REST_VO2 + p.net_vo2(MARCH)
    assert vo2 < 0.6 * 45
    expected = 65 + 0.64 * 190 * (vo2 - REST_VO2) / 45  # %HRmax = 0.64 %VO2max + 37, from rest
    assert p.settled_hr(MARCH) == pytest.approx(expected, rel=1e-9)
    hr = run(p.make_kinetics(0.1), MARCH, 900.0)
    assert hr[-1] == pytest.approx(expected, abs=0.3)


def test_vo2drive_slow_component_keeps_hr_climbing_above_the_threshold() -> None:
    p = Vo2Params(age=40, hr_rest=75, hr_max_true=180, vo2max=28, vt_fraction=0.5, slow_gain=0.15,
                  drift_gain=0.0, calibration_offset=0.0, step_height=0.2, arm_hr_extra=0.0)
    assert REST_VO2 + p.net_vo2(STEP) > 0.5 * 28
    hr = run(p.make_kinetics(0.1), STEP, 900.0)
    at_3, at_15 = hr[1799], hr[-1]
    assert at_15 - at_3 > 3.0  # still climbing after the primary phase
    no_slow = replace(p, slow_gain=0.0)
    assert p.settled_hr(STEP) > no_slow.settled_hr(STEP)


def test_vo2drive_cadence_is_entrained_from_the_preferred_one() -> None:
    p = Vo2Params(preferred_cadence=110.0, tempo_compliance=0.5)
    assert p.cadence(130.0) == pytest.approx(120.0)
    assert p.net_vo2(Activity("step_up", 130.0)) > p.net_vo2(Activity("step_up", 110.0))


def test_strap_jitter_and_dropouts() -> None:
    quiet = ParticipantParams()
    noisy = replace(VagalParams(), strap_jitter=2.0, dropout_rate=0.1)
    a = ParticipantSimulator(quiet, seed=4, ecg=False).advance_hr(600.0)
    b = ParticipantSimulator(noisy, seed=4, ecg=False).advance_hr(600.0)
    assert len(a) == 600
    assert 0.04 < 1 - len(b) / 600 < 0.2
    times = [t for t, _, _ in b]
    assert times == sorted(times) and len(set(times)) == len(times)


def test_models_are_selectable_for_the_evaluation_and_the_node() -> None:
    assert set(MODEL_NAMES) >= {"standard", "vagal", "vo2drive"}
    for name in MODEL_NAMES:
        people = make_cohort(3, 1, model=name)
        assert all(type(p) is model_info(name).params and p.model == name for p in people)
        cfg = ParticipantNodeConfig(model=name, age=40.0)
        assert cfg.params.model == name and cfg.params.age == 40.0
    assert as_model(ParticipantParams(hr_rest=60.0), "vo2drive").hr_rest == 60.0
    with pytest.raises(ValueError, match="unknown participant model"):
        model_info("nope")
    assert sample_vo2drive(5, 2) == sample_vo2drive(5, 2)  # seeded


def test_the_sensitivity_sweep_moves_only_what_a_model_uses() -> None:
    from hri_physio_coach.evaluate.cohort import variants

    standard = {name.split("=")[0] for name, _ in variants(make_cohort(2, 1))}
    vo2 = {name.split("=")[0] for name, _ in variants(make_cohort(2, 1, model="vo2drive"))}
    assert {"tau_on", "tau_fast", "drift_amplitude"} <= standard
    vagal = {name.split("=")[0] for name, _ in variants(make_cohort(2, 1, model="vagal"))}
    assert vo2 == {"tempo_compliance", "gesture_gain", "calibration_offset"}
    assert "lateral_cost" in vagal and "lateral_cost" not in standard | vo2


@pytest.mark.parametrize("model", MODEL_NAMES)
def test_a_run_advanced_in_any_chunks_is_the_run_stepped_one_model_step_at_a_time(model: str) -> None:
    """The simulator steps its kinetics in batches up to the next activity change: advancing one model
    step per call (batches of one) and in irregular chunks give the same beats, intervals and 1-Hz
    reports, bit for bit (activity changes falling inside chunks, artefacts, jitter and dropouts)."""
    person = replace(make_cohort(1, 4, model=model)[0], artefact_rate=0.05)
    rng = np.random.default_rng(7)
    names = ["marching", "step_up", "lateral", "arms_forward", "rest"]
    changes = [(float(rng.uniform(0.0, 280.0)), Activity(str(rng.choice(names)), float(rng.uniform(95, 140)),
                                                         float(rng.uniform(0.6, 1.4)))) for _ in range(12)]
    steps = np.cumsum(rng.choice([1, 3, 10, 27, 110], size=100))  # chunk ends, in model steps of 0.1 s

    def run(ends: np.ndarray) -> list[np.ndarray]:
        sim = ParticipantSimulator(person, seed=3, ecg=False, t0=100.0)
        for at, activity in changes:
            sim.set_activity(activity, 100.0 + at)  # all ahead: they start as the model reaches them
        outs = [sim.advance(100.0 + k * 0.1) for k in ends]
        fields = ("beat_t", "rr_t", "rr_s", "hr_t", "hr_bpm")
        return [np.concatenate([getattr(o, f) for o in outs]) for f in fields]

    stepwise, chunked = run(np.arange(1, steps[-1] + 1)), run(steps)
    assert len(chunked[3]) > 250 and len(chunked[0]) > 250  # the changes fall inside the run
    for a, b in zip(stepwise, chunked, strict=True):
        np.testing.assert_array_equal(a, b)

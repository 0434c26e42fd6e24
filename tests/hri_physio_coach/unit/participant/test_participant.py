"""The simulated participant: ACSM demand, HR kinetics, RR variability, synthetic ECG."""

from __future__ import annotations

import math

import neurokit2 as nk
import numpy as np
import pytest

from hri_physio_coach.participant.cardiac import ParticipantSimulator
from hri_physio_coach.participant.perception import RobotObserver, tempo_from_audio
from hri_physio_coach.participant.physiology import (
    REST_VO2,
    Activity,
    HeartRateKinetics,
    ParticipantParams,
    breathing_rate,
    demand,
    net_vo2,
    rr_sd,
    sample_population,
)


@pytest.mark.parametrize("tempo,mets", [(110, 6.3), (120, 6.8), (135, 7.5)])
def test_acsm_stepping_equation_at_20cm(tempo: float, mets: float) -> None:
    p = ParticipantParams(step_height=0.20, tempo_compliance=1.0, gesture_gain=0.0)
    vo2 = net_vo2(p, Activity("step_up", tempo, 1.0)) + REST_VO2
    assert vo2 / REST_VO2 == pytest.approx(mets, abs=0.05)


def test_demand_modifiers() -> None:
    p = ParticipantParams(tempo_compliance=0.5, gesture_gain=0.4)
    base = net_vo2(p, Activity("step_up", 120, 1.0))
    # Compliance: half of the tempo change reaches the cadence.
    assert net_vo2(p, Activity("step_up", 140, 1.0)) == pytest.approx(base * 130 / 120)
    assert net_vo2(p, Activity("arms_forward", 120, 1.0)) == pytest.approx(base * 1.10)
    assert net_vo2(p, Activity("step_up", 120, 1.15)) == pytest.approx(base * (1 + 0.4 * 0.15))
    assert net_vo2(p, Activity("marching", 120, 1.0)) == pytest.approx(2.5 * REST_VO2)
    assert net_vo2(p, Activity("base", 135, 1.2)) == 0.0
    assert demand(p, Activity("step_up", 120, 1.0)) == pytest.approx(base / (p.vo2max - REST_VO2))
    with pytest.raises(ValueError, match="unknown activity 'juggling'"):
        net_vo2(p, Activity("juggling"))


def run_kinetics(p: ParticipantParams, activity: Activity, seconds: float,
                 model: HeartRateKinetics | None = None) -> tuple[HeartRateKinetics, np.ndarray]:
    k = model or HeartRateKinetics(p, dt=0.1)
    k.set_activity(activity)
    hr = np.array([k.step() for _ in range(round(seconds / 0.1))])
    return k, hr


def test_fast_and_slow_components_follow_their_time_constants() -> None:
    p = ParticipantParams(drift_amplitude=0.0, calibration_offset=0.0)
    act = Activity("step_up", 120, 1.0)
    u = demand(p, act)
    k, _ = run_kinetics(p, act, p.tau_fast)
    assert k.x_fast == pytest.approx(0.35 * u * (1 - math.exp(-1)), rel=0.02)
    assert k.x_slow == pytest.approx(0.65 * u * (1 - math.exp(-(p.tau_fast - p.dead_time) / p.tau_on)),
                                     rel=0.05)
    k, _ = run_kinetics(p, act, p.dead_time + p.tau_on - p.tau_fast, model=k)
    assert k.x_slow == pytest.approx(0.65 * u * (1 - math.exp(-1)), rel=0.02)
    # Recovery uses tau_off: from steady state, one tau_off after the dead time -> e^-1 left.
    k, _ = run_kinetics(p, act, 600, model=k)
    steady = k.x_slow
    k, _ = run_kinetics(p, Activity("rest"), p.dead_time + p.tau_off, model=k)
    assert k.x_slow == pytest.approx(steady * math.exp(-1), rel=0.03)


def test_drift_only_above_30_percent_and_hr_capped() -> None:
    light = ParticipantParams(vo2max=60.0)
    k, _ = run_kinetics(light, Activity("marching", 110, 1.0), 300)
    assert demand(light, Activity("marching", 110, 1.0)) < 0.3 and k.x_drift == 0.0
    hard = ParticipantParams(vo2max=15.0, step_height=0.2, hr_max_true=170.0)
    k, hr = run_kinetics(hard, Activity("arms_forward", 135, 1.15), 900)
    assert k.x_drift > 0.0
    assert hr.max() == pytest.approx(170.0) and np.all(hr <= 170.0)


def test_calibration_offset_only_while_seated() -> None:
    p = ParticipantParams(calibration_offset=4.0)
    k = HeartRateKinetics(p)
    assert k.hr == pytest.approx(p.hr_rest + 4.0)
    k.set_activity(Activity("marching"))
    assert k.hr == pytest.approx(p.hr_rest)


def test_rr_variability_rules() -> None:
    p = ParticipantParams(sdnn_rest=0.045, hr_rest=70)
    assert rr_sd(p, 70) == pytest.approx(0.045)
    assert rr_sd(p, 90) == pytest.approx(0.0225)
    assert breathing_rate(0.0) == pytest.approx(0.25) and breathing_rate(1.5) == pytest.approx(0.6)


def test_invalid_participants_are_refused() -> None:
    with pytest.raises(ValueError, match="age must be in"):
        HeartRateKinetics(ParticipantParams(age=0))
    with pytest.raises(ValueError, match="hr_rest < hr_max_true"):
        HeartRateKinetics(ParticipantParams(hr_rest=190, hr_max_true=180))
    with pytest.raises(ValueError, match="vo2max must exceed"):
        HeartRateKinetics(ParticipantParams(vo2max=3.0))


def test_population_is_seeded_and_within_published_ranges() -> None:
    a = sample_population(200, seed=7)
    assert a == sample_population(200, seed=7)
    assert a != sample_population(200, seed=8)
    ages = np.array([p.age for p in a])
    assert ages.min() >= 20 and ages.max() <= 50
    assert all(50 <= p.hr_rest <= 100 for p in a)
    assert all(0.10 <= p.step_height <= 0.20 and 0.3 <= p.tempo_compliance <= 1 for p in a)
    hrmax_resid = np.array([p.hr_max_true - (208 - 0.7 * p.age) for p in a])
    assert abs(hrmax_resid.mean()) < 2.0 and 5.0 < hrmax_resid.std() < 9.0
    assert 0.3 < np.mean([p.female for p in a]) < 0.7


def simulate(p: ParticipantParams, plan: list[tuple[float, Activity]], seconds: float, seed: int = 1):
    sim = ParticipantSimulator(p, seed=seed)
    outs = []
    for second in range(1, int(seconds) + 1):
        for when, act in plan:
            if when == second - 1:
                sim.set_activity(act)
        outs.append(sim.advance(float(second)))
    return outs


def test_ecg_r_peaks_are_recovered_by_neurokit_within_20ms() -> None:
    plan = [(0, Activity("rest")), (60, Activity("step_up", 130, 1.1)), (150, Activity("marching"))]
    outs = simulate(ParticipantParams(), plan, 240)
    t = np.concatenate([o.ecg_t for o in outs])
    ecg = np.concatenate([o.ecg_mv for o in outs])
    beats = np.concatenate([o.beat_t for o in outs])
    np.testing.assert_allclose(np.diff(t), 1 / 130.0, atol=1e-9)  # continuous 130 Hz samples
    _, info = nk.ecg_peaks(nk.ecg_clean(ecg, sampling_rate=130), sampling_rate=130)
    found = t[info["ECG_R_Peaks"]]
    inner = beats[(beats > t[0] + 1.0) & (beats < t[-1] - 1.0)]
    nearest = np.abs(inner[:, None] - found[None, :]).min(axis=1)
    assert np.all(nearest <= 0.020), f"{(nearest > 0.020).sum()} of {len(inner)} beats not found"
    extra = np.abs(found[:, None] - beats[None, :]).min(axis=1)
    assert np.all(extra <= 0.020)


def test_heart_rate_rises_with_exercise_and_reported_hr_tracks_the_model() -> None:
    p = ParticipantParams(artefact_rate=0.0)
    outs = simulate(p, [(0, Activity("rest")), (60, Activity("step_up", 135, 1.15))], 360)
    hr = np.concatenate([o.hr_bpm for o in outs])
    model = np.array([h for o in outs for _, h in o.model_hr])
    assert len(hr) == 360  # 1 Hz
    assert hr[30:60].mean() == pytest.approx(p.hr_rest + p.calibration_offset, abs=4)
    assert hr[-30:].mean() > hr[30:60].mean() + 20
    assert abs(hr[-30:].mean() - model[-300:].mean()) < 3


def test_resting_variability_matches_parameters() -> None:
    p = ParticipantParams(sdnn_rest=0.045, hr_rest=70, calibration_offset=0.0, artefact_rate=0.0)
    outs = simulate(p, [(0, Activity("rest"))], 600, seed=3)
    rr = np.concatenate([o.rr_s for o in outs])
    assert rr.std() == pytest.approx(0.045, rel=0.25)
    assert 60 / rr.mean() == pytest.approx(70, abs=2)


def test_strap_artefacts_at_the_configured_rate() -> None:
    clean = simulate(ParticipantParams(artefact_rate=0.0), [(0, Activity("rest"))], 300, seed=5)
    beats = np.concatenate([o.beat_t for o in clean])
    rr = np.concatenate([o.rr_s for o in clean])
    np.testing.assert_allclose(rr, np.diff(beats), atol=1e-12)  # no artefacts: true intervals
    noisy = simulate(ParticipantParams(artefact_rate=0.05), [(0, Activity("rest"))], 600, seed=5)
    rr = np.concatenate([o.rr_s for o in noisy])
    odd = np.mean((rr > 1.5 * np.median(rr)) | (rr < 0.6 * np.median(rr)))
    # Half the artefacts are extra beats (two short reports), half missed ones (one long):
    # about 0.075 of the ~700 reports, whose sampling SD is about 0.01.
    assert 0.045 < odd < 0.105


def test_robot_commands_set_the_activity() -> None:
    assert tempo_from_audio("music/workout_125.wav") == 125
    assert tempo_from_audio("calm.mp3") is None
    assert tempo_from_audio("track2_bpm110.ogg") == 110
    obs = RobotObserver()
    assert obs.observe("set gesture step_up 1.05")
    assert obs.observe("set audio /media/music_130.wav")
    assert obs.activity == Activity("step_up", 130.0, 1.05)
    assert not obs.observe("set speech Keep going!")
    assert not obs.observe("set gesture")  # malformed: ignored, remembered
    assert obs.ignored == ["set gesture"]
    assert obs.observe("set gesture wave 1.0") and obs.activity.name == "rest"


def test_the_tempo_heard_is_the_one_the_audio_streamer_reports_playing() -> None:
    obs = RobotObserver()
    assert obs.observe("set audio beat:130") and obs.activity.tempo_bpm == 130.0  # no streamer heard yet
    assert obs.observe_audio_status({"state": "playing", "source": "beat:115", "tempo": 115.0})
    assert obs.hears_streamer and obs.activity.tempo_bpm == 115.0
    assert not obs.observe("set audio beat:135")  # asked for, not (yet) playing: the person hears 115
    assert obs.activity.tempo_bpm == 115.0
    # While fading, the incoming track; a plain file's tempo comes from its name.
    assert obs.observe_audio_status({"state": "fading", "source": "beat:135", "tempo": 135.0})
    assert obs.observe_audio_status({"state": "playing", "source": "./audio/exercise_125.wav",
                                     "kind": "file"})
    assert obs.activity.tempo_bpm == 125.0
    # An error status still describes what plays; silence and a pad without tempo keep the last one.
    assert not obs.observe_audio_status({"state": "error", "source": "./audio/exercise_125.wav",
                                         "error": "bad file", "request": "x.wav"})
    assert not obs.observe_audio_status({"state": "stopped"})
    assert not obs.observe_audio_status({"state": "playing", "source": "relaxing", "kind": "relaxing"})
    assert obs.activity.tempo_bpm == 125.0
    for bad in ({"state": "playing", "tempo": "fast"}, {"state": "playing", "tempo": True}, {}, {"state": 3}):
        assert not obs.observe_audio_status(bad)
    assert obs.activity.tempo_bpm == 125.0

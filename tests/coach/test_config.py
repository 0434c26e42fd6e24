"""Coach configuration: the seed's keys, validation with clear errors, participant ids."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from hri_physio_coach.coach import CoachError, ExerciseCoach, load_coach_routine
from hri_physio_coach.config import (
    CoachConfig,
    ConfigError,
    config_from_mapping,
    load_config,
    participant_id,
)
from hri_physio_coach.paths import default_config_file, default_routine_file
from hri_physio_coach.routine import parse_routine


def test_packaged_config_is_the_defaults() -> None:
    assert load_config(default_config_file()) == CoachConfig()
    raw = yaml.safe_load(default_config_file().read_text())
    assert set(raw) == set(CoachConfig().as_dict())  # the file documents every key


def test_seed_keys_and_defaults() -> None:
    cfg = CoachConfig()
    assert cfg.speed_modifier == [0.90, 0.95, 1.00, 1.05, 1.10, 1.15]
    assert cfg.audio_suffix == ["110", "115", "120", "125", "130", "135"]
    assert cfg.speed_idx == 1 and cfg.calib_time == 180.0 and cfg.video_time == 30.0
    assert (cfg.behaviour_period, cfg.rule_period) == (20.0, 30.0)
    assert (cfg.zone_low, cfg.zone_high, cfg.policy) == (0.40, 0.70, "threshold")
    assert cfg.adapter_options.refractory_period == 60.0 and cfg.adapter_options.warmup_max_speedups is None


def test_seed_style_file_and_ros_params_file(tmp_path: Path) -> None:
    seed = tmp_path / "coach.yaml"
    seed.write_text(
        "part_name: Jane\npart_age: 33\ncalib_time: 120\nresting_default: 70\n"
        "speed_modifier: ['0.8', '1.0', '1.2']\naudio_suffix: [100, 120, 140]\nspeed_idx: 0\n"
        "speech_motivation: [Go go go]\n"
    )
    cfg = load_config(seed)
    assert (cfg.part_age, cfg.calib_time, cfg.resting_default) == (33.0, 120.0, 70.0)
    assert cfg.speed_modifier == [0.8, 1.0, 1.2] and cfg.audio_suffix == ["100", "120", "140"]
    assert cfg.speech_motivation == ["Go go go"]
    params = tmp_path / "params.yaml"
    params.write_text("qt_physio_coach:\n  ros__parameters:\n    part_age: 40.0\n    policy: fuzzy\n")
    cfg = load_config(params, overrides={"seed": 9})
    assert (cfg.part_age, cfg.policy, cfg.seed) == (40.0, "fuzzy", 9)


@pytest.mark.parametrize(
    "values,match",
    [
        ({"part_age": 0}, r"part_age must be in \(0, 120\]"),
        ({"part_age": -3}, r"part_age must be in \(0, 120\]"),
        ({"part_age": 121}, r"part_age must be in \(0, 120\]"),
        ({"zone_low": 0.7, "zone_high": 0.4}, "zone bounds out of order"),
        ({"zone_low": 0.5, "zone_high": 0.5}, "zone bounds out of order"),
        ({"policy": "pid"}, "unknown policy 'pid'; choose one of threshold, fuzzy, static"),
        ({"speed_modifier": [], "audio_suffix": []}, "empty speed ladder"),
        ({"speed_modifier": [1.0, 1.1]}, "one music tempo per gesture speed"),
        ({"speed_idx": 6}, "speed_idx 6 is outside the ladder"),
        ({"speed_modifier": [1.0, 0.9, 1.1, 1.2, 1.3, 1.4]}, "increase"),
        ({"rule_period": 0}, "rule_period must be > 0"),
        ({"resting_default": 300}, "resting_default"),
        ({"hr_valid_min": 200, "hr_valid_max": 100}, "hr_valid_min"),
        ({"part_agee": 30}, r"unknown key\(s\) \['part_agee'\]"),
        ({"part_age": "old"}, "part_age must be float"),
        ({"calib_skip": "yes"}, "calib_skip must be bool"),
        ({"speech_motivation": []}, "speech_motivation must list at least one entry"),
        ({"audio_path": "music.wav"}, "audio_path must contain"),
        ({"adapt_warmup_max_speedups": -5}, "adapt_warmup_max_speedups"),
    ],
)
def test_invalid_configuration(values: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        config_from_mapping(values, "test.yaml")


def test_config_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("part_age: [1,\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(bad)
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="key: value"):
        load_config(listed)


def test_participant_id_is_pseudonymous_and_stable() -> None:
    pid = participant_id("Jane Doe", 33)
    assert pid.startswith("P-") and len(pid) == 12
    assert "jane" not in pid.lower()
    assert participant_id("  jane doe ", 33.0) == pid  # case and padding do not matter
    assert participant_id("Jane Doe", 34) != pid
    assert participant_id("John Doe", 33) != pid
    assert participant_id("Jane Doe", 33, salt="lab-secret") != pid
    assert CoachConfig(part_name="Jane Doe", part_age=33).participant == pid


def test_packaged_routine_is_the_thesis_routine() -> None:
    routine = load_coach_routine(CoachConfig())
    assert default_routine_file().is_file()
    assert [(p.name, p.duration) for p in routine.phases] == [
        ("calibration", 180.0), ("warm_up", 300.0), ("conditioning", 600.0), ("cool_down", 300.0)]
    assert routine.duration == 23 * 60
    acts = [(a.attrs.get("gesture"), a.duration) for p in routine.phases[1:] for a in p.activities]
    assert acts == [("marching", 180), ("step_up", 120),
                    ("marching", 60), ("lateral", 120), ("marching", 60), ("arms_forward", 120),
                    ("marching", 60), ("lateral", 120), ("marching", 60),
                    ("step_up", 120), ("marching", 180)]
    # calib_time comes from the configuration.
    assert load_coach_routine(CoachConfig(calib_time=60.0)).phases[0].duration == 60.0


def test_coach_rejects_routines_it_cannot_run() -> None:
    cfg = CoachConfig()
    activities = [{"name": "x", "duration": 60}]
    base = {"phases": [{"name": "p", "hooks": ["rule_update"], "activities": activities}]}

    def coach(raw: dict) -> ExerciseCoach:
        return ExerciseCoach(cfg, lambda: 0.0, lambda line: None, lambda e: None, parse_routine(raw))

    coach(base)  # fine
    with pytest.raises(CoachError, match=r"unknown placeholder \{colour\}"):
        coach({**base, "on_end": [{"say": "Bye {colour}"}]})
    with pytest.raises(CoachError, match="unknown call 'dance'"):
        coach({**base, "on_end": [{"call": "dance"}]})
    with pytest.raises(CoachError, match=r"uses hook\(s\) \['stretch'\]"):
        coach({"phases": [{"name": "p", "hooks": ["stretch"], "activities": activities}]})
    with pytest.raises(CoachError, match="speech_zone"):
        ExerciseCoach(cfg.replace(speech_zone="HR {hr_rset}"), lambda: 0.0, lambda line: None,
                      lambda e: None, parse_routine(base))

"""Coach and participant configuration: declared once, the seed's keys, clear errors, participant ids."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from hri_physio_bridge import config as bridge_config
from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError
from hri_physio_coach.coach import CoachError, ExerciseCoach, load_coach_routine
from hri_physio_coach.config import COACH_NODE, CoachConfig, CoachNodeConfig, load_config, participant_id
from hri_physio_coach.participant.physiology import ParticipantParams
from hri_physio_coach.participant_config import PARTICIPANT_NODE, ParticipantNodeConfig
from hri_physio_coach.paths import default_config_file, default_routine_file
from hri_physio_coach.policies.registry import POLICY_NAMES
from hri_physio_coach.routine import parse_routine


def test_packaged_config_is_the_defaults() -> None:
    assert load_config(default_config_file()) == CoachConfig()
    raw = yaml.safe_load(default_config_file().read_text())
    assert set(raw) == set(CoachConfig.model_fields)  # the file documents every key
    assert CoachNodeConfig.from_file(default_config_file(), COACH_NODE) == CoachNodeConfig()


def test_one_configuration_error_type() -> None:
    import hri_physio_coach.config as coach_config

    assert coach_config.ConfigError is bridge_config.ConfigError
    for gone in ("read_config_file", "SCALAR_KEYS", "_coerce", "config_from_mapping"):
        assert not hasattr(coach_config, gone), gone


def test_every_option_is_declared_with_its_help() -> None:
    for cls in (CoachNodeConfig, ParticipantNodeConfig):
        for name, info in cls.model_fields.items():
            assert info.description, f"{cls.__name__}.{name} has no help text"
    assert set(CoachConfig.SEED_KEYS) <= set(CoachConfig.model_fields)
    described = CoachConfig.describe("resting_default")
    assert "[bpm]" in described and ">= 20" in described and "(default: 61.0)" in described
    assert CoachNodeConfig.kind("policy") == "choice" and CoachNodeConfig.kind("speed_modifier") == "list"


def test_node_options_default_to_the_system_topics() -> None:
    cfg = CoachNodeConfig()
    assert (cfg.hr_topic, cfg.command_topic, cfg.reply_topic) == (
        topics.POLAR_H10_HR, topics.QT_COMMANDS, topics.QT_REPLIES)
    assert (cfg.events_topic, cfg.state_topic, cfg.control_topic) == (
        topics.COACH_EVENTS, topics.COACH_STATE, topics.COACH_CONTROL)
    assert (cfg.interactive, cfg.tick_period) == (False, 0.1)
    node = load_config(None, {"policy": "fuzzy", "hr_topic": "/x"}, CoachNodeConfig)
    assert isinstance(node, CoachNodeConfig) and (node.policy, node.hr_topic) == ("fuzzy", "/x")
    with pytest.raises(ConfigError, match="unknown option"):
        load_config(None, {"hr_topic": "/x"})  # a session option is not a node option


def test_flags_and_help_come_from_the_declaration() -> None:
    from hri_physio_bridge.node_runner import build_parser  # argparse only; no ROS node is made

    parser = build_parser(COACH_NODE, CoachNodeConfig, default_conf=default_config_file())
    text = parser.format_help()
    for flag in ("--interactive", "--policy", "--hr-topic", "--part-age", "--speed-modifier", "--conf"):
        assert flag in text, flag
    args = parser.parse_args(["--interactive", "--policy", "fuzzy", "--part-age", "45"])
    assert (args.interactive, args.policy, args.part_age) == (True, "fuzzy", "45")
    with pytest.raises(SystemExit):
        parser.parse_args(["--policy", "pid"])
    assert set(POLICY_NAMES) <= set(parser._option_string_actions["--policy"].choices)


def test_seed_keys_and_defaults() -> None:
    cfg = CoachConfig()
    assert cfg.speed_modifier == [0.90, 0.95, 1.00, 1.05, 1.10, 1.15]
    assert cfg.audio_suffix == ["110", "115", "120", "125", "130", "135"]
    assert cfg.speed_idx == 1 and cfg.calib_time == 180.0 and cfg.video_time == 30.0
    assert (cfg.behaviour_period, cfg.rule_period) == (20.0, 30.0)
    assert (cfg.zone_low, cfg.zone_high, cfg.policy) == (0.40, 0.70, "threshold")
    assert cfg.adapter_options.refractory_period is None and cfg.adapter_options.warmup_max_speedups is None


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
        ({"part_age": 0}, "part_age: expected greater than 0"),
        ({"part_age": -3}, "part_age: expected greater than 0"),
        ({"part_age": 121}, "part_age: expected less than or equal to 120"),
        ({"zone_low": 0.7, "zone_high": 0.4}, "zone bounds out of order"),
        ({"zone_low": 0.5, "zone_high": 0.5}, "zone bounds out of order"),
        ({"zone_high": 1.2}, "zone_high: expected less than or equal to 1"),
        ({"policy": "pid"}, "policy: expected 'threshold', 'fuzzy'"),
        ({"speed_modifier": [], "audio_suffix": []}, "speed_modifier: List should have at least 1 item"),
        ({"speed_modifier": [1.0, 1.1]}, "one music tempo per gesture speed"),
        ({"speed_idx": 6}, "speed_idx 6 is outside the ladder"),
        ({"speed_idx": -1}, "speed_idx: expected greater than or equal to 0"),
        ({"speed_modifier": [1.0, 0.9, 1.1, 1.2, 1.3, 1.4]}, "increase"),
        ({"speed_modifier": [0.05, 0.9, 1.1, 1.2, 1.3, 1.4]}, r"gesture speeds in \[0.1, 4\]"),
        ({"speed_modifier": ["fast", 0.9, 1.1, 1.2, 1.3, 1.4]}, "speed_modifier.0: expected a valid number"),
        ({"gesture_relaxing_speed": 0}, "gesture_relaxing_speed: expected greater than or equal to 0.1"),
        ({"rule_period": 0}, "rule_period: expected greater than 0"),
        ({"resting_default": 300}, "resting_default: expected less than or equal to 150"),
        ({"hr_valid_min": 200, "hr_valid_max": 100}, "hr_valid_min < hr_valid_max"),
        ({"buffer": 5}, r"buffer \(5\) must hold at least min_valid_samples \(10\)"),
        ({"part_agee": 30}, r"unknown option\(s\) part_agee"),
        ({"part_age": "old"}, "part_age: expected a valid number"),
        ({"part_age": True}, "part_age: expected a number, got True"),
        ({"calib_skip": "maybe"}, "calib_skip: expected a valid boolean"),
        ({"speech_motivation": []}, "speech_motivation: List should have at least 1 item"),
        ({"speech_faster": ["Go!", " "]}, "speech_faster: every entry must be a non-empty text"),
        ({"audio_path": "music.wav"}, "audio_path must contain"),
        ({"audio_exercise_base": "exercise"}, "audio_exercise_base must contain"),
        ({"adapt_warmup_max_speedups": -5}, "adapt_warmup_max_speedups: expected greater than or equal"),
        ({"max_invalid_fraction": 1.5}, "max_invalid_fraction: expected less than or equal to 1"),
        ({"seed": -1}, "seed: expected greater than or equal to 0"),
        ({"part_age": 90, "resting_default": 150},
         r"resting_default 150 bpm must be below the participant's HR_max 145\.0 bpm"),
    ],
)
def test_invalid_configuration(values: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        CoachConfig.from_mapping(values, "test.yaml")
    message = str(info.value)
    assert message.startswith("test.yaml: ") and "\n" not in message


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


# --- simulated_participant ----------------------------------------------------------------------
def test_participant_options_cover_the_model_with_its_defaults() -> None:
    cfg = ParticipantNodeConfig()
    model = {f.name for f in dataclasses.fields(ParticipantParams)}
    assert model <= set(ParticipantNodeConfig.model_fields), "a model parameter is not an option"
    assert cfg.params == ParticipantParams()
    assert cfg.command_topic == topics.QT_COMMANDS and cfg.state_topic == topics.PARTICIPANT_STATE
    assert cfg.lsl_name("HR") == "PolarH10/SIM0001/HR"
    assert cfg.replace(name_prefix="lab1/", device_id="X").lsl_name("ECG") == "lab1/PolarH10/X/ECG"
    assert ParticipantNodeConfig.from_mapping({"age": "45", "female": "true"}).params.age == 45.0


@pytest.mark.parametrize(
    "values,match",
    [
        ({"age": "abc"}, "age: expected a valid number"),
        ({"age": 0}, "age: expected greater than 0"),
        ({"hr_rest": 190}, "invalid participant: need 30 <= hr_rest < hr_max_true"),
        ({"vo2max": 3.0}, "vo2max: expected greater than 3.5"),
        ({"tempo_compliance": 2}, "tempo_compliance: expected less than or equal to 1"),
        ({"update_period": 0}, "update_period: expected greater than 0"),
        ({"device_id": ""}, "device_id: String should have at least 1 character"),
        ({"seed": 1.5}, "seed: expected a valid integer"),
        ({"seed": -1}, "seed: expected greater than or equal to 0"),
    ],
)
def test_invalid_participant_options(values: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        ParticipantNodeConfig.from_mapping(values, PARTICIPANT_NODE)

"""Every node's configuration, checked before anything starts; what is saved is what a node reads (no ROS)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import pytest
import yaml

from helpers import DATA, SRC
from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError, load_yaml
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.options import SessionConfig
from hri_physio_bringup.plan import (
    AUDIO,
    COACH,
    ECG_RECEIVER,
    HR_RECEIVER,
    PARTICIPANT,
    POLAR_STREAMER,
    PROCESSOR,
    RECORDER,
    VIDEO,
    coach_config,
    plan_session,
)

PACKAGED = SRC / "hri_physio_coach" / "config"


def plan(tmp_path: Path, **options):
    opts = SessionConfig.from_mapping(options, "test")
    folder = SessionFolder.plan(tmp_path / "sessions", "P-1", datetime(2026, 5, 4, 10, 30))
    return plan_session(opts, folder, "SIMABC123"), folder


def test_every_node_in_start_order_recorder_first_coach_last(tmp_path: Path) -> None:
    p, _ = plan(tmp_path)
    assert [n.name for n in p.nodes] == [RECORDER, "mock_qt_robot", "qt_controller", AUDIO, VIDEO,
                                         PARTICIPANT, HR_RECEIVER, ECG_RECEIVER, PROCESSOR, COACH]
    assert p.routine_duration == 1380.0  # the packaged 23-minute routine
    p, _ = plan(tmp_path, no_record=True, no_ecg=True)
    assert [n.name for n in p.nodes] == ["mock_qt_robot", "qt_controller", AUDIO, VIDEO, PARTICIPANT,
                                         HR_RECEIVER, COACH]


def test_saved_configurations_are_what_each_node_reads_back(tmp_path: Path) -> None:
    p, _ = plan(tmp_path)
    for node in p.nodes:
        conf = tmp_path / f"{node.name}.yaml"
        conf.write_text(node.config_yaml())
        assert node.argv(conf)[:2] == ["--conf", str(conf)]
        # What the node's runner does with --conf: load its program's section, validate with its model.
        again = type(node.config).from_mapping(load_yaml(conf, node.prog), str(conf))
        assert again == node.config, node.name


def test_the_session_sets_the_nodes_to_fit_together(tmp_path: Path) -> None:
    p, folder = plan(tmp_path, age=45, participant_seed=7)
    participant = p.node(PARTICIPANT).config
    assert (participant.age, participant.seed, participant.device_id) == (45.0, 7, "SIMABC123")
    hr, ecg = p.node(HR_RECEIVER).config, p.node(ECG_RECEIVER).config
    assert hr.input == "lsl:PolarH10/SIMABC123/HR" and ecg.input == "lsl:PolarH10/SIMABC123/ECG"
    assert participant.lsl_name("HR") == "PolarH10/SIMABC123/HR"  # the receiver resolves the participant's
    # supervision + watcher + recorder + coach; supervision + processor + recorder
    assert (hr.min_consumers, ecg.min_consumers) == (4, 3)
    assert p.node(HR_RECEIVER).extra == ("--ros-args", "-r", "__node:=hr_receiver")
    assert p.node(RECORDER).config.output == str(folder.bag)
    coach = p.node(COACH).config
    assert coach.interactive and coach.part_age == 45.0 and coach.hr_topic == topics.POLAR_H10_HR
    assert "use_sim_time:=true" in p.node(COACH).extra
    assert p.node(RECORDER).extra == () and p.node(PROCESSOR).extra == ()  # on wall time
    assert participant.model == "standard"
    vagal = plan(tmp_path, participant_model="vagal")[0].node(PARTICIPANT).config
    assert vagal.model == "vagal" and vagal.params.model == "vagal" and vagal.age == 33.0
    p, _ = plan(tmp_path, no_record=True, hr_source="ecg", log_data=True)
    hr = p.node(HR_RECEIVER).config
    assert hr.min_consumers == 2 and hr.log_data and hr.log_name.endswith("csv/hr.csv")
    assert p.coach.hr_topic == topics.POLAR_H10_ECG_HR and p.coach.min_valid_samples == 3


def test_the_coach_keeps_its_own_policy_unless_the_session_names_one(tmp_path: Path) -> None:
    conf = tmp_path / "coach.yaml"
    conf.write_text("policy: fuzzy\ncalib_time: 60\n")
    assert coach_config(SessionConfig(conf=str(conf))).policy == "fuzzy"
    assert coach_config(SessionConfig(conf=str(conf), policy="static")).policy == "static"
    assert coach_config(SessionConfig()).policy == "threshold"  # the packaged coach.yaml


def test_a_relative_routine_is_resolved_where_the_session_started(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "r.yaml").write_text((PACKAGED / "exercise_routine.yaml").read_text())
    monkeypatch.chdir(tmp_path)
    assert coach_config(SessionConfig(routine="r.yaml")).routine_file == str(tmp_path / "r.yaml")
    (tmp_path / "c.yaml").write_text("routine_file: r.yaml\n")
    assert coach_config(SessionConfig(conf="c.yaml")).routine_file == str(tmp_path / "r.yaml")


@pytest.mark.parametrize("coach_yaml,routine_edit,match", [
    ("zone_low: 0.8\nzone_high: 0.7\n", None, "zone bounds out of order"),
    ("calib_time: -1\n", None, "calib_time"),
    ("no_such_key: 1\n", None, "no_such_key"),
    ("", lambda r: r["phases"][1]["activities"][0].update(duration="soon"), "duration 'soon'"),
    ("", lambda r: r.update(surprise=True), "surprise"),
])
def test_an_invalid_coach_or_routine_is_found_before_anything_starts(tmp_path: Path, coach_yaml: str,
                                                                      routine_edit, match: str) -> None:
    conf = tmp_path / "coach.yaml"
    conf.write_text(coach_yaml)
    routine = yaml.safe_load((PACKAGED / "exercise_routine.yaml").read_text())
    if routine_edit is not None:
        routine_edit(routine)
    (tmp_path / "routine.yaml").write_text(yaml.safe_dump(routine))
    with pytest.raises(ConfigError, match=match):
        plan(tmp_path, conf=str(conf), routine=str(tmp_path / "routine.yaml"))
    assert not (tmp_path / "sessions").exists()


@pytest.mark.parametrize("options,match", [
    ({"speed": 0}, "speed"), ({"age": 150}, "age"), ({"conf": "/nonexistent/coach.yaml"}, "does not exist"),
    ({"hr_source": "ecg", "no_ecg": True}, "needs the ECG path"), ({"device_id": "SIM 1"}, "device_id"),
    ({"policy": "bogus"}, "policy"), ({"startup_timeout": -1}, "startup_timeout"),
    ({"participant_model": "athlete"}, "participant_model: unknown participant model 'athlete'; choose from "
                                       "standard, vagal, vo2drive"),
])
def test_bad_session_options_name_the_option(options: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        SessionConfig.from_mapping(options, "command line")


def test_the_streamers_play_on_the_session_clock_without_sound_card_or_screen(tmp_path: Path) -> None:
    p, _ = plan(tmp_path)
    audio, video = p.node(AUDIO), p.node(VIDEO)
    assert (audio.script, video.script) == ("audio_streamer", "video_streamer")
    assert audio.config.sink == "null" and video.config.display == "offscreen"
    assert video.config.preview_rate > 0
    assert "use_sim_time:=true" in audio.extra and "use_sim_time:=true" in video.extra
    assert p.node("mock_qt_robot").config.mirror_media is False  # the streamers' status says what played
    # The session starts only once the streamers (and the participant) listen: no request is lost.
    assert {(topics.AUDIO_REQUEST, AUDIO), (topics.VIDEO_REQUEST, VIDEO),
            (topics.AUDIO_STATUS, PARTICIPANT)} <= set(p.listeners)
    p, _ = plan(tmp_path, audio_sink="device")
    assert p.node(AUDIO).config.sink == "device"
    with pytest.raises(ConfigError, match="audio_sink"):
        plan(tmp_path, audio_sink="speaker")


def test_the_packaged_coach_asks_for_the_streamers_built_in_sources(tmp_path: Path) -> None:
    coach = coach_config(SessionConfig())
    music = [coach.audio_path.format(coach.audio_exercise_base.format(s)) for s in coach.audio_suffix]
    assert music == ["beat:110", "beat:115", "beat:120", "beat:125", "beat:130", "beat:135"]
    assert coach.audio_path.format(coach.audio_relaxing) == "relaxing"
    assert coach.video_path.format("marching") == "marching"
    # The thesis's one file per tempo still validates (through the session, as a lab would give it).
    conf = tmp_path / "coach.yaml"
    conf.write_text('audio_path: "./audio/{}.wav"\nvideo_path: "./video/{}.mp4"\n'
                    'audio_exercise_base: "exercise_{}"\n')
    files = coach_config(SessionConfig(conf=str(conf)))
    assert files.audio_path.format(files.audio_exercise_base.format("125")) == "./audio/exercise_125.wav"
    with_files, _ = plan(tmp_path, conf=str(conf))  # every node, the coach with its routine, validated
    # The audio streamer prepares the coach's music before the session: a new tempo never waits for its track.
    assert plan(tmp_path)[0].node(AUDIO).config.preload == [*music, "relaxing"]
    assert with_files.node(AUDIO).config.preload == [
        *(f"./audio/exercise_{s}.wav" for s in files.audio_suffix), "./audio/relaxing.wav"]


def test_a_polar_strap_replaces_the_simulated_participant(tmp_path: Path) -> None:
    p, _ = plan(tmp_path, source="polar:a1b2c3d4")
    names = [n.name for n in p.nodes]
    assert PARTICIPANT not in names and POLAR_STREAMER in names
    strap = p.node(POLAR_STREAMER)
    assert strap.script == "polar_streamer" and strap.config.device == "A1B2C3D4" and not strap.config.replay
    assert strap.config.streams == ["ecg", "hr", "rr"] and strap.extra == ()  # on wall time: LSL clock stamps
    assert p.device_id == "A1B2C3D4"
    assert p.node(HR_RECEIVER).config.input == "lsl:PolarH10/A1B2C3D4/HR"
    assert p.node(ECG_RECEIVER).config.input == "lsl:PolarH10/A1B2C3D4/ECG"
    assert all(node != PARTICIPANT for _topic, node in p.listeners)
    assert SessionConfig(source="polar:A1B2C3D4").speed == 1.0  # real time unless told otherwise
    p, _ = plan(tmp_path, source="polar:A1B2C3D4", no_ecg=True)
    assert p.node(POLAR_STREAMER).config.streams == ["hr", "rr"]


def test_a_replayed_capture_stands_in_for_the_strap(tmp_path: Path) -> None:
    capture = DATA / "polar" / "synthetic_h10.jsonl"
    p, _ = plan(tmp_path, source=f"polar-replay:{capture}")
    strap = p.node(POLAR_STREAMER)
    assert strap.config.replay == str(capture) and strap.config.device == ""
    assert p.device_id == "0A1B2C3D"  # from the capture's header: Polar H10 0A1B2C3D
    assert p.node(HR_RECEIVER).config.input == "lsl:PolarH10/0A1B2C3D/HR"
    headless = tmp_path / "no_id.jsonl"
    headless.write_text('{"format": "hri_physio.polar.capture", "version": 1, "device": {"name": "Strap"}}\n'
                        '{"t": 1.0, "op": "notify", "char": "hr", "hex": "1048db03c503"}\n')
    with pytest.raises(ConfigError, match="names no Polar device id"):
        plan(tmp_path, source=f"polar-replay:{headless}")
    (tmp_path / "broken.jsonl").write_text("not json\n")
    with pytest.raises(ConfigError, match=r"source polar-replay: .*not JSON"):
        plan(tmp_path, source=f"polar-replay:{tmp_path / 'broken.jsonl'}")


@pytest.mark.parametrize("options,message", [
    ({"source": "polar:A1B2C3D4", "speed": 30}, "speed must be 1"),
    ({"source": "polar:"}, "8-hex-digit id"),
    ({"source": "polar:not-an-id"}, "8-hex-digit id"),
    ({"source": "polar-replay:/nonexistent.jsonl"}, "does not exist"),
    ({"source": "lsl:x"}, "source must be simulated"),
    ({"source": "polar:A1B2C3D4", "device_id": "SIM1"}, "device_id"),
    ({"source": "polar:A1B2C3D4", "participant_model": "vagal"}, "the heart is the strap wearer's"),
])
def test_bad_sources_are_one_clear_error(options: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        SessionConfig.from_mapping(options, "command line")


@pytest.mark.parametrize(("speed", "frame"), [(1.0, 13), (0.5, 13), (30.0, 390), (60.0, 780)])
def test_ecg_frames_carry_a_tenth_of_a_wall_second_at_any_speed(tmp_path: Path, speed: float,
                                                                 frame: int) -> None:
    p, _ = plan(tmp_path, speed=speed)
    assert p.node(ECG_RECEIVER).config.output_frame == frame
    assert p.node(HR_RECEIVER).config.output_frame == 1


@pytest.mark.parametrize(("value", "message"), [(-1, "max_restarts: expected greater than or equal to 0"),
                                                (101, "max_restarts: expected less than or equal to 100")])
def test_the_restart_limit_is_checked(value: int, message: str) -> None:
    assert SessionConfig.from_mapping({}, "command line").max_restarts == 3
    with pytest.raises(ConfigError, match=message):
        SessionConfig.from_mapping({"max_restarts": value}, "command line")


def test_the_session_starts_once_the_recorder_records_every_publisher_from_its_start(tmp_path: Path) -> None:
    from hri_physio_bridge import topics

    p, _ = plan(tmp_path)
    capture = {topic for topic, node in p.listeners if node == "physio_recorder_capture"}
    robot_and_media = {topics.QT_COMMANDS, topics.QT_REPLIES, topics.QT_MOCK_EVENTS, topics.AUDIO_STATUS,
                       topics.VIDEO_STATUS, topics.VIDEO_PREVIEW, topics.AUDIO_CURRENT, topics.VIDEO_CURRENT}
    coach = {topics.COACH_EVENTS, topics.COACH_STATE, topics.SESSION_EVENTS, topics.PARTICIPANT_STATE}
    processor = {topics.POLAR_H10_ECG_HR, "/physio/polar_h10/ecg/status"}
    assert capture == robot_and_media | coach | processor
    p, _ = plan(tmp_path, no_ecg=True)
    assert {topic for topic, node in p.listeners if node == "physio_recorder_capture"} == (
        robot_and_media | coach)
    p, _ = plan(tmp_path, no_record=True)
    assert all(node != "physio_recorder_capture" for _topic, node in p.listeners)

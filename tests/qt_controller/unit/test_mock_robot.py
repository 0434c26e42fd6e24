"""The mock QT robot's behaviour as logic, on a hand-driven clock."""

from __future__ import annotations

from typing import Any

import pytest

from qt_controller.gestures import GestureLibrary, default_gesture_dir, parse_gesture_xml
from qt_controller.joint_limits import HOME
from qt_controller.mock_robot import MockConfig, MockRobot

SPC = 0.05  # seconds per character in these tests


class Clock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def make(policy: str = "interrupt", **cfg: Any) -> tuple[MockRobot, Clock]:
    clock = Clock()
    lib = GestureLibrary.from_dirs([default_gesture_dir()])
    lib.add(parse_gesture_xml(
        "<gesture><name>nod</name><joints><joint>HeadPitch</joint></joints><points>"
        '<point time="0">0</point><point time="1">20</point><point time="2">0</point></points></gesture>'))
    config = MockConfig.defaults(speech_seconds_per_char=SPC, gesture_busy_policy=policy, **cfg)
    return MockRobot(clock, lib, config=config), clock


def run_until(robot: MockRobot, clock: Clock, t: float, step: float = 1 / 30) -> list[dict[str, Any]]:
    """Advance like the node's 30 Hz timer; returns the events emitted on the way."""
    events = []
    while clock.t < t - 1e-9:
        clock.t = min(t, clock.t + step)
        robot.update()
        events += robot.drain_events()
    return events


def of(events: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [e for e in events if e["event"] == kind]


def test_speech_duration_is_proportional_to_length_and_queues() -> None:
    robot, clock = make()
    assert robot.say("a" * 20, "talkText").ok
    assert robot.say("b" * 40, "talkText").ok  # queued behind the first
    events = robot.drain_events() + run_until(robot, clock, 110.0)
    started = of(events, "speech_started")
    finished = of(events, "speech_finished")
    assert [e["text"][0] for e in started] == ["a", "b"]
    assert started[0]["t"] == 100.0 and started[0]["duration"] == pytest.approx(20 * SPC)
    assert finished[0]["t"] == pytest.approx(101.0)
    assert started[1]["t"] == pytest.approx(101.0)  # the second starts when the first ends
    assert finished[1]["t"] - started[1]["t"] == pytest.approx(2 * (finished[0]["t"] - started[0]["t"]))
    assert len(of(events, "speech_queued")) == 1
    assert robot.speech is None


def test_speech_speed_changes_duration_and_bad_config_is_refused() -> None:
    robot, _clock = make()
    assert robot.configure_speech("en-US", 150, 160).ok
    assert robot.speech_duration("x" * 10) == pytest.approx(10 * SPC * 80 / 160)
    refused = robot.configure_speech("en-US", 150, 0)
    assert not refused.ok and "speed" in refused.message
    assert (robot.speech_pitch, robot.speech_speed) == (150, 160)
    assert not robot.say("   ").ok
    kinds = [e["event"] for e in robot.drain_events()]
    assert kinds == ["speech_config", "speech_config_refused", "speech_refused"]


def test_emotion_is_shown_for_a_while_and_unknown_is_refused() -> None:
    robot, clock = make(emotion_seconds=2.0)
    assert robot.show_emotion("happy").ok
    assert robot.emotion == "QT/happy"
    refused = robot.show_emotion("grumpy")
    assert not refused.ok and "unknown emotion 'grumpy'" in refused.message
    assert robot.emotion == "QT/happy"  # a refused emotion does not change the face
    events = robot.drain_events() + run_until(robot, clock, 103.0)
    assert [e["event"] for e in events] == ["emotion_started", "emotion_refused", "emotion_finished"]
    assert events[2]["t"] == pytest.approx(102.0)
    assert robot.emotion is None


def test_new_emotion_replaces_the_shown_one() -> None:
    robot, clock = make(emotion_seconds=2.0)
    robot.show_emotion("happy")
    clock.t = 101.0
    robot.show_emotion("QT/sad")
    events = robot.drain_events()
    assert [(e["event"], e["name"]) for e in events] == [
        ("emotion_started", "QT/happy"), ("emotion_finished", "QT/happy"), ("emotion_started", "QT/sad")]
    assert events[1]["interrupted"] is True
    assert robot.emotion_end == pytest.approx(103.0)


@pytest.mark.parametrize("speed", [0.9, 1.0, 1.15])
def test_gesture_plays_for_recorded_duration_over_speed_and_moves_its_joints(speed: float) -> None:
    robot, clock = make()
    result = robot.play_gesture("marching", speed)
    assert result.ok and result.data["duration"] == pytest.approx(4.0 / speed)
    seen: list[float] = []
    events = robot.drain_events()
    while robot.playing is not None:
        events += run_until(robot, clock, clock.t + 1 / 30)
        seen.append(robot.positions["RightShoulderPitch"])
    started, finished = of(events, "gesture_started")[0], of(events, "gesture_finished")[0]
    assert finished["t"] - started["t"] == pytest.approx(4.0 / speed)
    assert finished["interrupted"] is False
    assert clock.t >= finished["t"]
    assert min(seen) < -120 and max(seen) > -60  # swung back and forth
    assert robot.positions["LeftElbowRoll"] == HOME["LeftElbowRoll"]  # back at rest
    assert robot.positions["HeadYaw"] == HOME["HeadYaw"]  # a joint it does not name never moved


def test_unknown_gesture_and_bad_speed_are_refused() -> None:
    robot, _ = make()
    bad = robot.play_gesture("moonwalk", 1.0)
    assert not bad.ok and "unknown gesture 'moonwalk'" in bad.message
    assert not robot.play_gesture("base", 0.0).ok
    assert [e["reason"] for e in robot.drain_events()] == ["unknown gesture", "bad speed"]
    assert robot.playing is None


def test_busy_gesture_interrupts_or_is_refused() -> None:
    robot, clock = make("interrupt")
    robot.play_gesture("marching", 1.0)
    run_until(robot, clock, 101.0)
    assert robot.play_gesture("nod", 1.0).ok
    events = robot.drain_events()
    assert events[0]["event"] == "gesture_finished" and events[0]["interrupted"] is True
    assert events[0]["duration"] == pytest.approx(1.0)
    assert robot.playing is not None and robot.playing.gesture.name == "nod"

    robot, clock = make("refuse")
    robot.play_gesture("marching", 1.0)
    run_until(robot, clock, 101.0)
    refused = robot.play_gesture("nod", 1.0)
    assert not refused.ok and "still playing" in refused.message
    assert robot.playing is not None and robot.playing.gesture.name == "marching"


def test_joint_command_moves_at_part_velocity_and_limits_refuse() -> None:
    robot, clock = make(max_joint_speed=100.0)
    assert robot.set_velocity(["head"], 50).ok  # 50 deg/s
    assert robot.command_part("head", [25, -10]).ok
    run_until(robot, clock, 100.2)
    assert robot.positions["HeadYaw"] == pytest.approx(10.0)  # 0.2 s at 50 deg/s
    assert robot.joint_velocities["HeadYaw"] == pytest.approx(50.0)
    assert robot.positions["HeadPitch"] == pytest.approx(-10.0)  # reached, then stopped
    run_until(robot, clock, 101.0)
    assert robot.positions["HeadYaw"] == pytest.approx(25.0)
    assert robot.joint_velocities["HeadYaw"] == 0.0
    refused = robot.command_part("head", [0, 80])
    assert not refused.ok and "HeadPitch 80 deg is outside" in refused.message
    assert not robot.command_part("head", [1]).ok
    assert not robot.set_velocity(["head"], 0).ok
    assert not robot.set_velocity(["tail"], 10).ok
    names, positions, velocities = robot.joint_state()
    assert len(names) == len(positions) == len(velocities) == 8
    assert positions[names.index("HeadYaw")] == pytest.approx(25.0)


def test_command_during_gesture_takes_effect_after_it() -> None:
    robot, clock = make(max_joint_speed=1000.0)
    robot.set_velocity(["head"], 100)
    robot.play_gesture("nod", 1.0)
    run_until(robot, clock, 100.5)
    robot.command_part("head", [30, 5])
    assert robot.drain_events()[-1]["deferred"] is True
    run_until(robot, clock, 101.0)
    assert robot.positions["HeadPitch"] == pytest.approx(20.0)  # the gesture still owns it
    assert robot.positions["HeadYaw"] == pytest.approx(30.0)  # not in the gesture: moved at once
    run_until(robot, clock, 103.0)
    assert robot.positions["HeadPitch"] == pytest.approx(5.0)


def test_volume_media_and_every_event_has_time() -> None:
    robot, clock = make()
    assert robot.set_volume(30).ok and robot.volume == 30
    assert not robot.set_volume(130).ok and robot.volume == 30
    clock.t = 100.5
    robot.media("audio", "calm.wav")
    events = robot.drain_events()
    assert [(e["event"], e["t"]) for e in events] == [("volume", 100.0), ("volume_refused", 100.0),
                                                      ("audio", 100.5)]


def test_clock_going_back_does_not_move_joints() -> None:
    robot, clock = make()
    robot.command_part("head", [20, 0])
    clock.t = 50.0  # e.g. sim time restarted
    robot.update()
    assert robot.positions["HeadYaw"] == 0.0


def test_bad_config_is_rejected() -> None:
    with pytest.raises(ValueError, match="gesture_busy_policy"):
        MockConfig.defaults(gesture_busy_policy="queue")
    with pytest.raises(ValueError, match="emotion_seconds"):
        MockConfig.defaults(emotion_seconds=0)
    with pytest.raises(ValueError, match="default_velocity"):
        MockConfig.defaults(default_velocity=150)

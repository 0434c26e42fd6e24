"""qt_controller -> mock_qt_robot over real rclpy, all on sim time driven by the test."""

from __future__ import annotations

import itertools
import statistics
import time

import pytest

from helpers import wait_until
from qt_controller.joint_limits import HOME

pytestmark = pytest.mark.ros


def test_speech_takes_time_proportional_to_length_and_queues(robot_side) -> None:
    p = robot_side.probe
    short, long = "Let us begin.", "Let us begin the exercise now, please!!"  # 13 and 39 characters
    r1, r2 = p.send(f"set speech {short}"), p.send(f"set speech {long}")
    assert r1["ok"] and r2["ok"], (r1, r2)
    assert "/qt_robot/behavior/talkText" in r1["message"]
    done = p.wait_event("speech_finished", text=long)
    first_start = p.events_of("speech_started", text=short)[0]
    first_end = p.events_of("speech_finished", text=short)[0]
    second_start = p.events_of("speech_started", text=long)[0]
    d1, d2 = first_end["t"] - first_start["t"], done["t"] - second_start["t"]
    assert d1 == pytest.approx(len(short) * 0.05)
    assert d2 / d1 == pytest.approx(len(long) / len(short))
    assert second_start["t"] == pytest.approx(first_end["t"])  # queued behind the first
    assert p.events_of("speech_queued", text=long)
    assert done["received"] >= done["t"]  # finished when sim time got there, not before


def test_speech_config_changes_speech_speed(robot_side) -> None:
    p = robot_side.probe
    r = p.send("set speechConfig 150 160")
    assert r["ok"], r
    event = p.wait_event("speech_config")
    assert (event["pitch"], event["speed"], event["language"]) == (150, 160, "en-US")
    assert p.send("set speech twenty characters long")["ok"]
    started = p.wait_event("speech_started")
    assert started["duration"] == pytest.approx(len("twenty characters long") * 0.05 * 80 / 160)
    assert started["pitch"] == 150


def test_emotion_shown_for_a_while_and_get_emotion(robot_side) -> None:
    p = robot_side.probe
    r = p.send("set emotion happy")
    assert r["ok"], r
    started = p.wait_event("emotion_started")
    assert started["name"] == "QT/happy"
    finished = p.wait_event("emotion_finished")
    assert finished["t"] - started["t"] == pytest.approx(2.0)
    got = p.send("get emotion")
    assert got["ok"] and got["data"]["emotion"] == "QT/happy"
    assert got["data"]["since"] == pytest.approx(r["t"], abs=0.5)  # sim time, not wall time


def test_gesture_duration_scales_with_speed_and_moves_named_joints(robot_side) -> None:
    p = robot_side.probe
    durations = {}
    for speed in (0.9, 1.0, 1.15):
        p.clear()
        r = p.send(f"set gesture marching {speed}")
        assert r["ok"], r
        started = p.wait_event("gesture_started", name="marching")
        finished = p.wait_event("gesture_finished", name="marching", timeout=60)
        assert finished["interrupted"] is False
        durations[speed] = finished["t"] - started["t"]
        assert durations[speed] == pytest.approx(4.0 / speed, abs=1e-6)
        assert finished["received"] >= finished["t"]
        wait_until(lambda f=finished: p.joints and p.joints[-1][0] > f["t"], 20,
                   "joint states after the gesture")
        with p.lock:
            during = [j for t, j in p.joints if started["t"] < t < finished["t"]]
            after = p.joints[-1][1]
        pitch = [j["RightShoulderPitch"] for j in during]
        assert min(pitch) < -110 and max(pitch) > -70, "the right arm swung during the gesture"
        assert all(j["HeadYaw"] == HOME["HeadYaw"] for j in during), "a joint it does not name stayed"
        assert after["RightShoulderPitch"] == pytest.approx(HOME["RightShoulderPitch"])
    assert durations[0.9] > durations[1.0] > durations[1.15]


def test_mock_timing_follows_ros_time_not_wall_time(robot_side) -> None:
    p = robot_side.probe
    clock = robot_side.clock
    clock.step = clock.period / 4  # sim time at (at most) a quarter of wall time
    r = p.send("set gesture test_blink 1.0")  # a 0.5 s gesture
    assert r["ok"], r
    started = p.wait_event("gesture_started", name="test_blink")
    wall0 = time.monotonic()
    finished = p.wait_event("gesture_finished", name="test_blink")
    # 0.5 s of ROS time, which took at least 2 s of wall time: a mock on wall time would have ended
    # the gesture after 0.5 s of wall time, at most 0.125 s of ROS time after its start.
    assert finished["t"] == pytest.approx(started["t"] + 0.5)
    assert time.monotonic() - wall0 >= 1.5


def test_joint_states_at_30_hz_of_ros_time(robot_side) -> None:
    p = robot_side.probe
    p.clear()
    wait_until(lambda: len(p.joints) >= 40, 30, "40 joint states")
    with p.lock:
        stamps = [t for t, _ in p.joints]
        names = set(p.joints[-1][1])
    assert names == set(HOME)
    assert all(t > 1000.0 for t in stamps)  # stamped with sim time
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    assert statistics.median(gaps) == pytest.approx(1 / 30, abs=0.005)


def test_joint_commands_move_joints_and_get_state(robot_side) -> None:
    p = robot_side.probe
    assert p.send("set velocity head 25")["ok"]  # 30 deg/s
    assert p.wait_event("velocity")["parts"] == ["head"]
    r = p.send("set state head 30 -10")
    assert r["ok"] and "/qt_robot/head_position/command" in r["message"], r
    command = p.wait_event("joint_command", part="head")
    assert command["degrees"] == [30.0, -10.0]

    def head() -> dict:
        reply = p.send("get state head")
        assert reply["ok"], reply
        return reply["data"]

    wait_until(lambda: head()["degrees"] == pytest.approx([30.0, -10.0]), 30, "the head to reach its target")
    data = head()
    assert data["joints"] == ["HeadYaw", "HeadPitch"] and data["stamp"] > 1000.0
    with p.lock:
        yaw = [j["HeadYaw"] for t, j in p.joints if t >= command["t"]]
    assert any(0 < y < 30 for y in yaw), "the head moved gradually, at its velocity"
    assert yaw == sorted(yaw)
    arm = p.send("set state leftarm 60 -40 -20")
    assert arm["ok"], arm
    wait_until(lambda: p.send("get state leftarm")["data"]["degrees"] == pytest.approx([60, -40, -20]),
               30, "the left arm to reach its target")
    velocity = p.send("get velocity head")
    assert velocity["ok"] and velocity["data"]["velocity"] == 25


def test_volume_and_media(robot_side) -> None:
    p = robot_side.probe
    assert p.send("set volume 35")["ok"]
    assert p.wait_event("volume")["volume"] == 35
    assert p.send("set audio calm.wav")["ok"]
    assert p.wait_event("audio")["name"] == "calm.wav"
    assert p.send("set video intro.mp4")["ok"]
    assert p.wait_event("video")["name"] == "intro.mp4"
    assert p.send("set audio calm2.wav")["ok"]
    # A streamer that starts now (a restart) finds the last request of each kind latched.
    from std_msgs.msg import String

    from hri_physio_bridge import topics
    from hri_physio_bridge.qos import latched_qos

    late: dict[str, list[str]] = {"audio": [], "video": []}
    for kind, topic in (("audio", topics.AUDIO_CURRENT), ("video", topics.VIDEO_CURRENT)):
        p.node.create_subscription(String, topic, lambda m, got=late[kind]: got.append(m.data), latched_qos())
    wanted = {"audio": ["calm2.wav"], "video": ["intro.mp4"]}
    wait_until(lambda: late == wanted, 30, lambda: f"latched: {late}")


@pytest.mark.parametrize(
    "line,fragment",
    [
        ("set gesture moonwalk 1.0", "unknown gesture 'moonwalk'"),
        ("set emotion grumpy", "unknown emotion 'grumpy'"),
        ("set state head 90 0", "HeadYaw 90 deg is outside its range"),
        ("set state rightarm 0 0", "takes 3 angle(s)"),
        ("set volume 101", "out of range"),
        ("set speechconfig 140", "takes 2 argument(s)"),
        ("wave please", "unknown command 'wave'"),
        ("set lights 1 2 3", "set_lights is not implemented by QtController"),
    ],
)
def test_failure_replies(robot_side, line: str, fragment: str) -> None:
    p = robot_side.probe
    r = p.send(line)
    assert r["ok"] is False and fragment in r["message"], r
    assert isinstance(r["t"], float) and r["t"] > 1000.0
    assert p.send("get emotion")["ok"]  # still answering after the failure


def test_gesture_refusal_is_recorded_by_the_mock(robot_side) -> None:
    p = robot_side.probe
    r = p.send("set gesture moonwalk")
    assert not r["ok"]
    refused = p.wait_event("gesture_refused")
    assert refused["name"] == "moonwalk" and refused["reason"] == "unknown gesture"

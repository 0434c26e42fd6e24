"""simulated_participant as a process: one-line configuration errors, and a person on LSL and ROS 2."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from helpers import NodeProcess, own_lines, resolve_lsl, wait_until
from hri_physio_bridge import topics
from hri_physio_coach.participant.perception import message_key, parse_receipt

pytestmark = [pytest.mark.ros, pytest.mark.lsl]

BIN = Path(sys.prefix) / "bin"


def run(script: str, *args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / script), *args], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("script", ["simulated_participant", "qt_physio_coach"])
@pytest.mark.parametrize(
    "args,names",
    [
        (["--ros-args", "-p", "seed:=abc"], "seed"),  # wrong type: text for an integer
        (["--ros-args", "-p", "seed:=1.5"], "seed"),
        (["--ros-args", "--params-file", "/nonexistent/params.yaml"], "/nonexistent/params.yaml"),
        (["--ros-args", "--params-file", "BROKEN"], "not valid YAML"),
        (["--ros-args", "-p"], "-p needs name:=value"),
        (["--no-such-option"], "--no-such-option"),
    ],
)
def test_bad_parameters_files_and_options_are_one_line(script: str, args: list[str], names: str,
                                                       tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("simulated_participant: {ros__parameters: [\n")
    args = [str(broken) if a == "BROKEN" else a for a in args]
    c = run(script, *args)
    assert c.returncode == 2, (c.stdout, c.stderr)
    assert "Traceback" not in c.stderr and "Traceback" not in c.stdout
    errors = [line for line in c.stderr.splitlines() if line.startswith(f"{script}: error: ")]
    assert len(errors) == 1 and names in errors[0], c.stderr


@pytest.mark.parametrize(
    "args,message",
    [
        (["--ros-args", "-p", "age:=abc"], "age: expected a valid number"),
        (["--ros-args", "-p", "age:=0.0"], "age: expected greater than 0"),
        (["--ros-args", "-p", "hr_rest:=200.0"], "need 30 <= hr_rest < hr_max_true"),
        (["--ros-args", "-p", "ecg_rate:=0.0"], "ecg_rate: expected greater than 0"),
        (["--ros-args", "-p", "agee:=30.0"], "unknown parameter(s) agee"),
        (["--age", "old"], "age: expected a valid number"),
    ],
)
def test_participant_configuration_errors(args: list[str], message: str) -> None:
    c = run("simulated_participant", *args)
    assert c.returncode == 2, (c.stdout, c.stderr)
    lines = own_lines(c.stderr)
    assert len(lines) == 1 and lines[0].startswith("simulated_participant: error: "), c.stderr
    assert message in lines[0]


def test_help_lists_every_option() -> None:
    c = run("simulated_participant", "--help")
    assert c.returncode == 0, c.stderr
    for flag in ("--age", "--hr-rest", "--tau-on", "--device-id", "--name-prefix", "--update-period",
                 "--conf"):
        assert flag in c.stdout, flag


def test_the_participant_streams_on_lsl_and_follows_the_robot(ros_context: Any, lsl_name: str) -> None:
    from rclpy.node import Node
    from std_msgs.msg import String

    from hri_physio_bridge.qos import command_qos, event_qos
    from hri_physio_bridge.ros_tools import ExecutorThread

    node = Node("participant_test_probe", context=ros_context)
    states: list[dict[str, Any]] = []
    lock = threading.Lock()

    def on_state(msg: String) -> None:
        with lock:
            states.append(json.loads(msg.data))

    receipts: list[tuple[str, int, float]] = []

    def on_receipt(msg: String) -> None:
        with lock:
            receipts.append(parse_receipt(msg.data))

    node.create_subscription(String, topics.PARTICIPANT_STATE, on_state, 100)
    node.create_subscription(String, topics.PARTICIPANT_HEARD, on_receipt, 100)
    commands = node.create_publisher(String, topics.QT_COMMANDS, command_qos())
    statuses = node.create_publisher(String, topics.AUDIO_STATUS, event_qos())
    events = node.create_publisher(String, topics.COACH_EVENTS, event_qos())
    spinner = ExecutorThread(node, context=ros_context)
    try:
        with NodeProcess("simulated_participant", "--name-prefix", lsl_name, "--seed", "4") as person:
            person.wait_for_output("model started")
            found = resolve_lsl(f"{lsl_name}/PolarH10/SIM0001/HR")
            assert found, person.output
            assert (found[0].type(), found[0].nominal_srate()) == ("HR", 1.0)
            wait_until(lambda: states, 30, "the participant's state")
            assert states[-1]["activity"] == "rest"
            wait_until(lambda: commands.get_subscription_count() >= 1, 30, "the participant on the commands")
            commands.publish(String(data="set gesture marching 1.05"))
            commands.publish(String(data="set audio ./audio/exercise_130.wav"))

            def latest() -> dict[str, Any]:
                with lock:
                    return states[-1]

            wait_until(lambda: (latest()["activity"], latest()["tempo_bpm"]) == ("marching", 130.0), 30,
                       lambda: f"marching at 130 BPM; last state {latest()}")
            assert latest()["gesture_speed"] == 1.05
            # Each command taken in is confirmed (the launcher's clock guard waits for it), also a status
            # the person cannot read: the guard must not wait for it forever.
            wait_until(lambda: statuses.get_subscription_count() >= 1, 30, "the participant on the status")
            statuses.publish(String(data="not json"))
            wait_until(lambda: len(receipts) >= 3, 30, lambda: f"three receipts; got {receipts}")
            with lock:
                assert [(topic, key) for topic, key, _t in receipts] == [
                    (topics.QT_COMMANDS, message_key("set gesture marching 1.05")),
                    (topics.QT_COMMANDS, message_key("set audio ./audio/exercise_130.wav")),
                    (topics.AUDIO_STATUS, message_key("not json"))]
                assert all(t > 0 for _topic, _key, t in receipts)  # taken in at the participant's ROS time
            # The coach's session start: the seeded model takes over on a whole second from then.
            assert latest()["session_model_t0"] is None
            start = latest()["t"]
            wait_until(lambda: events.get_subscription_count() >= 1, 30, "the participant on the events")
            events.publish(String(data=json.dumps({"t": start, "event": "session_start"})))
            wait_until(lambda: latest()["session_model_t0"] is not None, 30,
                       lambda: f"the session model; last state {latest()}")
            assert start <= latest()["session_model_t0"] <= start + 10.0
            assert latest()["activity"] == "marching"  # the person keeps doing what the robot asked
            assert person.stop(signal.SIGTERM) == 0, person.output
        assert "Traceback" not in person.output
    finally:
        spinner.close()
        node.destroy_node()

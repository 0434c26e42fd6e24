"""RobotManager dispatch and the RobotInterface defaults, with a recording robot (no ROS)."""

from __future__ import annotations

import queue
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import pytest

from qt_controller.commands import HELP_TEXT
from qt_controller.manager import Reply, RobotManager
from qt_controller.robot_interface import Outcome, RobotInterface


class MinimalRobot(RobotInterface):
    """Implements only what is mandatory: everything else must answer "not implemented"."""

    def configure(self, options: Mapping[str, Any]) -> Outcome:
        return Outcome.success()


class RecordingRobot(RobotInterface):
    """Records every call; fails a call whose first argument is 'refuse'."""

    def __init__(self) -> None:
        super().__init__("Recorder")
        self.calls: list[tuple[str, tuple[Any, ...]]] = []
        self.commands: queue.Queue[str] = queue.Queue()

    def configure(self, options: Mapping[str, Any]) -> Outcome:
        return Outcome.success()

    def _record(self, name: str, *args: Any) -> Outcome:
        self.calls.append((name, args))
        if args and args[0] == "refuse":
            return Outcome.failure(f"{name} refused")
        return Outcome.success(f"{name} done", args=list(args))

    def set_speech(self, text: str) -> Outcome:
        return self._record("set_speech", text)

    def set_speech_config(self, pitch: int, speed: int) -> Outcome:
        return self._record("set_speech_config", pitch, speed)

    def set_emotion(self, name: str) -> Outcome:
        return self._record("set_emotion", name)

    def set_gesture(self, name: str, speed: float) -> Outcome:
        if name == "explode":
            raise RuntimeError("driver crashed")
        return self._record("set_gesture", name, speed)

    def set_audio(self, file: str) -> Outcome:
        return self._record("set_audio", file)

    def set_video(self, file: str) -> Outcome:
        return self._record("set_video", file)

    def set_volume(self, percent: int) -> Outcome:
        return self._record("set_volume", percent)

    def set_peripheral_state(self, part: str, degrees: Sequence[float]) -> Outcome:
        return self._record("set_peripheral_state", part, tuple(degrees))

    def set_peripheral_velocity(self, part: str, percent: float) -> Outcome:
        return self._record("set_peripheral_velocity", part, percent)

    def get_peripheral_state(self, part: str) -> Outcome:
        return self._record("get_peripheral_state", part)

    def get_peripheral_velocity(self, part: str) -> Outcome:
        return self._record("get_peripheral_velocity", part)

    def get_emotion(self) -> Outcome:
        return self._record("get_emotion")

    def get_robot_command(self, timeout: float | None = None) -> str | None:
        try:
            return self.commands.get(timeout=timeout)
        except queue.Empty:
            return None


@pytest.mark.parametrize(
    "line,call",
    [
        ("set speech Hi there", ("set_speech", ("Hi there",))),
        ("set speechconfig 150 90", ("set_speech_config", (150, 90))),
        ("set emotion happy", ("set_emotion", ("happy",))),
        ("set gesture marching 1.05", ("set_gesture", ("marching", 1.05))),
        ("set audio a.wav", ("set_audio", ("a.wav",))),
        ("set video b.mp4", ("set_video", ("b.mp4",))),
        ("set volume 50", ("set_volume", (50,))),
        ("set state head 1 2", ("set_peripheral_state", ("head", (1.0, 2.0)))),
        ("set velocity leftarm 30", ("set_peripheral_velocity", ("leftarm", 30.0))),
        ("get state rightarm", ("get_peripheral_state", ("rightarm",))),
        ("get velocity head", ("get_peripheral_velocity", ("head",))),
        ("get emotion", ("get_emotion", ())),
    ],
)
def test_each_command_reaches_its_robot_method(line: str, call: tuple[str, tuple[Any, ...]]) -> None:
    robot = RecordingRobot()
    reply = RobotManager(robot).handle(line)
    assert robot.calls == [call]
    assert reply.ok and reply.command == line and reply.message == f"{call[0]} done"
    assert reply.data == {"args": list(call[1])}


def test_refusal_and_parse_errors_are_error_replies_without_calls() -> None:
    robot = RecordingRobot()
    manager = RobotManager(robot)
    refused = manager.handle("set emotion refuse")
    assert not refused.ok and refused.message == "set_emotion refused"
    bad = manager.handle("set volume 300")
    assert not bad.ok and bad.message.startswith("bad command:") and "out of range" in bad.message
    assert robot.calls == [("set_emotion", ("refuse",))]


def test_robot_exception_becomes_error_reply() -> None:
    reply = RobotManager(RecordingRobot()).handle("set gesture explode 1.0")
    assert not reply.ok
    assert "set gesture failed: RuntimeError: driver crashed" in reply.message


def test_defaults_answer_not_implemented_by_robot() -> None:
    manager = RobotManager(MinimalRobot("Minimal"))
    for line, method in [
        ("set speech hi", "set_speech"), ("set speechconfig 140 80", "set_speech_config"),
        ("set emotion happy", "set_emotion"), ("set gesture base", "set_gesture"),
        ("set audio a.wav", "set_audio"), ("set video a.mp4", "set_video"), ("set volume 3", "set_volume"),
        ("set state head 0 0", "set_peripheral_state"), ("set velocity head 5", "set_peripheral_velocity"),
        ("set vibration 5 1", "set_vibration"), ("set lights 1 2 3", "set_lights"),
        ("get state head", "get_peripheral_state"), ("get velocity head", "get_peripheral_velocity"),
        ("get emotion", "get_emotion"),
    ]:
        reply = manager.handle(line)
        assert not reply.ok
        assert reply.message == f"{method} is not implemented by Minimal"
    assert MinimalRobot().get_robot_command(timeout=0) is None


def test_help_and_exit() -> None:
    manager = RobotManager(RecordingRobot())
    assert manager.handle("help") == Reply(True, "help", HELP_TEXT)
    assert not manager.exit_requested
    assert manager.handle("exit").ok
    assert manager.exit_requested


def test_reply_json_shape() -> None:
    assert Reply(False, "x", "bad").as_dict(1.5) == {"t": 1.5, "ok": False, "command": "x", "message": "bad"}
    reply = Reply(True, "get emotion", "m", {"emotion": "QT/sad"})
    assert reply.as_dict(2.0)["data"] == {"emotion": "QT/sad"}


def test_run_loop_answers_queued_commands_until_exit() -> None:
    robot = RecordingRobot()
    manager = RobotManager(robot)
    replies: list[Reply] = []
    for line in ("set speech one", "nonsense", "set volume 7", "exit", "set speech never"):
        robot.commands.put(line)
    stop = threading.Event()
    worker = threading.Thread(target=manager.run, args=(replies.append, stop, 0.01))
    worker.start()
    worker.join(5)
    assert not worker.is_alive()
    assert [r.ok for r in replies] == [True, False, True, True]
    assert [r.command for r in replies] == ["set speech one", "nonsense", "set volume 7", "exit"]
    assert robot.commands.get_nowait() == "set speech never"  # nothing after exit is handled


def test_run_loop_stops_on_event() -> None:
    robot = RecordingRobot()
    stop = threading.Event()
    worker = threading.Thread(target=RobotManager(robot).run, args=(lambda r: None, stop, 0.01))
    worker.start()
    stop.set()
    worker.join(5)
    assert not worker.is_alive()

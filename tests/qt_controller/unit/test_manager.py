"""RobotManager dispatch and the RobotInterface defaults, with a recording robot (no ROS)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import pytest

from helpers import wait_until
from qt_controller.commands import HELP_TEXT
from qt_controller.manager import (
    LOG_LINES_PER_SECOND,
    OVERLOADED,
    REMOTE_EXIT_DISABLED,
    STOPPING,
    Reply,
    RobotManager,
)
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


def run_in_thread(manager: RobotManager, replies: list[Reply], stop: threading.Event) -> threading.Thread:
    worker = threading.Thread(target=manager.run, args=(replies.append, stop, 0.01))
    worker.start()
    return worker


def test_run_loop_answers_queued_commands_until_exit() -> None:
    robot = RecordingRobot()
    manager = RobotManager(robot)
    replies: list[Reply] = []
    for line in ("set speech one", "nonsense", "set volume 7", "exit", "set speech never"):
        assert manager.submit(line, remote=False) is None
    worker = run_in_thread(manager, replies, threading.Event())
    worker.join(5)
    assert not worker.is_alive()
    assert [r.command for r in replies] == ["set speech one", "nonsense", "set volume 7", "exit",
                                            "set speech never"]
    assert [r.ok for r in replies] == [True, False, True, True, False]
    assert replies[-1].data["error"] == STOPPING  # answered, not executed
    assert ("set_speech", ("never",)) not in robot.calls
    late = manager.submit("set speech later", remote=True)  # after the loop ended: answered at once
    assert late is not None and not late.ok and late.data["error"] == STOPPING


def test_run_loop_stops_on_event() -> None:
    robot = RecordingRobot()
    stop = threading.Event()
    worker = threading.Thread(target=RobotManager(robot).run, args=(lambda r: None, stop, 0.01))
    worker.start()
    stop.set()
    worker.join(5)
    assert not worker.is_alive()


def test_without_a_poll_the_loop_waits_for_lines_and_a_stop_request_ends_it() -> None:
    """The controller's worker waits for the next line (no polling); request_stop wakes it at once."""
    robot = RecordingRobot()
    manager = RobotManager(robot)
    replies: list[Reply] = []
    stop = threading.Event()  # never set: only the request ends the loop
    worker = threading.Thread(target=manager.run, args=(replies.append, stop, None))
    worker.start()
    manager.submit("set volume 7", remote=True)
    wait_until(lambda: len(replies) == 1, 5, "the reply to a line submitted while the loop waits")
    assert worker.is_alive()
    manager.request_stop()
    worker.join(5)
    assert not worker.is_alive()
    late = manager.submit("set volume 8", remote=True)
    assert late is not None and late.data["error"] == STOPPING
    assert [c for c in robot.calls if c[0] == "set_volume"] == [("set_volume", (7,))]


def test_a_stop_request_before_the_loop_starts_ends_it_at_once() -> None:
    manager = RobotManager(RecordingRobot())
    manager.request_stop()
    worker = threading.Thread(target=manager.run, args=(lambda r: None, threading.Event(), None))
    worker.start()
    worker.join(5)
    assert not worker.is_alive()


def test_without_a_poll_a_burst_summary_still_comes_when_the_lines_stop() -> None:
    log = logging.getLogger("test.manager.burst_no_poll")
    log.propagate = False
    log.setLevel(logging.DEBUG)
    handler = LogLines()
    log.handlers[:] = [handler]
    manager = RobotManager(RecordingRobot(), log, clock=lambda: 0.0)
    for i in range(LOG_LINES_PER_SECOND + 5):
        manager.submit(f"set volume {i}", remote=True)
    worker = threading.Thread(target=manager.run, args=(lambda r: None, threading.Event(), None))
    worker.start()
    wait_until(lambda: len(handler.lines) == LOG_LINES_PER_SECOND + 1, 10, "the burst summary")
    assert handler.lines[-1].startswith("5 more command lines in a burst: 5 ok")
    manager.request_stop()
    worker.join(5)
    assert not worker.is_alive()


def test_exit_from_the_topic_is_refused_unless_allowed() -> None:
    manager = RobotManager(RecordingRobot())
    refused = manager.handle("exit", remote=True)
    assert not refused.ok and refused.data["error"] == REMOTE_EXIT_DISABLED
    assert "allow_remote_exit" in refused.message
    assert not manager.exit_requested
    assert manager.handle("exit", remote=False).ok and manager.exit_requested  # the console may

    allowed = RobotManager(RecordingRobot(), allow_remote_exit=True)
    assert allowed.handle("exit", remote=True).ok and allowed.exit_requested

    replies: list[Reply] = []
    queued = RobotManager(RecordingRobot())
    for line in ("exit", "set volume 3"):
        queued.submit(line, remote=True)
    stop = threading.Event()
    worker = run_in_thread(queued, replies, stop)
    wait_until(lambda: len(replies) == 2, 10, "two replies")
    assert worker.is_alive(), "a remote exit did not stop the loop"
    assert [(r.command, r.ok) for r in replies] == [("exit", False), ("set volume 3", True)]
    stop.set()
    worker.join(5)


def test_every_line_of_a_burst_gets_one_reply_in_order() -> None:
    robot = RecordingRobot()
    manager = RobotManager(robot)
    replies: list[Reply] = []
    stop = threading.Event()
    worker = run_in_thread(manager, replies, stop)
    lines = [f"set volume {i % 101}" if i % 3 else f"set volume {101 + i}" for i in range(10_000)]
    for line in lines:  # as fast as a subscription callback can take them
        assert manager.submit(line, remote=True) is None
    wait_until(lambda: len(replies) == len(lines), 60, "a reply to every line")
    stop.set()
    worker.join(5)
    assert [r.command for r in replies] == lines
    assert [r.ok for r in replies] == [bool(i % 3) for i in range(10_000)]
    assert [args[0] for _, args in robot.calls] == [i % 101 for i in range(10_000) if i % 3]


def test_a_full_queue_answers_overloaded_never_silence() -> None:
    manager = RobotManager(RecordingRobot(), queue_limit=3)
    immediate = [manager.submit(f"set volume {i}", remote=True) for i in range(5)]
    assert immediate[:3] == [None, None, None]
    for i, reply in enumerate(immediate[3:], start=3):
        assert reply is not None and not reply.ok and reply.command == f"set volume {i}"
        assert reply.data == {"error": OVERLOADED, "waiting": 3}
    assert manager.overloaded == 2 and manager.waiting == 3
    replies: list[Reply] = []
    stop = threading.Event()
    worker = run_in_thread(manager, replies, stop)
    wait_until(lambda: len(replies) == 3, 10, "three replies")
    stop.set()
    worker.join(5)
    assert [r.command for r in replies] == ["set volume 0", "set volume 1", "set volume 2"]
    assert all(r.ok for r in replies)


class LogLines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def test_a_burst_is_logged_as_a_summary_not_line_by_line() -> None:
    log = logging.getLogger("test.manager.burst")
    log.propagate = False
    log.setLevel(logging.DEBUG)
    handler = LogLines()
    log.handlers[:] = [handler]
    now = [0.0]
    manager = RobotManager(RecordingRobot(), log, clock=lambda: now[0])
    for i in range(LOG_LINES_PER_SECOND + 30):
        manager.submit(f"set volume {i % 101}", remote=True)
    replies: list[Reply] = []
    stop = threading.Event()
    worker = run_in_thread(manager, replies, stop)
    wait_until(lambda: len(handler.lines) == LOG_LINES_PER_SECOND + 1, 10, "the burst summary")
    assert len(replies) == LOG_LINES_PER_SECOND + 30  # every line answered
    assert all("-> ok" in line for line in handler.lines[:LOG_LINES_PER_SECOND])
    assert handler.lines[-1].startswith("30 more command lines in a burst: 30 ok, 0 error(s)")
    now[0] = 2.0  # a second later, one line is logged on its own again
    manager.submit("set volume 300", remote=True)
    wait_until(lambda: len(handler.lines) == LOG_LINES_PER_SECOND + 2, 10, "the next line")
    assert handler.lines[-1].startswith("'set volume 300' -> error")
    stop.set()
    worker.join(5)

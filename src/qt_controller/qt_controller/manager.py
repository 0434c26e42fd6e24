"""RobotManager: queue command lines, parse them and dispatch them to a RobotInterface.

Every line gets exactly one :class:`Reply`, in the order the lines came: parse errors,
refusals and even unexpected exceptions from a robot implementation become error replies,
never a crash. Lines are taken into the manager's own queue at once (:meth:`RobotManager.submit`,
from the subscription callback or the console) and handled one at a time by :meth:`RobotManager.run`,
so a burst is never lost while the robot is busy. The queue is bounded
(``queue_limit``): a line beyond it is not executed and gets an ``overloaded`` error reply
at once, never silence. Lines still queued when the manager stops get a ``stopping`` reply.
Each line is logged with its result, up to LOG_LINES_PER_SECOND; a faster burst is logged as
a summary (its replies are on the reply topic, one per line).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from qt_controller import commands as c
from qt_controller.robot_interface import Outcome, RobotInterface

#: Lines logged one by one per second; beyond that a burst is logged as one summary (every line is
#: still answered on the reply topic; rclpy's logger costs milliseconds per line, which would
#: otherwise slow a burst to a few hundred lines a second).
LOG_LINES_PER_SECOND = 20
#: A long burst gets a summary line at least this often.
BURST_SUMMARY_PERIOD = 5.0
#: A burst ends (its summary is logged) when no line came for this long.
BURST_GAP = 0.1

#: Machine-readable ``data["error"]`` codes of replies the manager makes itself.
OVERLOADED = "overloaded"
REMOTE_EXIT_DISABLED = "remote_exit_disabled"
STOPPING = "stopping"

REMOTE_EXIT_MESSAGE = (
    "exit from the command topic is disabled (anyone on the ROS graph could stop the controller); "
    "start qt_controller with --allow-remote-exit true (or --ros-args -p allow_remote_exit:=true), "
    "or type exit on its --interactive console"
)


@dataclass(frozen=True)
class Reply:
    """The answer to one command line (published as JSON on /QtController/output)."""

    ok: bool
    command: str
    message: str
    data: Mapping[str, Any] = field(default_factory=dict)

    def as_dict(self, t: float) -> dict[str, Any]:
        out: dict[str, Any] = {"t": t, "ok": self.ok, "command": self.command, "message": self.message}
        if self.data:
            out["data"] = dict(self.data)
        return out


@dataclass(frozen=True)
class CommandLine:
    """A queued line and where it came from: the ROS topic (``remote``) or the local console."""

    text: str
    remote: bool


class RobotManager:
    """Turns command text into robot calls (the seed's RobotManager loop)."""

    def __init__(self, robot: RobotInterface, log: logging.Logger | None = None, *,
                 allow_remote_exit: bool = False, queue_limit: int = 100_000,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if queue_limit < 1:
            raise ValueError(f"queue_limit must be >= 1, got {queue_limit}")
        self.robot = robot
        self.log = log or logging.getLogger("hri_physio.robot_manager")
        self.allow_remote_exit = allow_remote_exit
        self.queue_limit = queue_limit
        self.exit_requested = False
        self.overloaded = 0  # lines refused because the queue was full
        self._queue: deque[CommandLine] = deque()
        self._ready = threading.Condition()
        self._closed = False  # run() has ended: new lines are answered "stopping" at once
        self._stop_requested = False
        self._clock = clock
        self._logged: deque[float] = deque()  # when the last lines were logged one by one
        self._burst: _BurstLog | None = None

    # ------------------------------------------------------------------ the queue
    def submit(self, line: str, *, remote: bool) -> Reply | None:
        """Queue one line (never blocks). Returns None, or the reply to send at once when the line
        cannot be queued (``overloaded``, or ``stopping`` once :meth:`run` has ended)."""
        text = line.strip()
        with self._ready:
            if self._closed:
                return _stopping(text)
            waiting = len(self._queue)
            if waiting < self.queue_limit:
                self._queue.append(CommandLine(line, remote))
                self._ready.notify()
                return None
            self.overloaded += 1
        self.log.warning(f"overloaded: {waiting} command lines waiting; refused {text!r}")
        return Reply(False, text, f"overloaded: {waiting} command lines are waiting to be handled "
                     f"(command_queue_limit {self.queue_limit}); this line was not executed",
                     {"error": OVERLOADED, "waiting": waiting})

    @property
    def waiting(self) -> int:
        with self._ready:
            return len(self._queue)

    def next_line(self, timeout: float | None) -> CommandLine | None:
        """The oldest queued line, waiting up to ``timeout`` s (None: until a line or a stop request)
        for one (None: none came)."""
        with self._ready:
            if not self._queue and not self._stop_requested:
                self._ready.wait(timeout)
            return self._queue.popleft() if self._queue else None

    # ------------------------------------------------------------------ one line
    def handle(self, line: str, *, remote: bool = False) -> Reply:
        """Parse and execute one command line (``remote``: it came from the ROS topic)."""
        text = line.strip() if isinstance(line, str) else line
        try:
            command = c.parse_command(text)
        except c.ParseError as exc:
            return Reply(False, str(text), f"bad command: {exc}")
        if isinstance(command, c.Exit) and remote and not self.allow_remote_exit:
            return Reply(False, text, REMOTE_EXIT_MESSAGE, {"error": REMOTE_EXIT_DISABLED})
        name = c.command_name(command)
        try:
            outcome = self.dispatch(command)
        except Exception as exc:  # a robot bug must not take the controller down
            self.log.exception(f"{name} failed inside {self.robot.name}")
            return Reply(False, text, f"{name} failed: {type(exc).__name__}: {exc}")
        message = outcome.message or (f"{name}: done" if outcome.ok else f"{name}: failed")
        return Reply(outcome.ok, text, message, outcome.data)

    def dispatch(self, command: c.Command) -> Outcome:
        r = self.robot
        match command:
            case c.SetSpeech(text):
                return r.set_speech(text)
            case c.SetSpeechConfig(pitch, speed):
                return r.set_speech_config(pitch, speed)
            case c.SetEmotion(name):
                return r.set_emotion(name)
            case c.SetGesture(name, speed):
                return r.set_gesture(name, speed)
            case c.SetAudio(file):
                return r.set_audio(file)
            case c.SetVideo(file):
                return r.set_video(file)
            case c.SetVolume(percent):
                return r.set_volume(percent)
            case c.SetState(part, degrees):
                return r.set_peripheral_state(part, degrees)
            case c.SetVelocity(part, percent):
                return r.set_peripheral_velocity(part, percent)
            case c.SetVibration(intensity, seconds):
                return r.set_vibration(intensity, seconds)
            case c.SetLights(red, green, blue):
                return r.set_lights(red, green, blue)
            case c.GetState(part):
                return r.get_peripheral_state(part)
            case c.GetVelocity(part):
                return r.get_peripheral_velocity(part)
            case c.GetEmotion():
                return r.get_emotion()
            case c.Help():
                return Outcome.success(c.HELP_TEXT)
            case c.Exit():
                self.exit_requested = True
                return Outcome.success("exiting")
        raise TypeError(f"no dispatch for {command!r}")

    # ------------------------------------------------------------------ the loop
    def request_stop(self) -> None:
        """End :meth:`run` soon (from any thread): it wakes at once, as for a new line."""
        with self._ready:
            self._stop_requested = True
            self._ready.notify_all()

    def run(self, reply: Callable[[Reply], None], stop: threading.Event, poll: float | None = None) -> None:
        """Handle queued lines in order until ``exit``, :meth:`request_stop` or ``stop``; then answer
        what is left ``stopping``.

        Between lines it waits for the next one; ``stop`` is looked at every ``poll`` seconds (None:
        only when a line comes or :meth:`request_stop` wakes it). A burst's summary is logged once no
        line came for BURST_GAP seconds.
        """
        while not stop.is_set() and not self.exit_requested and not self._stop_requested:
            wait = poll if self._burst is None else min(poll or BURST_GAP, BURST_GAP)
            item = self.next_line(wait)
            if item is None:
                self._end_burst()
                continue
            result = self.handle(item.text, remote=item.remote)
            self._log(result)
            reply(result)
        self._end_burst()
        with self._ready:
            self._closed = True
            left = list(self._queue)
            self._queue.clear()
        for item in left:
            reply(_stopping(item.text.strip()))

    def _log(self, result: Reply) -> None:
        """One line per command, up to LOG_LINES_PER_SECOND; beyond that one summary per burst."""
        now = self._clock()
        while self._logged and self._logged[0] <= now - 1.0:
            self._logged.popleft()
        if self._burst is None and len(self._logged) < LOG_LINES_PER_SECOND:
            self._logged.append(now)
            level, verdict = (logging.INFO, "ok") if result.ok else (logging.WARNING, "error")
            self.log.log(level, f"{result.command!r} -> {verdict}: {_first_line(result)}")
            return
        if self._burst is None:
            self._burst = _BurstLog(started=now)
        self._burst.add(result)
        if now - self._burst.started >= BURST_SUMMARY_PERIOD:
            self._end_burst()

    def _end_burst(self) -> None:
        """Log the summary of the burst in progress (when the queue ran dry, periodically, at the end)."""
        burst, self._burst = self._burst, None
        if burst is not None:
            self.log.log(logging.WARNING if burst.errors else logging.INFO, burst.summary())


@dataclass
class _BurstLog:
    started: float
    lines: int = 0
    errors: int = 0
    first_error: str = ""

    def add(self, result: Reply) -> None:
        self.lines += 1
        if not result.ok:
            self.errors += 1
            self.first_error = self.first_error or f"{result.command!r} -> {_first_line(result)}"

    def summary(self) -> str:
        text = (f"{self.lines} more command lines in a burst: {self.lines - self.errors} ok, "
                f"{self.errors} error(s), each answered on the reply topic")
        return text + (f"; first error: {self.first_error}" if self.errors else "")


def _first_line(result: Reply) -> str:
    return result.message.splitlines()[0] if result.message else ""


def _stopping(text: str) -> Reply:
    return Reply(False, text, "not executed: qt_controller is stopping", {"error": STOPPING})

"""RobotManager: parse command lines and dispatch them to a RobotInterface.

Every line gets exactly one :class:`Reply`; parse errors, refusals and even unexpected
exceptions from a robot implementation become error replies, never a crash.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from qt_controller import commands as c
from qt_controller.robot_interface import Outcome, RobotInterface


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


class RobotManager:
    """Turns command text into robot calls (the seed's RobotManager loop)."""

    def __init__(self, robot: RobotInterface, log: logging.Logger | None = None) -> None:
        self.robot = robot
        self.log = log or logging.getLogger("hri_physio.robot_manager")
        self.exit_requested = False

    def handle(self, line: str) -> Reply:
        """Parse and execute one command line."""
        text = line.strip() if isinstance(line, str) else line
        try:
            command = c.parse_command(text)
        except c.ParseError as exc:
            return Reply(False, str(text), f"bad command: {exc}")
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

    def run(self, reply: Callable[[Reply], None], stop: threading.Event, poll: float = 0.1) -> None:
        """Handle the robot's commands (``get_robot_command``) until ``exit`` or ``stop``."""
        while not stop.is_set() and not self.exit_requested:
            line = self.robot.get_robot_command(timeout=poll)
            if line is None:
                continue
            result = self.handle(line)
            level = logging.INFO if result.ok else logging.WARNING
            self.log.log(
                level,
                f"{line.strip()!r} -> {'ok' if result.ok else 'error'}: "
                f"{result.message.splitlines()[0] if result.message else ''}",
            )
            reply(result)

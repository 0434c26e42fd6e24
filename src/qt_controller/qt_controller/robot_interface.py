"""The abstract robot: the seed's six feedback modalities, one method each.

Feedback modalities: screen (video), speech and sounds (speech, speech configuration,
volume, audio file), vibration, lights, facial expression (emotion), body language and
movement (peripheral state and velocity of head/arms, gestures with a speed).

Only :meth:`RobotInterface.configure` is mandatory. Every other method has a default that
logs "<method> is not implemented by <robot>" and fails, so a robot implements what it has
and the command protocol answers the rest with a clear error.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Outcome:
    """Success or failure of one robot action, with a message a researcher can act on."""

    ok: bool
    message: str = ""
    data: Mapping[str, Any] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.ok

    @classmethod
    def success(cls, message: str = "", **data: Any) -> Outcome:
        return cls(True, message, data)

    @classmethod
    def failure(cls, message: str) -> Outcome:
        return cls(False, message)


class RobotInterface(ABC):
    """What the robot manager can ask of any robot."""

    def __init__(self, name: str | None = None, log: logging.Logger | None = None) -> None:
        self.name = name or type(self).__name__
        self.log = log or logging.getLogger(f"hri_physio.{self.name}")

    def not_implemented(self, method: str) -> Outcome:
        message = f"{method} is not implemented by {self.name}"
        self.log.warning(message)
        return Outcome.failure(message)

    @abstractmethod
    def configure(self, options: Mapping[str, Any]) -> Outcome:
        """Prepare the robot from its options; must be called before any other method."""

    # Screen-based feedback.
    def set_video(self, file: str) -> Outcome:
        return self.not_implemented("set_video")

    # Speech and sounds.
    def set_speech(self, text: str) -> Outcome:
        return self.not_implemented("set_speech")

    def set_speech_config(self, pitch: int, speed: int) -> Outcome:
        return self.not_implemented("set_speech_config")

    def set_volume(self, percent: int) -> Outcome:
        return self.not_implemented("set_volume")

    def set_audio(self, file: str) -> Outcome:
        return self.not_implemented("set_audio")

    # Vibration.
    def set_vibration(self, intensity: int, seconds: float) -> Outcome:
        return self.not_implemented("set_vibration")

    # Lights.
    def set_lights(self, red: int, green: int, blue: int) -> Outcome:
        return self.not_implemented("set_lights")

    # Facial expression.
    def set_emotion(self, name: str) -> Outcome:
        return self.not_implemented("set_emotion")

    # Body language and movement.
    def set_peripheral_state(self, part: str, degrees: Sequence[float]) -> Outcome:
        return self.not_implemented("set_peripheral_state")

    def set_peripheral_velocity(self, part: str, percent: float) -> Outcome:
        return self.not_implemented("set_peripheral_velocity")

    def set_gesture(self, name: str, speed: float) -> Outcome:
        return self.not_implemented("set_gesture")

    # Getters: an Outcome whose data holds the value.
    def get_peripheral_state(self, part: str) -> Outcome:
        return self.not_implemented("get_peripheral_state")

    def get_peripheral_velocity(self, part: str) -> Outcome:
        return self.not_implemented("get_peripheral_velocity")

    def get_emotion(self) -> Outcome:
        return self.not_implemented("get_emotion")

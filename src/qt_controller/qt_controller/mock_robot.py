"""Behaviour of the mock QT robot as plain logic on an injected clock.

What a researcher would observe on the robot, in simulated form:

* speech takes time proportional to its length (and inversely to the speech speed) and
  queues: a sentence sent while another is being said starts when that one ends;
* an emotion is shown for a while, then the face returns to neutral; a new emotion
  replaces the one on screen; unknown emotions are refused;
* a gesture plays for its recorded duration divided by the speed, moving the joints its
  keyframe file names; unknown gestures are refused; a gesture requested while another
  plays interrupts it (``gesture_busy_policy = "interrupt"``, the default, because a
  scenario that starts the next gesture when its own timer says the last one ended must
  not be refused by a few milliseconds of transport delay) or is refused (``"refuse"``);
* joint commands move a part towards its target at the part's velocity (percent of
  ``max_joint_speed``); during a gesture the gesture owns its joints and a command for
  them takes effect when the gesture ends.

Every action is recorded as an event dict with its time ``t`` (the clock's time, or the
exact scheduled time for things that end on their own), drained by the node and published.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from qt_controller.commands import SPEECH_PITCH_RANGE, SPEECH_SPEED_RANGE
from qt_controller.config import MockQtRobotConfig
from qt_controller.emotions import EmotionCatalogue
from qt_controller.gestures import Gesture, GestureLibrary
from qt_controller.joint_limits import (
    ALL_JOINTS,
    HOME,
    PART_QT_NAME,
    PARTS,
    JointLimitError,
    JointLimits,
    canonical_part,
)
from qt_controller.robot_interface import Outcome

Event = dict[str, Any]


@dataclass
class MockConfig:
    """The mock's timing and start values. The fields that are mock_qt_robot options take their
    defaults from :class:`~qt_controller.config.MockQtRobotConfig` (declared once there):
    build one with :meth:`defaults` or ``MockQtRobotConfig.settings(MockConfig)``."""

    speech_seconds_per_char: float  # at the default speech speed (about 150 words/min)
    emotion_seconds: float
    max_joint_speed: float  # degrees/s at 100 % velocity
    default_velocity: float  # percent
    default_volume: int
    gesture_busy_policy: str
    default_speech_pitch: int = 140
    default_speech_speed: int = 80
    default_language: str = "en-US"

    @classmethod
    def defaults(cls, **changes: Any) -> MockConfig:
        """The node's defaults (its options' declared defaults), with ``changes``."""
        return MockQtRobotConfig().settings(cls, **changes)

    def __post_init__(self) -> None:
        if self.gesture_busy_policy not in ("interrupt", "refuse"):
            raise ValueError(
                f"gesture_busy_policy must be interrupt or refuse, not {self.gesture_busy_policy!r}"
            )
        for name in ("speech_seconds_per_char", "emotion_seconds", "max_joint_speed"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if not 0 < self.default_velocity <= 100:
            raise ValueError(f"default_velocity must be in (0, 100], got {self.default_velocity!r}")


@dataclass
class _Speech:
    text: str
    channel: str
    duration: float
    start: float = 0.0

    @property
    def end(self) -> float:
        return self.start + self.duration


@dataclass
class _Playing:
    gesture: Gesture
    speed: float
    start: float
    end: float
    commanded: set[str] = field(default_factory=set)  # joints commanded during the gesture


class MockRobot:
    """The mock QT robot's state machine; call :meth:`update` regularly (the node does, at 30 Hz)."""

    def __init__(
        self,
        clock: Callable[[], float],
        gestures: GestureLibrary,
        emotions: EmotionCatalogue | None = None,
        config: MockConfig | None = None,
        limits: JointLimits | None = None,
    ) -> None:
        self.clock = clock
        self.gestures = gestures
        self.emotions = emotions or EmotionCatalogue()
        self.config = config or MockConfig.defaults()
        self.limits = limits or JointLimits.default()
        self.positions: dict[str, float] = {j: HOME[j] for j in ALL_JOINTS}
        self.targets: dict[str, float] = dict(self.positions)
        self.joint_velocities: dict[str, float] = dict.fromkeys(ALL_JOINTS, 0.0)
        self.part_velocity: dict[str, float] = dict.fromkeys(PARTS, self.config.default_velocity)
        self.volume = self.config.default_volume
        self.speech_pitch = self.config.default_speech_pitch
        self.speech_speed = self.config.default_speech_speed
        self.language = self.config.default_language
        self.speech: _Speech | None = None
        self.speech_queue: deque[_Speech] = deque()
        self.emotion: str | None = None
        self.emotion_end = 0.0
        self.playing: _Playing | None = None
        self._events: list[Event] = []
        self._last = clock()

    # ------------------------------------------------------------------ events and time
    def _emit(self, t: float, event: str, **fields: Any) -> None:
        self._events.append({"t": t, "event": event, **fields})

    def drain_events(self) -> list[Event]:
        out, self._events = self._events, []
        return out

    def update(self, now: float | None = None) -> None:
        """Advance the robot to ``now`` (default: the clock's time)."""
        now = self.clock() if now is None else now
        if now < self._last:  # the clock went back (sim time restarted): no motion this step
            self._last = now
        self._advance_speech(now)
        if self.emotion is not None and self.emotion_end <= now:
            self._emit(self.emotion_end, "emotion_finished", name=self.emotion)
            self.emotion = None
        self._advance_gesture(now)
        self._move_joints(now)
        self._last = now

    def _advance_speech(self, now: float) -> None:
        while self.speech is not None and self.speech.end <= now:
            done = self.speech
            self._emit(done.end, "speech_finished", text=done.text, channel=done.channel)
            self.speech = self.speech_queue.popleft() if self.speech_queue else None
            if self.speech is not None:
                self.speech.start = done.end
                self._emit_speech_started(self.speech)

    def _emit_speech_started(self, s: _Speech) -> None:
        self._emit(
            s.start,
            "speech_started",
            text=s.text,
            channel=s.channel,
            duration=s.duration,
            pitch=self.speech_pitch,
            speed=self.speech_speed,
            language=self.language,
        )

    def _advance_gesture(self, now: float) -> None:
        p = self.playing
        if p is None:
            return
        if p.end <= now:
            final = p.gesture.final_positions
            self.positions.update(final)
            for j, v in final.items():
                if j not in p.commanded:
                    self.targets[j] = v
            self.playing = None
            self._emit(
                p.end,
                "gesture_finished",
                name=p.gesture.name,
                speed=p.speed,
                duration=p.end - p.start,
                interrupted=False,
            )
        else:
            self.positions.update(p.gesture.positions_at(now - p.start, p.speed))

    def _move_joints(self, now: float) -> None:
        dt = now - self._last
        owned = set(self.playing.gesture.joints) if self.playing else set()
        for part, joints in PARTS.items():
            step = self.config.max_joint_speed * self.part_velocity[part] / 100.0 * dt
            for j in joints:
                before = self.positions[j]
                if j not in owned:
                    delta = self.targets[j] - before
                    self.positions[j] = (
                        self.targets[j] if abs(delta) <= step else before + math.copysign(step, delta)
                    )
                self.joint_velocities[j] = (self.positions[j] - before) / dt if dt > 0 else 0.0

    # ------------------------------------------------------------------ speech and sound
    def speech_duration(self, text: str) -> float:
        return (
            len(text)
            * self.config.speech_seconds_per_char
            * self.config.default_speech_speed
            / self.speech_speed
        )

    def say(self, text: str, channel: str = "speech/say") -> Outcome:
        """Queue ``text``; it starts now if nothing is being said."""
        now = self.clock()
        self.update(now)
        if not text.strip():
            self._emit(now, "speech_refused", channel=channel, reason="empty text")
            return Outcome.failure("empty text")
        s = _Speech(text, channel, self.speech_duration(text))
        if self.speech is None:
            s.start = now
            self.speech = s
            self._emit_speech_started(s)
            return Outcome.success(
                f"saying {len(text)} characters for {s.duration:.2f} s", duration=s.duration
            )
        self.speech_queue.append(s)
        self._emit(now, "speech_queued", text=text, channel=channel, position=len(self.speech_queue))
        return Outcome.success(f"queued behind {len(self.speech_queue)} utterance(s)", duration=s.duration)

    def configure_speech(self, language: str, pitch: int, speed: int) -> Outcome:
        now = self.clock()
        self.update(now)
        (lo_p, hi_p), (lo_s, hi_s) = SPEECH_PITCH_RANGE, SPEECH_SPEED_RANGE
        if not (lo_p <= pitch <= hi_p and lo_s <= speed <= hi_s):
            self._emit(now, "speech_config_refused", pitch=pitch, speed=speed)
            return Outcome.failure(f"speech pitch must be in [{lo_p}, {hi_p}] and speed in [{lo_s}, {hi_s}]")
        self.language = language or self.language
        self.speech_pitch, self.speech_speed = int(pitch), int(speed)
        self._emit(
            now, "speech_config", language=self.language, pitch=self.speech_pitch, speed=self.speech_speed
        )
        return Outcome.success()

    def set_volume(self, volume: int) -> Outcome:
        now = self.clock()
        self.update(now)
        if not 0 <= volume <= 100:
            self._emit(now, "volume_refused", volume=volume)
            return Outcome.failure(f"volume {volume} is outside [0, 100]")
        self.volume = int(volume)
        self._emit(now, "volume", volume=self.volume)
        return Outcome.success()

    def media(self, kind: str, name: str) -> None:
        """An audio or video file requested from the streamers (recorded, not played)."""
        now = self.clock()
        self.update(now)
        self._emit(now, kind, name=name)

    # ------------------------------------------------------------------ face
    def show_emotion(self, name: str) -> Outcome:
        now = self.clock()
        self.update(now)
        resolved = self.emotions.resolve(name)
        if resolved is None:
            self._emit(now, "emotion_refused", name=name, reason="unknown emotion")
            return Outcome.failure(f"unknown emotion {name!r}")
        if self.emotion is not None:
            self._emit(now, "emotion_finished", name=self.emotion, interrupted=True)
        self.emotion = resolved
        self.emotion_end = now + self.config.emotion_seconds
        self._emit(now, "emotion_started", name=resolved, duration=self.config.emotion_seconds)
        return Outcome.success()

    # ------------------------------------------------------------------ body
    def play_gesture(self, name: str, speed: float) -> Outcome:
        now = self.clock()
        self.update(now)
        if not (math.isfinite(speed) and speed > 0):
            self._emit(now, "gesture_refused", name=name, speed=speed, reason="bad speed")
            return Outcome.failure(f"gesture speed must be positive, got {speed!r}")
        if name not in self.gestures:
            self._emit(now, "gesture_refused", name=name, speed=speed, reason="unknown gesture")
            return Outcome.failure(f"unknown gesture {name!r}; known: {', '.join(self.gestures.names)}")
        if self.playing is not None:
            if self.config.gesture_busy_policy == "refuse":
                self._emit(
                    now,
                    "gesture_refused",
                    name=name,
                    speed=speed,
                    reason=f"{self.playing.gesture.name} is playing",
                )
                return Outcome.failure(f"gesture {self.playing.gesture.name!r} is still playing")
            old = self.playing
            for j in old.gesture.joints:  # stay where the interrupted gesture left the joint
                if j not in old.commanded:
                    self.targets[j] = self.positions[j]
            self._emit(
                now,
                "gesture_finished",
                name=old.gesture.name,
                speed=old.speed,
                duration=now - old.start,
                interrupted=True,
            )
        gesture = self.gestures.get(name)
        duration = gesture.duration_at(speed)
        self.playing = _Playing(gesture, speed, now, now + duration)
        self.positions.update(gesture.positions_at(0.0))
        self._emit(
            now,
            "gesture_started",
            name=gesture.name,
            speed=speed,
            duration=duration,
            recorded_duration=gesture.duration,
            joints=list(gesture.joints),
        )
        return Outcome.success(f"playing {gesture.name} for {duration:.2f} s", duration=duration)

    def command_part(self, part: str, degrees: Sequence[float]) -> Outcome:
        now = self.clock()
        self.update(now)
        try:
            part = canonical_part(part)
            values = self.limits.check_part(part, degrees)
        except JointLimitError as exc:
            self._emit(now, "joint_command_refused", part=part, degrees=list(degrees), reason=str(exc))
            return Outcome.failure(str(exc))
        deferred = False
        for j, v in zip(PARTS[part], values, strict=True):
            self.targets[j] = v
            if self.playing is not None and j in self.playing.gesture.joints:
                self.playing.commanded.add(j)
                deferred = True
        self._emit(now, "joint_command", part=part, degrees=values, deferred=deferred)
        return Outcome.success()

    def set_velocity(self, parts: Sequence[str], percent: float) -> Outcome:
        now = self.clock()
        self.update(now)
        try:
            names = [canonical_part(p) for p in parts]
        except JointLimitError as exc:
            return Outcome.failure(str(exc))
        if not names or not (math.isfinite(percent) and 0 < percent <= 100):
            self._emit(now, "velocity_refused", parts=list(parts), velocity=percent)
            return Outcome.failure(f"velocity must be in (0, 100] for at least one part, got {percent!r}")
        for p in names:
            self.part_velocity[p] = float(percent)
        self._emit(now, "velocity", parts=[PART_QT_NAME[p] for p in names], velocity=float(percent))
        return Outcome.success()

    def joint_state(self) -> tuple[list[str], list[float], list[float]]:
        names = list(ALL_JOINTS)
        return names, [self.positions[j] for j in names], [self.joint_velocities[j] for j in names]

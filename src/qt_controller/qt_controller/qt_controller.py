"""QtController: the RobotInterface of the real QT robot, over its ROS topics and services.

It runs unchanged against mock_qt_robot, which serves the same names. Checks happen
here, before anything is sent: emotion names against the catalogue, joint commands
against the joint limits, and (``require_listeners``) that someone listens on a topic,
so a researcher is told "nobody listens on /qt_robot/emotion/show" instead of a command
silently going nowhere. Topic sends wait up to ``discovery_timeout`` for a listener and
service calls up to ``service_timeout`` (wall-clock seconds, as they bound transport and
discovery, not robot behaviour). Commands go out reliable and KEEP_ALL (``command_qos``):
a burst of them reaches the robot whole. The robot's joint states (30 a second) are taken only
when a ``get state`` asks for them (:class:`~hri_physio_bridge.ros_tools.TakenOnDemand`): the
middleware keeps the newest, and no callback wakes the node for each.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError
from hri_physio_bridge.qos import command_qos, latched_qos
from hri_physio_bridge.ros_tools import TakenOnDemand
from hri_physio_bridge.waiting import Clock, wait_until
from qt_controller import qt_services
from qt_controller.config import QtRobotOptions
from qt_controller.emotions import STANDARD_EMOTIONS, EmotionCatalogue
from qt_controller.joint_limits import (
    PART_QT_NAME,
    PART_TOPIC_STEM,
    PARTS,
    JointLimitError,
    JointLimits,
    canonical_part,
    parse_limit_overrides,
)
from qt_controller.robot_interface import Outcome, RobotInterface

SPEECH_TOPICS = {"talkText": topics.QT_TALK_TEXT, "say": topics.QT_SPEECH_SAY}


def part_topic(part: str) -> str:
    return topics.qt_joint_command(PART_TOPIC_STEM[part])


class QtController(RobotInterface):
    """The real QT robot (or mock_qt_robot) driven through ``node``."""

    def __init__(self, node: Node, log: logging.Logger | None = None, clock: Clock = time.monotonic) -> None:
        super().__init__("QtController", log)
        self.node = node
        self.options = QtRobotOptions()
        self.limits = JointLimits.default()
        self.emotions = EmotionCatalogue()
        self._clock = clock
        self._lock = threading.Lock()
        self._joint_state: JointState | None = None  # the newest taken so far
        self._joint_states: TakenOnDemand | None = None
        self._emotion: tuple[str, float] | None = None
        self._velocity: dict[str, float] = {}
        self._pubs: dict[str, Publisher] = {}
        self._services: dict[str, qt_services.ServiceClient] = {}
        self._configured = False

    # ------------------------------------------------------------------ setup
    def configure(self, options: Mapping[str, Any]) -> Outcome:
        try:
            opts = QtRobotOptions.from_mapping(options, "QtController options")
        except ConfigError as exc:
            return Outcome.failure(str(exc))
        specs = {
            "gesture": qt_services.GESTURE_PLAY,
            "speech_config": qt_services.SPEECH_CONFIG,
            "volume": qt_services.SET_VOLUME,
            "velocity": qt_services.SET_VELOCITY,
        }
        try:
            limits = JointLimits.default().with_overrides(parse_limit_overrides(opts.joint_limits))
            services = {
                key: qt_services.ServiceClient(self.node, spec, opts.service_backend, clock=self._clock)
                for key, spec in specs.items()
            }
        except ValueError as exc:  # JointLimitError, or backend 'qt' without QT's packages
            return Outcome.failure(str(exc))
        self.options, self.limits, self._services = opts, limits, services
        self.emotions = EmotionCatalogue([*STANDARD_EMOTIONS, *opts.extra_emotions])
        names = {
            "speech": SPEECH_TOPICS[opts.speech_channel],
            "emotion": topics.QT_EMOTION,
            "audio": topics.AUDIO_REQUEST,
            "video": topics.VIDEO_REQUEST,
        }
        for key, topic in names.items():
            self._pubs[key] = self.node.create_publisher(String, topic, command_qos())
        for key, topic in (("audio_current", topics.AUDIO_CURRENT), ("video_current", topics.VIDEO_CURRENT)):
            self._pubs[key] = self.node.create_publisher(String, topic, latched_qos())
        for part in PARTS:
            self._pubs[part] = self.node.create_publisher(Float64MultiArray, part_topic(part), command_qos())
        if self._joint_states is None:
            self._joint_states = TakenOnDemand(f"{self.node.get_name()}_joint_states", self.node.context)
            self._joint_states.subscribe("joints", JointState, topics.QT_JOINT_STATE, QoSProfile(depth=1))
        self._configured = True
        backend = services["gesture"].backend
        return Outcome.success(f"QT robot interface ready (service backend: {backend})", backend=backend)

    def close(self) -> None:
        """Destroy the joint-state subscription's node (the publishers go with the caller's node)."""
        with self._lock:
            if self._joint_states is not None:
                self._joint_states.destroy()
                self._joint_states = None

    # ------------------------------------------------------------------ helpers
    def _send(self, key: str, msg: Any, what: str) -> Outcome:
        if not self._configured:
            return Outcome.failure("the QT robot interface is not configured")
        pub = self._pubs[key]
        if self.options.require_listeners and not wait_until(
            lambda: pub.get_subscription_count() > 0, self.options.discovery_timeout, clock=self._clock,
            poll=0.02,
        ):
            return Outcome.failure(f"nobody listens on {pub.topic_name} (is the robot running?)")
        pub.publish(msg)
        return Outcome.success(f"{what} sent to {pub.topic_name}")

    def _call(self, key: str, **fields: Any) -> Outcome:
        if not self._configured:
            return Outcome.failure("the QT robot interface is not configured")
        return self._services[key].call(self.options.service_timeout, **fields)

    # ------------------------------------------------------------------ modalities
    def set_speech(self, text: str) -> Outcome:
        return self._send("speech", String(data=text), "speech")

    def set_speech_config(self, pitch: int, speed: int) -> Outcome:
        result = self._call(
            "speech_config", language=self.options.language, pitch=int(pitch), speed=int(speed)
        )
        if not result:
            return result
        return Outcome.success(f"speech pitch {pitch}, speed {speed}", pitch=int(pitch), speed=int(speed))

    def set_volume(self, percent: int) -> Outcome:
        result = self._call("volume", volume=int(percent))
        return Outcome.success(f"volume {percent} %", volume=int(percent)) if result else result

    def set_audio(self, file: str) -> Outcome:
        return self._send_media("audio", file)

    def set_video(self, file: str) -> Outcome:
        return self._send_media("video", file)

    def _send_media(self, kind: str, request: str) -> Outcome:
        """The request, and the same text as the streamer's latched current request (for a restart)."""
        result = self._send(kind, String(data=request), f"{kind} {request!r}")
        if result:
            self._pubs[f"{kind}_current"].publish(String(data=request))
        return result

    def set_emotion(self, name: str) -> Outcome:
        resolved = self.emotions.resolve(name)
        if resolved is None:
            return Outcome.failure(f"unknown emotion {name!r}; known: {', '.join(self.emotions.names)}")
        result = self._send("emotion", String(data=resolved), f"emotion {resolved}")
        if result:
            with self._lock:
                self._emotion = (resolved, self._now())
        return result

    def set_gesture(self, name: str, speed: float) -> Outcome:
        result = self._call("gesture", name=name, speed=float(speed))
        if not result:
            return Outcome.failure(f"gesture {name!r} at speed {speed:g} not played: {result.message}")
        return Outcome.success(
            f"gesture {name} at speed {speed:g}" + (f": {result.message}" if result.message else "")
        )

    def set_peripheral_state(self, part: str, degrees: Sequence[float]) -> Outcome:
        try:
            part = canonical_part(part)
            values = self.limits.check_part(part, degrees)
        except JointLimitError as exc:
            return Outcome.failure(f"not sent: {exc}")
        msg = Float64MultiArray(data=values)
        msg.layout.dim = [MultiArrayDimension(label="joints", size=len(values), stride=len(values))]
        return self._send(part, msg, f"{part} {values}")

    def set_peripheral_velocity(self, part: str, percent: float) -> Outcome:
        try:
            part = canonical_part(part)
        except JointLimitError as exc:
            return Outcome.failure(str(exc))
        result = self._call("velocity", parts=[PART_QT_NAME[part]], velocity=round(percent))
        if not result:
            return result
        with self._lock:
            self._velocity[part] = float(round(percent))
        return Outcome.success(f"{part} velocity {round(percent)} %", part=part, velocity=round(percent))

    # ------------------------------------------------------------------ getters
    def _now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def _latest_joints(self) -> tuple[dict[str, float], dict[str, float], float] | None:
        with self._lock:
            if self._joint_states is not None:
                taken = self._joint_states.take("joints")
                if taken:
                    self._joint_state = taken[-1]
            msg = self._joint_state
        if msg is None:
            return None
        pos = dict(zip(msg.name, msg.position, strict=False))
        vel = dict(zip(msg.name, msg.velocity, strict=False))
        return pos, vel, msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9

    def get_peripheral_state(self, part: str) -> Outcome:
        try:
            part = canonical_part(part)
        except JointLimitError as exc:
            return Outcome.failure(str(exc))
        latest = self._latest_joints()
        if latest is None:
            return Outcome.failure(f"no joint state received on {topics.QT_JOINT_STATE} yet")
        pos, _vel, stamp = latest
        missing = [j for j in PARTS[part] if j not in pos]
        if missing:
            return Outcome.failure(f"joint state on {topics.QT_JOINT_STATE} lacks {', '.join(missing)}")
        values = [pos[j] for j in PARTS[part]]
        text = ", ".join(f"{j} {v:.1f}" for j, v in zip(PARTS[part], values, strict=True))
        return Outcome.success(
            f"{part}: {text}", part=part, joints=list(PARTS[part]), degrees=values, stamp=stamp
        )

    def get_peripheral_velocity(self, part: str) -> Outcome:
        try:
            part = canonical_part(part)
        except JointLimitError as exc:
            return Outcome.failure(str(exc))
        with self._lock:
            percent = self._velocity.get(part)
        latest = self._latest_joints()
        joint_vel = [latest[1][j] for j in PARTS[part] if j in latest[1]] if latest else []
        if percent is None and len(joint_vel) != len(PARTS[part]):
            return Outcome.failure(
                f"velocity of {part} unknown: not set here and no joint velocities received"
            )
        text = f"{part}: " + (f"velocity {percent:g} %" if percent is not None else "velocity not set here")
        if len(joint_vel) == len(PARTS[part]):
            text += ", joint velocities " + ", ".join(f"{v:.1f}" for v in joint_vel) + " deg/s"
        return Outcome.success(text, part=part, velocity=percent, joint_velocities=joint_vel)

    def get_emotion(self) -> Outcome:
        with self._lock:
            current = self._emotion
        if current is None:
            return Outcome.success("no emotion shown by this controller yet", emotion=None)
        return Outcome.success(
            f"emotion {current[0]} (sent at t={current[1]:.3f})", emotion=current[0], since=current[1]
        )

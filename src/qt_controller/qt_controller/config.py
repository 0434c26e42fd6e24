"""The options of qt_controller and mock_qt_robot, declared once (no rclpy: checkable before launch).

Each option's type, default, bounds, unit and help text live on its field; the command-line
flags, ``--conf`` YAML keys, ROS parameters and ``--help`` text all come from here
(:mod:`hri_physio_bridge.config`).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import field_validator

from hri_physio_bridge import topics
from hri_physio_bridge.config import NodeConfig, option
from qt_controller.joint_limits import JointLimits, parse_limit_overrides

SERVICE_BACKENDS = ("auto", "qt", "json")
ServiceBackend = Literal["auto", "qt", "json"]

_BACKEND_HELP = ("how QT's services are reached: auto (qt when QT's service types import, else json), "
                 "qt (QT's own types) or json (std_msgs request/reply topics); the same on both nodes")
_LIMITS_HELP = "joint limit overrides, Joint:min:max,... in degrees (e.g. HeadYaw:-45:45)"


def _check_limits(value: str) -> str:
    JointLimits.default().with_overrides(parse_limit_overrides(value))
    return value


class QtRobotOptions(NodeConfig):
    """How :class:`~qt_controller.qt_controller.QtController` reaches the robot."""

    speech_channel: Literal["talkText", "say"] = option(
        "talkText", "speech topic: talkText (speech with lip animation) or say (voice only)")
    language: str = option("en-US", "speech language sent with speech configuration", min_length=1)
    service_backend: ServiceBackend = option("auto", _BACKEND_HELP)
    service_timeout: float = option(10.0, "how long to wait for a robot service to appear and answer",
                                    unit="s", ge=0)
    discovery_timeout: float = option(2.0, "how long to wait for a listener before a topic command fails",
                                      unit="s", ge=0)
    require_listeners: bool = option(True, "fail topic commands nobody listens to")
    extra_emotions: list[str] = option([], "comma-separated emotion names the robot has beyond QT's "
                                       "standard set, e.g. QT/my_face")
    joint_limits: str = option("", _LIMITS_HELP)

    @field_validator("joint_limits")
    @classmethod
    def _limits(cls, value: str) -> str:
        return _check_limits(value)


class QtControllerConfig(QtRobotOptions):
    """qt_controller: the robot options plus the command protocol's topics and safeguards."""

    input_topic: str = option(topics.QT_COMMANDS, "command lines (std_msgs/String)", min_length=1)
    output_topic: str = option(topics.QT_REPLIES, "one JSON reply per command line (std_msgs/String)",
                               min_length=1)
    allow_remote_exit: bool = option(
        False, "let an 'exit' line on input_topic stop the controller (anyone on the ROS graph could); "
        "'exit' on the --interactive console always works")
    command_queue_limit: int = option(
        100_000, "command lines waiting to be handled; a line beyond this is answered 'overloaded' at once "
        "and not executed", ge=1)
    interactive: bool = option(False, "also read commands from stdin (end with 'exit' or Ctrl-D)",
                               switch=True)

    def robot_options(self) -> dict[str, Any]:
        """The options :meth:`QtController.configure` takes."""
        return {name: getattr(self, name) for name in QtRobotOptions.model_fields}


class MockQtRobotConfig(NodeConfig):
    """mock_qt_robot: timing of the simulated robot and what it serves."""

    gesture_dirs: list[str] = option([], "comma-separated extra directories of gesture XML files (the "
                                     "package's exercise gestures always load)")
    extra_emotions: list[str] = option([], "comma-separated emotion names beyond QT's standard set")
    speech_seconds_per_char: float = option(0.06, "speaking time per character at the default speech "
                                            "speed (80)", unit="s", gt=0, dynamic=True)
    emotion_seconds: float = option(3.0, "how long an emotion stays on the face", unit="s", gt=0,
                                    dynamic=True)
    max_joint_speed: float = option(120.0, "joint speed at 100 percent velocity", unit="deg/s", gt=0,
                                    dynamic=True)
    default_velocity: float = option(50.0, "motor velocity at start", unit="percent", gt=0, le=100)
    default_volume: int = option(50, "speaker volume at start", unit="percent", ge=0, le=100)
    gesture_busy_policy: Literal["interrupt", "refuse"] = option(
        "interrupt", "a gesture requested while one plays: interrupt it or refuse the new one", dynamic=True)
    joint_state_rate: float = option(30.0, "rate of /qt_robot/joints/state on ROS time", unit="Hz", gt=0)
    service_backend: ServiceBackend = option("auto", _BACKEND_HELP)
    events_topic: str = option(topics.QT_MOCK_EVENTS, "JSON events of every action", min_length=1)
    mirror_media: bool = option(True, "also record /audio_streamer and /video_streamer requests as events")
    joint_limits: str = option("", _LIMITS_HELP)

    @field_validator("joint_limits")
    @classmethod
    def _limits(cls, value: str) -> str:
        return _check_limits(value)

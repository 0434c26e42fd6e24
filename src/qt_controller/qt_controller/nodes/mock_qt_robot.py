"""mock_qt_robot: stands in for the QT robot with the same topic and service names.

Speech takes time and queues, emotions show for a while, gestures play from keyframe
files for their duration divided by the speed, /qt_robot/joints/state is published at
30 Hz. All timing follows the node's ROS clock, so with ``use_sim_time`` the mock runs as
fast as /clock goes. Every action is also published as a JSON event (with ``t``) on
/qt_robot/mock/events so a recording shows what the "robot" did.

Examples::

    mock_qt_robot
    mock_qt_robot --gesture-dir my_gestures --ros-args -p use_sim_time:=true
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import threading
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge.nodes.common import (
    CliError,
    fail,
    install_stop_handlers,
    load_yaml_conf,
    split_ros_args,
)
from qt_controller import qt_services
from qt_controller.emotions import STANDARD_EMOTIONS, EmotionCatalogue
from qt_controller.gestures import GestureError, GestureLibrary, default_gesture_dir
from qt_controller.joint_limits import PARTS, JointLimitError, JointLimits, parse_limit_overrides
from qt_controller.mock_robot import MockConfig, MockRobot
from qt_controller.nodes.params import declare_options
from qt_controller.qt_robot import (
    AUDIO_TOPIC,
    EMOTION_TOPIC,
    JOINT_STATE_TOPIC,
    SPEECH_TOPICS,
    VIDEO_TOPIC,
    part_topic,
)
from qt_controller.robot_interface import Outcome

PROG = "mock_qt_robot"
_CFG = MockConfig()
NODE_OPTIONS: dict[str, Any] = {
    "gesture_dirs": [],
    "extra_emotions": [],
    "speech_seconds_per_char": _CFG.speech_seconds_per_char,
    "emotion_seconds": _CFG.emotion_seconds,
    "max_joint_speed": _CFG.max_joint_speed,
    "default_velocity": _CFG.default_velocity,
    "default_volume": _CFG.default_volume,
    "gesture_busy_policy": _CFG.gesture_busy_policy,
    "joint_state_rate": 30.0,
    "service_backend": "auto",
    "events_topic": "/qt_robot/mock/events",
    "mirror_media": True,
    "joint_limits": "",
}
DESCRIPTIONS = {
    "gesture_dirs": "extra directories of gesture XML files (the package's exercise gestures always load)",
    "extra_emotions": "emotion names beyond QT's standard set",
    "speech_seconds_per_char": "speaking time per character at the default speech speed",
    "emotion_seconds": "how long an emotion stays on the face",
    "max_joint_speed": "degrees/s of a joint at 100 % velocity",
    "default_velocity": "motor velocity (percent) at start",
    "default_volume": "speaker volume (percent) at start",
    "gesture_busy_policy": "a gesture requested while one plays: interrupt | refuse",
    "joint_state_rate": "Hz of /qt_robot/joints/state (ROS time)",
    "service_backend": "auto | qt | json (must match qt_controller)",
    "events_topic": "JSON events of every action",
    "mirror_media": "also record /audio_streamer and /video_streamer requests as events",
    "joint_limits": "joint limit overrides, Joint:min:max,...",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="A mock QT robot: the real robot's topics and services, with speech, emotion and "
        "gesture timing on ROS time, 30 Hz joint states and a JSON event of every action.",
        epilog="Precedence: defaults < --conf file < command-line options < --ros-args parameters.",
    )
    parser.add_argument("--conf", help="YAML file with node options (flat, or a ROS params file)")
    parser.add_argument(
        "--gesture-dir",
        action="append",
        default=None,
        help="extra directory of gesture XML files (repeatable)",
    )
    parser.add_argument(
        "--gesture-busy-policy",
        choices=("interrupt", "refuse"),
        default=None,
        help="what a gesture request does while another plays (default: interrupt)",
    )
    parser.add_argument(
        "--service-backend",
        choices=("auto", "qt", "json"),
        default=None,
        help="how QT's services are served (default: auto)",
    )
    return parser


class MockQtRobotNode(Node):
    """ROS 2 shell around :class:`MockRobot`."""

    def __init__(self, options: dict[str, Any], **kwargs: Any) -> None:
        super().__init__("mock_qt_robot", **kwargs)
        v = declare_options(self, NODE_OPTIONS, options, DESCRIPTIONS)
        if not v["joint_state_rate"] > 0:
            raise ValueError("joint_state_rate must be > 0 Hz")
        limits = JointLimits.default().with_overrides(parse_limit_overrides(v["joint_limits"]))
        gestures = GestureLibrary.from_dirs([default_gesture_dir(), *v["gesture_dirs"]], limits)
        config = MockConfig(
            speech_seconds_per_char=v["speech_seconds_per_char"],
            emotion_seconds=v["emotion_seconds"],
            max_joint_speed=v["max_joint_speed"],
            default_velocity=v["default_velocity"],
            default_volume=v["default_volume"],
            gesture_busy_policy=v["gesture_busy_policy"],
        )
        self.robot = MockRobot(
            self._now, gestures, EmotionCatalogue([*STANDARD_EMOTIONS, *v["extra_emotions"]]), config, limits
        )
        self.events = self.create_publisher(String, v["events_topic"], 100)
        self.joint_pub = self.create_publisher(JointState, JOINT_STATE_TOPIC, 10)
        for channel, topic in SPEECH_TOPICS.items():
            self.create_subscription(
                String, topic, self._acting(lambda m, c=channel: self.robot.say(m.data, c)), 50
            )
        self.create_subscription(
            String, EMOTION_TOPIC, self._acting(lambda m: self.robot.show_emotion(m.data)), 10
        )
        for part in PARTS:
            self.create_subscription(
                Float64MultiArray,
                part_topic(part),
                self._acting(lambda m, p=part: self.robot.command_part(p, list(m.data))),
                10,
            )
        if v["mirror_media"]:
            self.create_subscription(
                String, AUDIO_TOPIC, self._acting(lambda m: self.robot.media("audio", m.data)), 10
            )
            self.create_subscription(
                String, VIDEO_TOPIC, self._acting(lambda m: self.robot.media("video", m.data)), 10
            )
        backend = v["service_backend"]
        self.servers = [
            qt_services.ServiceServer(
                self,
                qt_services.GESTURE_PLAY,
                self._served(lambda f: self.robot.play_gesture(f["name"], f["speed"])),
                backend,
            ),
            qt_services.ServiceServer(
                self,
                qt_services.SPEECH_CONFIG,
                self._served(lambda f: self.robot.configure_speech(f["language"], f["pitch"], f["speed"])),
                backend,
            ),
            qt_services.ServiceServer(
                self,
                qt_services.SET_VOLUME,
                self._served(lambda f: self.robot.set_volume(f["volume"])),
                backend,
            ),
            qt_services.ServiceServer(
                self,
                qt_services.SET_VELOCITY,
                self._served(lambda f: self.robot.set_velocity(f["parts"], float(f["velocity"]))),
                backend,
            ),
        ]
        self.timer = self.create_timer(1.0 / v["joint_state_rate"], self._tick)
        self.get_logger().info(
            f"mock QT robot ready: gestures {', '.join(gestures.names)}; service backend "
            f"{self.servers[0].backend}; events on {v['events_topic']}"
        )

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _acting(self, action: Callable[[Any], Any]) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            result = action(msg)
            if isinstance(result, Outcome) and not result:
                self.get_logger().warning(f"refused: {result.message}")
            self._flush_events()

        return callback

    def _served(self, action: Callable[[dict[str, Any]], Outcome]) -> Callable[[dict[str, Any]], Outcome]:
        def handler(fields: dict[str, Any]) -> Outcome:
            result = action(fields)
            if not result:
                self.get_logger().warning(f"refused: {result.message}")
            self._flush_events()
            return result

        return handler

    def _flush_events(self) -> None:
        for event in self.robot.drain_events():
            self.events.publish(String(data=json.dumps(event)))
            if event["event"] not in ("speech_queued",):
                detail = {k: v for k, v in event.items() if k not in ("t", "event")}
                self.get_logger().info(f"{event['event']} {json.dumps(detail)}")

    def _tick(self) -> None:
        self.robot.update()
        names, positions, velocities = self.robot.joint_state()
        msg = JointState(name=names, position=positions, velocity=velocities, effort=[0.0] * len(names))
        msg.header.stamp = self.get_clock().now().to_msg()
        self.joint_pub.publish(msg)
        self._flush_events()


def _options_from(args: argparse.Namespace) -> dict[str, Any]:
    options = load_yaml_conf(args.conf, PROG) if args.conf else {}
    unknown = sorted(set(options) - set(NODE_OPTIONS))
    if unknown:
        raise CliError(f"{args.conf}: unknown option(s) {unknown}; known: {sorted(NODE_OPTIONS)}")
    if args.gesture_dir:
        options["gesture_dirs"] = [*options.get("gesture_dirs", []), *args.gesture_dir]
    if args.gesture_busy_policy is not None:
        options["gesture_busy_policy"] = args.gesture_busy_policy
    if args.service_backend is not None:
        options["service_backend"] = args.service_backend
    return options


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    try:
        options = _options_from(args)
    except CliError as exc:
        fail(PROG, str(exc))

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node: MockQtRobotNode | None = None
    executor = SingleThreadedExecutor()
    spin: threading.Thread | None = None
    try:
        try:
            node = MockQtRobotNode(options)
        except (
            ValueError,
            GestureError,
            JointLimitError,
            ParameterException,
            NameValidationException,
        ) as exc:
            fail(PROG, str(exc))
        log = node.get_logger()
        stop = install_stop_handlers(lambda name: log.info(f"{name} received: exiting"))
        executor.add_node(node)
        spin = threading.Thread(target=_spin, args=(executor,), name="ros-spin")
        spin.start()
        stop.wait()
    finally:
        executor.shutdown(timeout_sec=1.0)
        if spin is not None:
            spin.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def _spin(executor: SingleThreadedExecutor) -> None:
    with contextlib.suppress(ExternalShutdownException, KeyboardInterrupt):
        executor.spin()


if __name__ == "__main__":
    sys.exit(main())

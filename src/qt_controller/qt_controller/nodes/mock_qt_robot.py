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
import json
import sys
from array import array
from collections.abc import Callable
from typing import Any

from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge import topics
from hri_physio_bridge.node_runner import ManagedNode, run_node
from hri_physio_bridge.qos import command_qos, event_qos
from qt_controller import qt_services
from qt_controller.config import MockQtRobotConfig
from qt_controller.emotions import STANDARD_EMOTIONS, EmotionCatalogue
from qt_controller.gestures import GestureError, GestureLibrary, default_gesture_dir
from qt_controller.joint_limits import PARTS, JointLimitError, JointLimits, parse_limit_overrides
from qt_controller.mock_robot import MockConfig, MockRobot
from qt_controller.qt_controller import SPEECH_TOPICS, part_topic
from qt_controller.robot_interface import Outcome

PROG = "mock_qt_robot"


class MockQtRobotNode(ManagedNode):
    """ROS 2 shell around :class:`MockRobot`. Every input that takes commands is reliable and
    KEEP_ALL (``command_qos``), so a burst of commands reaches the mock whole."""

    def __init__(self, config: MockQtRobotConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = v = self.declare_config(config)
        limits = JointLimits.default().with_overrides(parse_limit_overrides(v.joint_limits))
        gestures = GestureLibrary.from_dirs([default_gesture_dir(), *v.gesture_dirs], limits)
        mock_config = v.settings(MockConfig)
        emotions = EmotionCatalogue([*STANDARD_EMOTIONS, *v.extra_emotions])
        self.robot = MockRobot(self._now, gestures, emotions, mock_config, limits)
        self.events = self.create_publisher(String, v.events_topic, event_qos())
        self.joint_pub = self.create_publisher(JointState, topics.QT_JOINT_STATE, 10)
        for channel, topic in SPEECH_TOPICS.items():
            self.create_subscription(
                String, topic, self._acting(lambda m, c=channel: self.robot.say(m.data, c)), command_qos()
            )
        self.create_subscription(
            String, topics.QT_EMOTION, self._acting(lambda m: self.robot.show_emotion(m.data)), command_qos()
        )
        for part in PARTS:
            self.create_subscription(
                Float64MultiArray,
                part_topic(part),
                self._acting(lambda m, p=part: self.robot.command_part(p, list(m.data))),
                command_qos(),
            )
        if v.mirror_media:
            self.create_subscription(
                String, topics.AUDIO_REQUEST, self._acting(lambda m: self.robot.media("audio", m.data)),
                command_qos(),
            )
            self.create_subscription(
                String, topics.VIDEO_REQUEST, self._acting(lambda m: self.robot.media("video", m.data)),
                command_qos(),
            )
        backend = v.service_backend
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
        # Reused at every tick, with arrays of doubles (building a JointState from lists checks every
        # value in Python); the joints are always the same ones, in the same order.
        names = self.robot.joint_state()[0]
        self._joint_msg = JointState(name=names, effort=array("d", bytes(8 * len(names))))
        self.timer = self.create_timer(1.0 / v.joint_state_rate, self._tick)
        self.get_logger().info(
            f"mock QT robot ready: gestures {', '.join(gestures.names)}; service backend "
            f"{self.servers[0].backend}; events on {v.events_topic}"
        )

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def apply_config(self, config: MockQtRobotConfig, changed: tuple[str, ...]) -> None:
        """The simulated timing (speech, emotions, joint speed) and the busy policy, from now on."""
        self.robot.config = config.settings(MockConfig)
        self.config = config

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
        # One clock reading per tick, for the motion and the stamp (under sim time both were the same
        # value anyway: the clock moves only between callbacks of this executor).
        now = self.get_clock().now()
        self.robot.update(now.nanoseconds * 1e-9)
        _names, positions, velocities = self.robot.joint_state()
        msg = self._joint_msg
        msg.position, msg.velocity = array("d", positions), array("d", velocities)
        msg.header.stamp = now.to_msg()
        self.joint_pub.publish(msg)
        self._flush_events()


def _gesture_dir_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--gesture-dir", action="append", default=None, metavar="DIR",
                        help="extra directory of gesture XML files (repeatable; added to gesture_dirs)")


def _make_node(config: MockQtRobotConfig, args: argparse.Namespace) -> MockQtRobotNode:
    if args.gesture_dir:
        config = config.replace(gesture_dirs=[*config.gesture_dirs, *args.gesture_dir])
    return MockQtRobotNode(config)


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, MockQtRobotConfig, _make_node, argv=argv, extra_arguments=_gesture_dir_flag,
        startup_errors=(GestureError, JointLimitError, ValueError),
        description="A mock QT robot: the real robot's topics and services, with speech, emotion and "
        "gesture timing on ROS time, 30 Hz joint states and a JSON event of every action.",
    )


if __name__ == "__main__":
    sys.exit(main())

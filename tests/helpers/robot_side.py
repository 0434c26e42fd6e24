"""In-process robot side for integration tests: mock_qt_robot + qt_controller + a probe, on sim time.

The test drives /clock itself (a few times faster than real time), so every duration the
tests check is ROS time, exactly as the coach will run this robot side.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

from helpers import wait_until
from hri_physio_bridge.ros_tools import ExecutorThread, clock_message
from hri_physio_bridge.waiting import wait_until as waited

SIM_START = 1000.0
#: A query every controller answers without touching the robot (Probe.wait_answering).
PING = "get emotion"


class ClockDriver:
    """Publishes /clock from its own thread: ``step`` sim seconds every ``period`` wall seconds."""

    def __init__(self, context: Any, step: float = 1 / 60, period: float = 0.005) -> None:
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        self.node = Node("test_clock", context=context)
        self.pub = self.node.create_publisher(Clock, "/clock", 10)
        self.step, self.period = step, period
        self.t = SIM_START
        self.running = threading.Event()
        self.running.set()
        self._alive = True
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while self._alive:
            if self.running.is_set():
                self.t += self.step
                self.pub.publish(clock_message(self.t))
            time.sleep(self.period)

    def close(self) -> None:
        self._alive = False
        self._thread.join(2.0)
        self.node.destroy_node()


class Probe:
    """Sends command lines and collects replies, mock events and joint states (with receipt sim time)."""

    def __init__(self, context: Any, use_sim_time: bool = True) -> None:
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String

        from hri_physio_bridge import topics
        from hri_physio_bridge.qos import command_qos, event_qos

        self._string = String
        self.node = Node("test_probe", context=context,
                         parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, use_sim_time)])
        self.lock = threading.Lock()
        self.replies: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []
        self.joints: list[tuple[float, dict[str, float]]] = []
        self.input = self.node.create_publisher(String, topics.QT_COMMANDS, command_qos())
        self.output_sub = self.node.create_subscription(String, topics.QT_REPLIES, self._on_reply,
                                                        command_qos())
        self.events_sub = self.node.create_subscription(String, topics.QT_MOCK_EVENTS, self._on_event,
                                                        event_qos())
        self.node.create_subscription(JointState, topics.QT_JOINT_STATE, self._on_joints, 100)

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def _on_reply(self, msg: Any) -> None:
        with self.lock:
            self.replies.append(json.loads(msg.data))

    def _on_event(self, msg: Any) -> None:
        event = json.loads(msg.data)
        event["received"] = self.now()
        with self.lock:
            self.events.append(event)

    def _on_joints(self, msg: Any) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self.lock:
            self.joints.append((stamp, dict(zip(msg.name, msg.position, strict=True))))

    def connected(self) -> bool:
        """This probe has matched a controller's input and output (its own view of the graph only)."""
        return self.input.get_subscription_count() > 0 and self.output_sub.get_publisher_count() > 0

    def wait_answering(self, timeout: float, what: str) -> None:
        """Until a controller answers this probe: a harmless query, sent again each second, is answered.

        Each side discovers the other on its own. ``connected`` says the probe has matched the
        controller; the controller's reply writer may not have matched the probe's reader yet, and a
        reply sent before that match is lost (the topic is volatile). Under load that took seconds.
        """
        def answered() -> bool:
            if not self.connected():
                return False
            with self.lock:
                n = len(self.replies)
            self.input.publish(self._string(data=PING))

            def pinged() -> bool:
                with self.lock:
                    return any(r["command"] == PING for r in self.replies[n:])

            return waited(pinged, 1.0, poll=0.02)

        wait_until(answered, timeout, what)

    def send(self, line: str, timeout: float = 20.0) -> dict[str, Any]:
        """Publish one command and return its reply (commands are answered in order; a late answer to
        :meth:`wait_answering`'s query is passed over)."""
        with self.lock:
            n = len(self.replies)
        self.input.publish(self._string(data=line))

        def reply() -> dict[str, Any] | None:
            with self.lock:
                return next((r for r in self.replies[n:] if r["command"] != PING or line == PING), None)

        wait_until(lambda: reply() is not None, timeout, f"a reply to {line!r}")
        answer = reply()
        assert answer is not None and answer["command"] == line.strip(), answer
        return answer

    def events_of(self, kind: str, **match: Any) -> list[dict[str, Any]]:
        with self.lock:
            return [e for e in self.events if e["event"] == kind
                    and all(e.get(k) == v for k, v in match.items())]

    def wait_event(self, kind: str, timeout: float = 20.0, **match: Any) -> dict[str, Any]:
        wait_until(lambda: self.events_of(kind, **match), timeout,
                   lambda: f"event {kind} {match}; got {[e['event'] for e in self.events]}")
        return self.events_of(kind, **match)[0]

    def clear(self) -> None:
        with self.lock:
            self.events.clear()
            self.joints.clear()


class RobotSide:
    """mock_qt_robot + qt_controller (+ probe and /clock) on one executor in this process."""

    def __init__(self, context: Any, mock_options: dict[str, Any],
                 controller_options: dict[str, Any]) -> None:
        from rclpy.parameter import Parameter

        from qt_controller.config import MockQtRobotConfig, QtControllerConfig
        from qt_controller.nodes.mock_qt_robot import MockQtRobotNode
        from qt_controller.nodes.qt_controller import QtControllerNode

        sim = [Parameter("use_sim_time", Parameter.Type.BOOL, True)]
        self.clock = ClockDriver(context)
        self.mock = MockQtRobotNode(MockQtRobotConfig.from_mapping(mock_options), context=context,
                                    parameter_overrides=sim)
        self.controller = QtControllerNode(QtControllerConfig.from_mapping(controller_options),
                                           context=context, parameter_overrides=sim)
        self.probe = Probe(context)
        self._spinner = ExecutorThread(self.mock, self.controller, self.probe.node, context=context)
        self.stop = threading.Event()
        self.controller.start(self.stop)
        wait_until(self.probe.connected, 20, "the probe to discover qt_controller")
        wait_until(lambda: self.mock._now() > SIM_START and self.probe.now() > SIM_START, 20, "sim time")
        for client in self.controller.robot._services.values():
            assert client.wait_available(20), f"{client.spec.name} not available"

    def close(self) -> None:
        self.stop.set()
        self.controller.join()
        self.controller.close()
        self._spinner.close(join_timeout=5.0)
        for node in (self.controller, self.mock, self.probe.node):
            node.destroy_node()
        self.clock.close()

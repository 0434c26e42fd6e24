"""The ROS parameters a node declares: read-only unless the option is applied at run time."""

from __future__ import annotations

from typing import Any

import pytest

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_bridge.node_runner import ManagedNode, _descriptor
from hri_physio_bridge.ros_tools import ExecutorThread
from qt_controller.config import MockQtRobotConfig

pytestmark = pytest.mark.ros


class Options(NodeConfig):
    rate: float = option(2.0, "a rate", unit="Hz", gt=0)
    gain: float = option(1.0, "a gain", ge=0, le=10, dynamic=True)


def test_descriptors_are_read_only_unless_the_option_is_dynamic() -> None:
    assert _descriptor(Options, "rate").read_only and not _descriptor(Options, "gain").read_only
    assert "(settable at run time)" in Options.describe("gain")
    assert "settable" not in Options.describe("rate")
    dynamic = set(MockQtRobotConfig.dynamic_options())
    assert dynamic == {"speech_seconds_per_char", "emotion_seconds", "max_joint_speed", "gesture_busy_policy"}
    for name in MockQtRobotConfig.model_fields:
        assert _descriptor(MockQtRobotConfig, name).read_only == (name not in dynamic)


def test_a_node_that_does_not_apply_a_dynamic_option_refuses_its_change(ros_context: Any) -> None:
    from rclpy.parameter import Parameter

    class Node(ManagedNode):
        def __init__(self) -> None:
            super().__init__("runner_test_node", context=ros_context)
            self.config = self.declare_config(Options())

    node = Node()
    spinner = ExecutorThread(node, context=ros_context)
    try:
        (result,) = node.set_parameters([Parameter("gain", value=2.0)])
        assert not result.successful and "applies no change of gain" in result.reason
        (result,) = node.set_parameters([Parameter("rate", value=3.0)])
        assert not result.successful and "read-only" in result.reason
        assert (node.get_parameter("gain").value, node.get_parameter("rate").value) == (1.0, 2.0)
        (result,) = node.set_parameters([Parameter("use_sim_time", value=False)])  # rclpy's own
        assert result.successful
    finally:
        spinner.close()
        node.destroy_node()


def test_the_executor_thread_waits_without_polling_and_close_wakes_it(ros_context: Any) -> None:
    """The spin waits until there is work (no timeout to poll a flag): close() itself ends the wait."""
    import threading

    import rclpy
    from std_msgs.msg import String

    node = rclpy.create_node("executor_thread_test", context=ros_context)
    heard = threading.Event()
    node.create_subscription(String, "/executor_thread_test", lambda _m: heard.set(), 10)
    publisher = node.create_publisher(String, "/executor_thread_test", 10)
    spinner = ExecutorThread(node, context=ros_context)
    try:
        for _ in range(100):  # matched within a few tries: a message wakes the waiting thread
            publisher.publish(String(data="hello"))
            if heard.wait(0.1):
                break
        assert heard.is_set()
    finally:
        spinner.close(join_timeout=30.0)
        node.destroy_node()
    assert not spinner._thread.is_alive()  # woken by close(), not by a timeout of its own

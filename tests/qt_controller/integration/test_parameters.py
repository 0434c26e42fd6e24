"""Parameters at run time, as ``ros2 param set`` sends them (the node's set_parameters service).

A dynamic option (the mock's timing) is checked by the configuration model and applied; a bad
value is refused with the model's reason; every other option is read-only and refused as such.
"""

from __future__ import annotations

from typing import Any

import pytest

from helpers import wait_until
from hri_physio_bridge.ros_tools import ExecutorThread
from qt_controller.config import MockQtRobotConfig
from qt_controller.nodes.mock_qt_robot import MockQtRobotNode

pytestmark = pytest.mark.ros


@pytest.fixture
def mock_and_client(ros_context: Any):
    from rclpy.node import Node
    from rclpy.parameter_client import AsyncParameterClient

    mock = MockQtRobotNode(MockQtRobotConfig(), context=ros_context)
    tool = Node("param_tool", context=ros_context)
    client = AsyncParameterClient(tool, "mock_qt_robot")
    spinner = ExecutorThread(mock, tool, context=ros_context)
    try:
        assert client.wait_for_services(timeout_sec=20.0), "the mock's parameter services did not appear"
        yield mock, client
    finally:
        spinner.close()
        tool.destroy_node()
        mock.destroy_node()


def set_one(client: Any, name: str, value: Any) -> Any:
    """One ``ros2 param set``: the service's answer for that parameter."""
    from rclpy.parameter import Parameter

    future = client.set_parameters([Parameter(name, value=value)])
    wait_until(future.done, 20.0, f"an answer to setting {name}")
    (result,) = future.result().results
    return result


def test_a_dynamic_option_is_applied_and_a_bad_value_refused_with_the_reason(mock_and_client) -> None:
    mock, client = mock_and_client
    ok = set_one(client, "emotion_seconds", 1.5)
    assert ok.successful, ok.reason
    assert mock.robot.config.emotion_seconds == 1.5 and mock.config.emotion_seconds == 1.5
    negative = set_one(client, "emotion_seconds", -2.0)  # outside the descriptor's range: rclpy refuses
    assert not negative.successful and "emotion_seconds" in negative.reason and "range" in negative.reason
    zero = set_one(client, "emotion_seconds", 0.0)  # inside the range, but the model wants > 0
    assert not zero.successful and "emotion_seconds" in zero.reason and "greater than 0" in zero.reason
    not_a_number = set_one(client, "max_joint_speed", "fast")
    assert not not_a_number.successful and "max_joint_speed" in not_a_number.reason
    unknown_policy = set_one(client, "gesture_busy_policy", "queue")
    assert not unknown_policy.successful and "gesture_busy_policy" in unknown_policy.reason
    assert mock.robot.config.emotion_seconds == 1.5  # nothing refused was applied
    assert mock.get_parameter("emotion_seconds").value == 1.5


def test_an_option_applied_only_at_start_up_is_read_only(mock_and_client) -> None:
    mock, client = mock_and_client
    refused = set_one(client, "joint_state_rate", 10.0)
    assert not refused.successful and "read-only" in refused.reason
    assert mock.get_parameter("joint_state_rate").value == 30.0

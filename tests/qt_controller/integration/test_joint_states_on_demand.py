"""The controller takes the robot's joint states when a ``get state`` asks, not on every message (issue 28).

Nothing spins the controller's node here: the answers can only come from what the middleware kept.
A ``get state`` before any state has arrived says so; after several, it answers with the newest; and a
second ``get state`` with nothing new since still answers (with the one taken before).
"""

from __future__ import annotations

import uuid
from typing import Any

from helpers import wait_until
from hri_physio_bridge import topics


def _state(yaw: float, pitch: float) -> Any:
    from sensor_msgs.msg import JointState

    return JointState(name=["HeadYaw", "HeadPitch", "LeftShoulderPitch"], position=[yaw, pitch, 5.0],
                      velocity=[0.0, 0.0, 0.0], effort=[0.0, 0.0, 0.0])


def test_get_state_takes_the_newest_joint_state_without_any_callback(ros_context: Any) -> None:
    import rclpy
    from sensor_msgs.msg import JointState

    from qt_controller.qt_controller import QtController

    name = f"controller_{uuid.uuid4().hex[:6]}"
    node = rclpy.create_node(name, context=ros_context)
    robot_node = rclpy.create_node(f"robot_{uuid.uuid4().hex[:6]}", context=ros_context)
    robot = QtController(node)
    try:
        assert robot.configure({"service_backend": "json"}), "configure"
        missing = robot.get_peripheral_state("head")
        assert not missing and f"no joint state received on {topics.QT_JOINT_STATE} yet" in missing.message

        pub = robot_node.create_publisher(JointState, topics.QT_JOINT_STATE, 10)
        wait_until(lambda: pub.get_subscription_count() > 0, 20, "the controller's joint-state reader")
        for yaw in (10.0, 20.0, 30.0):
            pub.publish(_state(yaw, -yaw))
        wait_until(lambda: robot.get_peripheral_state("head").data.get("degrees") == [30.0, -30.0], 20,
                   lambda: f"the newest state, got {robot.get_peripheral_state('head')}")
        again = robot.get_peripheral_state("head")  # nothing new since: the last one taken still answers
        assert again and again.data["degrees"] == [30.0, -30.0]
        assert not robot.get_peripheral_state("rightarm")  # the state lacks that arm's joints: said

        pub.publish(_state(40.0, -40.0))
        wait_until(lambda: robot.get_peripheral_state("head").data.get("degrees") == [40.0, -40.0], 20,
                   "a newer state")
        assert f"{name}_joint_states" in node.get_node_names()
    finally:
        robot.close()
        robot.close()  # a second close is harmless
        robot_node.destroy_node()
        node.destroy_node()

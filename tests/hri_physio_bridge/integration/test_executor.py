"""LeanExecutor (ExecutorThread's executor) serves every kind of entity as rclpy's executor does."""

from __future__ import annotations

import threading
import time

import pytest

from helpers import wait_until


@pytest.fixture
def node(ros_context):
    from rclpy.node import Node

    from hri_physio_bridge.ros_tools import ExecutorThread

    node = Node("lean_executor_test", context=ros_context)
    spinner = ExecutorThread(node, context=ros_context)
    try:
        yield node
    finally:
        spinner.close()
        node.destroy_node()


def test_messages_in_order_and_entities_made_while_spinning(node) -> None:
    from std_msgs.msg import Int32

    got: list[int] = []
    pub = node.create_publisher(Int32, "/test/lean/ints", 100)
    sub = node.create_subscription(Int32, "/test/lean/ints", lambda m: got.append(m.data), 100)  # after start
    wait_until(lambda: pub.get_subscription_count() > 0, 30, "the subscription")
    for i in range(50):
        pub.publish(Int32(data=i))
    wait_until(lambda: len(got) == 50, 30, lambda: f"50 messages, got {got}")
    assert got == list(range(50))
    node.destroy_subscription(sub)  # destroyed while spinning: the executor goes on without it
    ticks: list[float] = []
    node.create_timer(0.01, lambda: ticks.append(time.monotonic()))
    wait_until(lambda: len(ticks) >= 5, 30, "five timer calls")


def test_services_clients_guards_and_coroutines(node) -> None:
    from rcl_interfaces.srv import GetParameters
    from std_msgs.msg import String

    srv = node.create_service(GetParameters, "/test/lean/get",
                              lambda req, res: (res.values.extend([]), res)[1])
    assert srv is not None
    client = node.create_client(GetParameters, "/test/lean/get")
    wait_until(client.service_is_ready, 30, "the service")
    answered = threading.Event()
    future = client.call_async(GetParameters.Request(names=["x"]))
    future.add_done_callback(lambda _f: answered.set())  # run by the executor, as a task
    assert answered.wait(30) and future.result() is not None

    guarded = threading.Event()
    gc = node.create_guard_condition(guarded.set)
    gc.trigger()
    assert guarded.wait(30)

    got: list[str] = []

    async def on_msg(msg: String) -> None:
        got.append(msg.data)

    pub = node.create_publisher(String, "/test/lean/async", 10)
    node.create_subscription(String, "/test/lean/async", on_msg, 10)
    wait_until(lambda: pub.get_subscription_count() > 0, 30, "the subscription")
    pub.publish(String(data="hello"))
    wait_until(lambda: got == ["hello"], 30, "a coroutine callback")


def test_qos_events_are_still_delivered(node) -> None:
    """Incompatible QoS (a reliable reader, a best-effort writer) is reported, within about a second."""
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    seen = threading.Event()
    callbacks = SubscriptionEventCallbacks(incompatible_qos=lambda e: seen.set())
    reliable = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(String, "/test/lean/qos", lambda m: None, reliable, event_callbacks=callbacks)
    best_effort = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    node.create_publisher(String, "/test/lean/qos", best_effort)
    assert seen.wait(30)


def test_spin_once_returns_after_its_timeout(ros_context) -> None:
    from rclpy.node import Node

    from hri_physio_bridge.executor import LeanExecutor

    node = Node("lean_executor_timeout", context=ros_context)
    executor = LeanExecutor(context=ros_context)
    executor.add_node(node)
    try:
        t0 = time.monotonic()
        executor.spin_once(timeout_sec=0.2)
        assert 0.15 <= time.monotonic() - t0 < 5.0
    finally:
        executor.shutdown()
        node.destroy_node()

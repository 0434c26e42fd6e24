"""MessageArrivals: the recorder's wait between passes ends when a message arrives, not on a poll.

Real rclpy subscriptions on a node no executor spins (as the recorder's): the wait says which topics
hold messages, and only those; with nothing published it lasts its timeout; wake() ends it early
from another thread (a stop signal).
"""

from __future__ import annotations

import threading
import time
import uuid

from helpers import wait_until
from hri_physio_bridge.qos import event_qos
from hri_physio_bridge.ros_tools import MessageArrivals


def test_the_wait_names_the_topics_that_hold_messages_and_otherwise_lasts_its_timeout(ros_context) -> None:
    import rclpy
    from std_msgs.msg import String

    suffix = uuid.uuid4().hex[:8]
    node = rclpy.create_node(f"arrivals_{suffix}", context=ros_context, start_parameter_services=False)
    try:
        topics = [f"/test_arrivals_{suffix}_{k}" for k in ("a", "b", "c")]
        subs = {t: node.create_subscription(String, t, lambda _m: None, event_qos(), raw=True)
                for t in topics}
        pubs = {t: node.create_publisher(String, t, event_qos()) for t in topics}
        wait_until(lambda: all(p.get_subscription_count() == 1 for p in pubs.values()), 20, "matching")
        arrivals = MessageArrivals(node)

        began = time.monotonic()
        assert arrivals.wait(subs, 0.3) == []
        assert time.monotonic() - began >= 0.25  # nothing came: it slept, it did not return at once

        pubs[topics[1]].publish(String(data="x"))
        began = time.monotonic()
        assert arrivals.wait(subs, 10.0) == [topics[1]]
        assert time.monotonic() - began < 5.0
        # Not taken yet: still there, and named again.
        assert arrivals.wait(subs, 0.0) == [topics[1]]
        with subs[topics[1]].handle:
            assert subs[topics[1]].handle.take_message(String, True) is not None
        pubs[topics[0]].publish(String(data="y"))
        pubs[topics[2]].publish(String(data="z"))
        wait_until(lambda: sorted(arrivals.wait(subs, 0.0)) == [topics[0], topics[2]], 10, "both topics")

        # A topic added later is waited on too (the wait set grows with the subscriptions).
        late = f"/test_arrivals_{suffix}_late"
        subs[late] = node.create_subscription(String, late, lambda _m: None, event_qos(), raw=True)
        pub = node.create_publisher(String, late, event_qos())
        wait_until(lambda: pub.get_subscription_count() == 1, 20, "matching")
        pub.publish(String(data="w"))
        wait_until(lambda: late in arrivals.wait(subs, 1.0), 10, "the late topic")
    finally:
        node.destroy_node()


def test_wake_ends_a_wait_early_from_another_thread(ros_context) -> None:
    import rclpy
    from std_msgs.msg import String

    suffix = uuid.uuid4().hex[:8]
    node = rclpy.create_node(f"arrivals_{suffix}", context=ros_context, start_parameter_services=False)
    try:
        subs = {"/quiet": node.create_subscription(String, f"/test_quiet_{suffix}", lambda _m: None,
                                                   event_qos(), raw=True)}
        arrivals = MessageArrivals(node)
        threading.Timer(0.2, arrivals.wake).start()
        began = time.monotonic()
        assert arrivals.wait(subs, 30.0) == []
        assert time.monotonic() - began < 15.0
    finally:
        node.destroy_node()

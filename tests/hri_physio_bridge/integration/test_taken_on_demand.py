"""Subscriptions no executor spins: the middleware keeps their messages until taken (issue 28).

The launcher watches its receivers' output this way (only a restart needs it). Two things matter:
every message published since the last take is handed over in order, up to the QoS depth, and the
writer sees its messages acknowledged although no one has taken them (a receiver stopping waits for
its subscribers' acknowledgements: an untaken reader must not make it wait). The publisher is
another process, as a receiver is.
"""

from __future__ import annotations

import subprocess
import sys
import uuid

from conftest import ros_env
from hri_physio_bridge.qos import frame_qos
from hri_physio_bridge.ros_tools import TakenOnDemand

PUBLISHER = """
import sys, time
import rclpy
from rclpy.duration import Duration
from std_msgs.msg import Float64MultiArray
from hri_physio_bridge.qos import frame_qos

topic, first, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
rclpy.init()
node = rclpy.create_node("on_demand_publisher")
pub = node.create_publisher(Float64MultiArray, topic, frame_qos())
end = time.monotonic() + 30
while pub.get_subscription_count() < 2 and time.monotonic() < end:
    time.sleep(0.05)
for i in range(first, first + count):
    pub.publish(Float64MultiArray(data=[float(i)]))
print("acked" if pub.wait_for_all_acked(Duration(seconds=10)) else "not acked", flush=True)
node.destroy_node()
rclpy.shutdown()
"""


def publish(topic: str, first: int, count: int) -> str:
    done = subprocess.run([sys.executable, "-c", PUBLISHER, topic, str(first), str(count)], env=ros_env(),
                          capture_output=True, text=True, timeout=90)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def values(messages: list) -> list[int]:
    return [int(m.data[0]) for m in messages]


def test_untaken_messages_are_acknowledged_kept_to_their_depth_and_taken_in_order(ros_context) -> None:
    from std_msgs.msg import Float64MultiArray

    topic = f"/test_on_demand_{uuid.uuid4().hex[:8]}"
    reader = TakenOnDemand(f"on_demand_{uuid.uuid4().hex[:8]}", context=ros_context)
    try:
        reader.subscribe("all", Float64MultiArray, topic, frame_qos())
        reader.subscribe("newest", Float64MultiArray, topic, frame_qos(3))
        assert publish(topic, 0, 50) == "acked"  # nothing took them: the middleware acknowledged them
        assert values(reader.take("all")) == list(range(50))
        assert reader.take("all") == []
        assert values(reader.take("newest")) == [47, 48, 49]  # the depth, the newest kept
        assert publish(topic, 50, 5) == "acked"
        assert values(reader.take("all")) == list(range(50, 55))
        assert values(reader.take("newest")) == [52, 53, 54]
    finally:
        reader.destroy()

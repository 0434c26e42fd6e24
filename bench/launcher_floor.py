"""The least the session's launcher can cost: a process that does only its ROS work.

The launcher (``hri_physio_session``) drives the session's sim clock: a ``/clock`` message every
``CLOCK_STEP`` of sim time (ten a second at 1x), sent to every process on that clock. It also takes the
messages of every topic it subscribes to: heart rate, the coach's state and events, robot commands and
answers, media status, and so on. This process does that and nothing else. In the session's ROS domain it
subscribes to each topic the launcher's node subscribes to, with the launcher's QoS, and drops each
message. The launcher's on-demand readers (its ``<node>_<suffix>`` nodes) are created too and never
read. It publishes a clock like the launcher's, at the same rate and with the same QoS, from its main
thread, and spins on the executor thread the launcher uses. The clock goes on a topic of its own,
because the session's ``/clock`` must have one source. It reaches as many follower processes
(``floor_node.py --clock-topic``) as there are processes on the session's ``/clock``.

``bench_loop.py`` runs it in a window of its own, while the session still runs, and prints its CPU
beside the launcher's. The difference is what the launcher's own work costs: supervision, progress, the
clock guard, its callbacks. It says ``ready`` on stdout once the followers hear its clock and its
subscriptions are matched, then runs until SIGINT or SIGTERM. Everything here runs at nice 19, as
floor_node.py does.

    python bench/launcher_floor.py --domain 42
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import rclpy
from rclpy.qos import HistoryPolicy, QoSProfile

from hri_physio_bridge.ros_tools import ExecutorThread, clock_message
from hri_physio_bringup.clock import CLOCK_STEP
from hri_physio_bringup.session import CLOCK_DEPTH

HERE = Path(__file__).resolve().parent
#: The launcher's node: ``session_launcher_<4 hex>`` (see BackgroundNode); its on-demand readers' nodes
#: add ``_<suffix>``.
LAUNCHER_NODE = "session_launcher_"
#: Depth of each subscription here (the graph does not tell the launcher's history depth).
DEPTH = 10


def message_class(type_name: str) -> Any:
    """``std_msgs/msg/String`` -> the class."""
    package, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def settled(snapshot: Any, timeout: float, what: str, steady: float = 3.0) -> Any:
    """``snapshot()`` once it is non-empty and has not changed for ``steady`` s: discovery fills the
    graph a participant at a time, and a first look can miss some."""
    deadline = time.monotonic() + timeout
    last, since = None, time.monotonic()
    while time.monotonic() < deadline:
        now = snapshot()
        if now != last:
            last, since = now, time.monotonic()
        elif now and time.monotonic() - since >= steady:
            return now
        time.sleep(0.2)
    raise SystemExit(f"launcher_floor.py: {what} not seen (or still changing) after {timeout:g} s")


def wait_for(condition: Any, timeout: float, what: str) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.2)
    raise SystemExit(f"launcher_floor.py: {what} not seen after {timeout:g} s")


def launcher_nodes(node: Any) -> list[tuple[str, str]]:
    """The launcher's node and its on-demand readers' nodes (name, namespace), its own first."""
    found = [(n, ns) for n, ns in node.get_node_names_and_namespaces() if n.startswith(LAUNCHER_NODE)]
    return sorted(found, key=lambda pair: len(pair[0]))


def subscriptions_of(node: Any, name: str, namespace: str) -> list[tuple[str, Any, QoSProfile]]:
    """(topic, message class, QoS) of each subscription of node ``name``, as the graph shows it."""
    out = []
    for topic, types in node.get_subscriber_names_and_types_by_node(name, namespace):
        infos = [i for i in node.get_subscriptions_info_by_topic(topic) if i.node_name == name]
        if not infos or not types:
            continue
        seen = infos[0].qos_profile
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=seen.reliability,
                         durability=seen.durability)
        out.append((topic, message_class(types[0]), qos))
    return out


def clock_followers(node: Any) -> int:
    """Processes (DDS participants) on the session's /clock, the bench's own nodes aside."""
    infos = node.get_subscriptions_info_by_topic("/clock")
    return len({bytes(i.endpoint_gid[:12]) for i in infos if not i.node_name.startswith("bench_")})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--domain", type=int, required=True, help="the session's ROS domain")
    args = parser.parse_args()
    os.nice(19)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.domain)
    tag = uuid.uuid4().hex[:6]
    node = rclpy.create_node(f"bench_launcher_floor_{tag}", context=context)
    on_demand = rclpy.create_node(f"bench_launcher_floor_{tag}_on_demand", context=context)

    def graph() -> tuple[Any, ...]:
        nodes = launcher_nodes(node)
        subscriptions = [[(topic, cls.__name__, str(qos.reliability), str(qos.durability))
                          for topic, cls, qos in subscriptions_of(node, *pair)] for pair in nodes]
        return (tuple(nodes), repr(subscriptions), clock_followers(node)) if nodes else ()

    nodes, _, followers_wanted = settled(graph, 60.0, f"the launcher's node ({LAUNCHER_NODE}*)")
    taken = 0
    for i, (name, namespace) in enumerate(nodes):
        target = node if i == 0 else on_demand  # the launcher spins its own node only
        for topic, cls, qos in subscriptions_of(node, name, namespace):
            target.create_subscription(cls, topic, lambda _msg: None, qos)
            taken += 1
    topic = f"/bench_launcher_floor_{tag}/clock"
    clock_pub = node.create_publisher(message_class("rosgraph_msgs/msg/Clock"), topic, CLOCK_DEPTH)
    cmd = [sys.executable, str(HERE / "floor_node.py"), "--domain", str(args.domain), "--clock-topic", topic]
    followers = [subprocess.Popen(cmd) for _ in range(followers_wanted)]
    spinner = ExecutorThread(node, context=context)

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda _signum, _frame: stop.set())
    signal.signal(signal.SIGTERM, lambda _signum, _frame: stop.set())
    try:
        wait_for(lambda: clock_pub.get_subscription_count() >= followers_wanted or stop.is_set(), 60.0,
                 f"{followers_wanted} follower(s) on {topic}")
        print(f"ready: a clock to {followers_wanted} process(es), {taken} subscription(s) of the launcher's "
              f"{len(nodes)} node(s)", flush=True)
        t0, sim0, steps = time.monotonic(), 1_000_000.0, 0
        while not stop.is_set():  # paced as the launcher's loop paces its clock at 1x
            steps += 1
            clock_pub.publish(clock_message(sim0 + steps * CLOCK_STEP))
            stop.wait(max(0.0, t0 + steps * CLOCK_STEP - time.monotonic()))
    finally:
        for follower in followers:
            follower.send_signal(signal.SIGINT)
        for follower in followers:
            try:
                follower.wait(30)
            except subprocess.TimeoutExpired:
                follower.kill()
        spinner.close()
        on_demand.destroy_node()
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    main()

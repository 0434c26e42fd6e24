"""The least a node on a session's sim clock costs: an rclpy node that only follows ``/clock``.

A node with ``use_sim_time`` wakes on every ``/clock`` message (ten a second at 1x) however little
else it does. This one has nothing but what every rclpy node has (parameter services, the clock
subscription rclpy makes for sim time) and spins on the project's executor, as the session's nodes
do. ``bench_loop.py`` runs it in the session's ROS domain beside the session and prints its CPU as
the floor under the waiting nodes' figures. Runs until SIGINT or SIGTERM.

It runs at the lowest priority (nice 19): it wakes on every ``/clock`` step, the instants when the
session's nodes wake too, and a measuring instrument must not delay the loop it measures (the
input path's latency is measured in the same run). Its CPU time is the same at any priority.

``--clock-topic`` follows another topic instead (remapped, as ``-r /clock:=...`` would): the
followers of ``launcher_floor.py``'s clock.

    python bench/floor_node.py --domain 42
"""

from __future__ import annotations

import argparse
import os
import signal
import uuid

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

from hri_physio_bridge.executor import LeanExecutor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--domain", type=int, required=True, help="the session's ROS domain")
    parser.add_argument("--clock-topic", default="/clock", help="the clock to follow (default /clock)")
    args = parser.parse_args()
    os.nice(19)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.domain)
    node = rclpy.create_node(f"bench_floor_{uuid.uuid4().hex[:6]}", context=context,
                             parameter_overrides=[Parameter("use_sim_time", value=True)],
                             cli_args=["--ros-args", "-r", f"/clock:={args.clock_topic}"])
    executor = LeanExecutor(context=context)
    executor.add_node(node)

    stopped: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, _frame: stopped.append(signum))
    signal.signal(signal.SIGTERM, lambda signum, _frame: stopped.append(signum))
    try:
        while not stopped and context.ok():
            executor.spin_once(timeout_sec=0.5)  # a stop is seen within this
    except ExternalShutdownException:
        pass
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    main()

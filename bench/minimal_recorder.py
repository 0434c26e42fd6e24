"""The least a Python ROS 2 recorder can do: one raw rclpy subscription -> rosbags Writer.

A baseline for bench_recorder.py (not part of the project): no graph polling, no durability
(flushes), no repair, no metadata beyond what rosbags writes. It logs progress in the
recorder's format so the benchmark measures both the same way.

With ``take-only`` it writes nothing: it takes the raw messages straight from the
subscription's handle in batches (the recorder's own receive path) and drops them. That is
the ceiling of any rclpy recorder on this machine, whatever its writer.

Usage: python bench/minimal_recorder.py TOPIC TYPE OUTPUT_DIR STATUS_PERIOD [write|take-only]
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from pathlib import Path


def main() -> int:
    topic, msgtype, out, period = sys.argv[1], sys.argv[2], Path(sys.argv[3]), float(sys.argv[4])
    take_only = sys.argv[5:] == ["take-only"]
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from std_msgs.msg import Float64MultiArray, String

    from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    writer.open()
    conn = writer.add_connection(topic, msgtype, msgdef=message_definition(msgtype),
                                 rihs01=installed_type_hash(msgtype) or "")
    counts = [0, 0]

    def on_msg(data: bytes) -> None:
        writer.write(conn, time.time_ns(), data)
        counts[0] += 1
        counts[1] += len(data)

    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node("minimal_recorder")
    cls = String if msgtype.endswith("/String") else Float64MultiArray
    depth = 10000 if take_only else 1000
    sub = node.create_subscription(cls, topic, on_msg, QoSProfile(depth=depth), raw=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    next_status = time.monotonic() + period
    while not stop.is_set():
        if take_only:
            with sub.handle:
                while (item := sub.handle.take_message(sub.msg_type, True)) is not None:
                    counts[0] += 1
                    counts[1] += len(item[0])
            time.sleep(0.002)
        else:
            executor.spin_once(timeout_sec=0.01)
        if time.monotonic() >= next_status:
            next_status += period
            print(f"[INFO] [{time.time():.6f}] [recorder]: minimal; {counts[0]} messages, "
                  f"{counts[1] / 1e6:.3f} MB payload", file=sys.stderr, flush=True)
    writer.close()
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())

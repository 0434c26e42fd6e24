"""Small rclpy helpers for launchers and tools that watch or drive a running system."""

from __future__ import annotations

import threading
import uuid
from typing import Any


def clock_message(t: float) -> Any:
    """A rosgraph_msgs/Clock for ``t`` seconds (nanoseconds rounded, never 1e9)."""
    from rosgraph_msgs.msg import Clock

    msg = Clock()
    msg.clock.sec = int(t)
    msg.clock.nanosec = min(round((t - int(t)) * 1e9), 999_999_999)
    return msg


class ExecutorThread:
    """A single-threaded executor spinning ``nodes`` on a daemon thread until :meth:`close`.

    ``context`` is the rclpy context of the nodes (None: the default one).
    """

    def __init__(self, *nodes: Any, context: Any = None) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            self.executor.add_node(node)
        self._running = True
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while self._running:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self, join_timeout: float = 2.0) -> None:
        """Stop spinning and shut the executor down (the nodes stay for their owner to destroy)."""
        self._running = False
        if self._thread.is_alive():
            self._thread.join(join_timeout)
        self.executor.shutdown(timeout_sec=1.0)


class BackgroundNode:
    """An rclpy node spun on its own thread, in a process that handles its own signals.

    rclpy is initialised without its signal handlers, so the owner's SIGINT/SIGTERM handlers
    decide how to stop. Create subscriptions on ``self.node`` before or after ``start()``.
    """

    def __init__(self, name_prefix: str) -> None:
        import rclpy

        self._rclpy = rclpy
        rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"{name_prefix}_{uuid.uuid4().hex[:4]}")
        self._spinner: ExecutorThread | None = None

    def start(self) -> None:
        self._spinner = ExecutorThread(self.node)

    def close(self) -> None:
        if self._spinner is not None:
            self._spinner.close()
        self.node.destroy_node()
        self._rclpy.try_shutdown()

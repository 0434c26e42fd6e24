"""ROS 2 topic streamer: frames as Float64MultiArray, markers as JSON String.

Address: the topic name, e.g. ``ros:/physio/polar_h10/ecg``. The streamer
needs an rclpy node (the caller owns it and spins it); subscriptions and
publishers are reliable with a deep queue so bursts are not dropped.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge.frames import Frame, FrameFormatError
from hri_physio_bridge.qos import frame_qos
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.ros_frames import frame_to_msg, msg_to_frame, msg_to_marker, string_frame_to_msgs
from hri_physio_bridge.streamers.base import (
    Streamer,
    StreamerError,
    StreamSpec,
    numpy_dtype,
)


class RosStreamer(Streamer):
    scheme = "ros"

    def __init__(
        self,
        address: str,
        node: Node | None,
        depth: int = 1000,
        on_bad_message: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(address)
        if node is None:
            raise StreamerError(f"ros:{address} needs a ROS 2 node (none was given)")
        if not address.startswith("/"):
            raise ValueError(f"ROS topic must be absolute (start with '/'), got {address!r}")
        self.node = node
        self.topic = address
        self.depth = depth
        self._queue: queue.Queue[Frame] = queue.Queue()
        self._sub = None
        self._pub = None
        self._expected: StreamSpec | None = None
        self._last_seq: dict[bytes, int] = {}  # per publisher: the last sequence number seen
        # Every bad message is counted; at most one line per kind of problem every 5 s is logged.
        self._bad_log = RateLimitedLog(on_bad_message or (lambda text: node.get_logger().error(text)))

    # -- input ---------------------------------------------------------------
    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        # A subscription needs no publisher to exist: nothing to wait for (timeout, stop unused).
        self.close()
        spec = expected or StreamSpec(name=self.topic)
        self._expected = spec
        self._np_dtype = numpy_dtype(spec.dtype)
        if spec.is_string:
            msg_type, callback = String, self._on_marker
        else:
            msg_type, callback = Float64MultiArray, self._on_frame
        self._sub = self.node.create_subscription(msg_type, self.topic, callback, frame_qos(self.depth))
        self.spec = spec
        return spec

    def _count_skipped(self, info: dict) -> None:
        """Count messages a publisher sent that never reached us (its sequence numbers skip).

        A full reader queue drops the oldest messages without any middleware event; the
        publisher's sequence numbers show it. Counted in ``lost_messages`` and logged, rate-limited.
        """
        seq = info.get("publication_sequence_number")
        if not seq:  # None (or 0): this middleware does not number messages
            return
        gid = info.get("publisher_gid") or {}
        key = bytes(gid.get("data", b""))
        last = self._last_seq.get(key)
        self._last_seq[key] = seq
        if last is not None and seq > last + 1:
            skipped = seq - last - 1
            self.lost_messages += skipped
            self._bad_log.report("lost", f"{self.topic}: {skipped} message(s) lost before they were taken "
                                 f"(input queue of {self.depth} full?)", "message(s) lost", count=skipped)

    def backlog(self) -> int:
        return self._queue.qsize()

    def _reject(self, kind: str, why: str) -> None:
        """Count a message that cannot be used; log it, rate-limited per ``kind`` of problem."""
        self.bad_messages += 1
        self._bad_log.report(kind, f"{self.topic}: message rejected: {why}", "message(s) rejected")

    def _on_frame(self, msg: Float64MultiArray, info: dict) -> None:
        self._count_skipped(info)
        try:
            frame = msg_to_frame(msg)
        except FrameFormatError as exc:
            self._reject("layout", f"malformed frame layout: {exc}")
            return
        spec = self._expected
        if spec is not None and frame.num_channels != spec.channel_count:
            self._reject(
                "channels", f"frame has {frame.num_channels} channel(s), num_channels is {spec.channel_count}"
            )
            return
        if self._np_dtype.kind == "i":
            values = frame.values
            if not np.all(np.isfinite(values)) or np.any(values != np.rint(values)):
                self._reject("non-integer", f"non-integer values on a {spec.dtype} stream")
                return
            frame = Frame(frame.timestamps, values.astype(self._np_dtype), frame.channels)
        self._queue.put(frame)

    def _on_marker(self, msg: String, info: dict) -> None:
        self._count_skipped(info)
        try:
            t, data = msg_to_marker(msg)
        except FrameFormatError as exc:
            self._reject("marker", str(exc))
            return
        self._queue.put(Frame(np.array([t]), np.array([[data]], dtype=object), self.spec.channels))

    def receive(self, timeout: float = 0.1) -> Frame | None:
        if self._sub is None:
            raise StreamerError(f"{self.uri} is not open as an input")
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    # -- output --------------------------------------------------------------
    def open_output(self, spec: StreamSpec) -> None:
        self.close()
        msg_type = String if spec.is_string else Float64MultiArray
        self._pub = self.node.create_publisher(msg_type, self.topic, frame_qos(self.depth))
        self.spec = spec

    def publish(self, frame: Frame) -> None:
        spec = self._check_publishable(frame, self._pub is not None, f"{self.topic} carries")
        if spec.is_string:
            for msg in string_frame_to_msgs(frame):
                self._pub.publish(msg)
        else:
            self._pub.publish(frame_to_msg(frame))

    counts_consumers = True

    def has_consumers(self) -> bool:
        return self.consumer_count() > 0

    def consumer_count(self) -> int:
        return self._pub.get_subscription_count() if self._pub is not None else 0

    @property
    def publisher(self) -> Any:
        """The output's rclpy publisher (None unless open as an output)."""
        return self._pub

    def close(self, ack_timeout: float = 1.0) -> None:
        """Close; an output first waits up to ``ack_timeout`` s for its last frames to be acknowledged
        (0 when the caller already waited for several outputs at once: ``ros_tools.wait_all_acked``)."""
        if self._sub is not None:
            self.node.destroy_subscription(self._sub)
            self._sub = None
        if self._pub is not None:
            # Reliable delivery of the last frames before the publisher goes away.
            if ack_timeout > 0:
                self._pub.wait_for_all_acked(Duration(nanoseconds=int(ack_timeout * 1e9)))
            self.node.destroy_publisher(self._pub)
            self._pub = None

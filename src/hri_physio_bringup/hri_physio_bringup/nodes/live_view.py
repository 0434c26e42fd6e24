"""live_view: the session served live to Foxglove over its WebSocket protocol (foxglove-sdk).

Examples::

    live_view                                  # ws://127.0.0.1:8765, this host only
    live_view --host 0.0.0.0 --port 8765       # every interface: anyone reaching the port sees the data
    hri_physio_session --live                  # what the session starts on the station

Each topic of :data:`hri_physio_bringup.live.LIVE_TOPICS` has a Foxglove channel of the same name; the
topic is subscribed to on ROS (raw, serialized messages, converted here) only while a client watches
its channel, so with no viewer connected the node holds no subscription and costs nothing. Messages are
logged at the station's wall clock as they arrive (the session's time is in each message: an event's
``t``, a frame's sample stamps). Not on ``use_sim_time``: that would subscribe it to ``/clock``, hundreds
of messages a second at 30x, watched or not.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from typing import Any

import foxglove
from foxglove.channels import CompressedImageChannel, LogChannel
from foxglove.messages import CompressedImage, Log, LogLevel, Timestamp
from rcl_interfaces.msg import Log as RosLog
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CompressedImage as RosCompressedImage
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge import topics
from hri_physio_bridge.node_runner import ManagedNode, run_node
from hri_physio_bridge.qos import command_qos, event_qos, frame_qos, latched_qos
from hri_physio_bringup.live import (
    FRAME,
    FRAME_SCHEMA,
    IMAGE,
    LIVE_NODE,
    LIVE_TOPICS,
    LOG,
    TEXT,
    TEXT_SCHEMA,
    Demand,
    LiveViewConfig,
    frame_message,
    log_level,
    text_message,
)

_MSG_TYPES = {FRAME: Float64MultiArray, TEXT: String, IMAGE: RosCompressedImage, LOG: RosLog}
#: foxglove.Log levels by number (live.log_level's).
_LEVELS = (LogLevel.Unknown, LogLevel.Debug, LogLevel.Info, LogLevel.Warning, LogLevel.Error, LogLevel.Fatal)


class LiveViewError(Exception):
    """The server could not start (the port is taken, the address is not this host's)."""


def _qos(topic: str, kind: str) -> Any:
    if kind == FRAME:
        return frame_qos()
    if topic == topics.COACH_STATE:
        return latched_qos()  # the state the coach had when the viewer started, at once
    if topic in (topics.QT_COMMANDS, topics.QT_REPLIES):
        return command_qos()
    if kind == TEXT:
        return event_qos()
    return 10


class LiveViewNode(ManagedNode):
    """ROS 2 shell: the session's topics in, Foxglove channels out (WebSocket server).

    A topic is subscribed to on ROS while some viewer watches its channel (:class:`Demand`): the
    server's subscribe and unsubscribe callbacks (on the SDK's thread) update the demand and trigger a
    guard condition, and the executor's thread subscribes or unsubscribes. A latched topic (the coach's
    state) is subscribed to transient-local: a new viewer gets its last message at once.
    """

    def __init__(self, config: LiveViewConfig, **kwargs: Any) -> None:
        super().__init__(LIVE_NODE, **kwargs)
        self.config = cfg = self.declare_config(config)
        self._lock = threading.Lock()
        self.sent = 0
        self._demand = Demand()
        self._watching: dict[str, Any] = {}
        self._changed = self.create_guard_condition(self._apply_demand)
        self.channels: dict[str, Any] = {topic: self._channel(topic, kind)
                                         for topic, kind in LIVE_TOPICS.items()}
        self.server: Any = None
        try:
            self.server = foxglove.start_server(name=cfg.name, host=cfg.host, port=cfg.port,
                                                server_listener=_Listener(self))
        except Exception as exc:  # the SDK raises its own error types for a taken port or a bad address
            raise LiveViewError(f"cannot serve on {cfg.host}:{cfg.port}: {exc}") from None
        self.get_logger().info(
            f"serving the session live on ws://{cfg.host}:{self.server.port} (Foxglove: open connection, "
            f"Foxglove WebSocket; layout src/hri_physio_bringup/config/foxglove_layout.json): "
            f"{len(self.channels)} topics")

    @staticmethod
    def _channel(topic: str, kind: str) -> Any:
        if kind == FRAME:
            return foxglove.Channel(topic, schema=FRAME_SCHEMA)
        if kind == TEXT:
            return foxglove.Channel(topic, schema=TEXT_SCHEMA)
        if kind == IMAGE:
            return CompressedImageChannel(topic)
        return LogChannel(topic)

    # -- viewers (the SDK's thread) --------------------------------------------------------------
    def viewer_subscribed(self, topic: str, client: int) -> None:
        with self._lock:
            self._demand.subscribe(topic, client)
        self._changed.trigger()

    def viewer_unsubscribed(self, topic: str, client: int) -> None:
        with self._lock:
            self._demand.unsubscribe(topic, client)
        self._changed.trigger()

    # -- ROS (the executor's thread) -------------------------------------------------------------
    def _apply_demand(self) -> None:
        with self._lock:
            add, drop = self._demand.changes(set(self._watching))
        for topic in sorted(drop):
            self.destroy_subscription(self._watching.pop(topic))
        for topic in sorted(add):
            kind = LIVE_TOPICS[topic]
            self._watching[topic] = self.create_subscription(
                _MSG_TYPES[kind], topic, self._forward(topic, kind), _qos(topic, kind), raw=True)
        if add or drop:
            self.get_logger().info(f"viewers watch {len(self._watching)} of {len(self.channels)} topics"
                                   + (f" (+{', '.join(sorted(add))})" if add else ""))

    def _now_ns(self) -> int:
        return int(self.get_clock().now().nanoseconds)

    def _forward(self, topic: str, kind: str) -> Callable[[bytes], None]:
        channel, msg_type = self.channels[topic], _MSG_TYPES[kind]
        convert = {FRAME: _frame, TEXT: _text, IMAGE: _image, LOG: _log}[kind]

        def callback(raw: bytes) -> None:
            channel.log(convert(deserialize_message(raw, msg_type)), log_time=self._now_ns())
            self.sent += 1  # the executor's thread only

        return callback

    def run(self, stop: threading.Event) -> int:
        stop.wait()
        return 0

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
        for channel in self.channels.values():
            channel.close()
        self.get_logger().info(f"live view closed: {self.sent} messages sent to viewers")


class _Listener:
    """The server's callbacks (foxglove.websocket.ServerListener), on the SDK's thread."""

    def __init__(self, node: LiveViewNode) -> None:
        self.node = node

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.node.viewer_subscribed(channel.topic, client.id)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self.node.viewer_unsubscribed(channel.topic, client.id)


def _frame(msg: Float64MultiArray) -> dict:
    return frame_message([(d.label, d.size, d.stride) for d in msg.layout.dim], msg.layout.data_offset,
                         msg.data)


def _text(msg: String) -> dict:
    return text_message(msg.data)


def _stamp(stamp: Any) -> Timestamp:
    return Timestamp(sec=int(stamp.sec), nsec=int(stamp.nanosec))


def _image(msg: RosCompressedImage) -> CompressedImage:
    return CompressedImage(timestamp=_stamp(msg.header.stamp), frame_id=msg.header.frame_id,
                           data=bytes(msg.data), format=msg.format)


def _log(msg: RosLog) -> Log:
    return Log(timestamp=_stamp(msg.stamp), level=_LEVELS[log_level(msg.level)], message=msg.msg,
               name=msg.name, file=msg.file, line=int(msg.line))


def main(argv: list[str] | None = None) -> int:
    return run_node(
        LIVE_NODE, LiveViewConfig, LiveViewNode, argv=argv, startup_errors=(LiveViewError,),
        description="Serve the session's heart rate, zone, phase and activity, adaptations, robot actions, "
        "media status, video preview and logs live to Foxglove (WebSocket protocol, JSON schemas); "
        "src/hri_physio_bringup/config/foxglove_layout.json works on it as on the session's bag.",
    )


if __name__ == "__main__":
    sys.exit(main())

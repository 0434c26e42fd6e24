"""The live view: what the station serves to Foxglove while a session runs (no rclpy, no foxglove).

``hri_physio_session --live [HOST:]PORT`` starts ``live_view`` (:mod:`hri_physio_bringup.nodes.live_view`)
on the station. It subscribes to the session's topics below and logs each message on a Foxglove
channel of the same name, over Foxglove's WebSocket protocol. The messages keep the shape they have in
the bag (a frame is ``{"layout": {"dim": [...], "data_offset": 0}, "data": [t, value, ...]}``, an
event or a state ``{"data": "<JSON text>"}``), so ``config/foxglove_layout.json``'s message paths
(``/physio/polar_h10/hr.data[1]``) and user scripts (``JSON.parse(message.data)``) work on the live
connection as on the bag. A topic is subscribed to on ROS only while a viewer watches its channel
(:class:`Demand`): with nobody connected the live view holds no subscription and costs nothing. They
are JSON with a JSON schema each (:data:`FRAME_SCHEMA`,
:data:`TEXT_SCHEMA`); the video preview is a ``foxglove.CompressedImage`` and the nodes' logs
(``/rosout``) ``foxglove.Log`` (the SDK's own schemas), which Foxglove's Image and Log panels show.

Non-finite samples (a NaN heart rate) are sent as ``null``: JSON has no NaN.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from typing import Any

from pydantic import field_validator

from hri_physio_bridge import topics
from hri_physio_bridge.config import NodeConfig, option

LIVE_NODE = "live_view"
DEFAULT_HOST, DEFAULT_PORT = "127.0.0.1", 8765
#: ``--live`` given without a value.
DEFAULT_LIVE = f"{DEFAULT_HOST}:{DEFAULT_PORT}"

#: The session's topics the live view serves, by kind: frames (Float64MultiArray), text (String: JSON
#: events and states, command lines), the video preview (CompressedImage), the nodes' logs.
FRAME, TEXT, IMAGE, LOG = "frame", "text", "image", "log"
ROSOUT = "/rosout"
LIVE_TOPICS: dict[str, str] = {
    topics.POLAR_H10_HR: FRAME,  # heart rate from the strap
    topics.POLAR_H10_ECG_HR: FRAME,  # heart rate from the processor
    topics.POLAR_H10_ECG: FRAME,  # the ECG strip
    topics.COACH_STATE: TEXT,  # zone, phase, activity, pace
    topics.COACH_EVENTS: TEXT,  # adaptations (rule updates), phases, behaviours
    topics.QT_COMMANDS: TEXT,  # robot actions the coach commanded
    topics.QT_REPLIES: TEXT,
    topics.QT_MOCK_EVENTS: TEXT,  # what the (mock) robot performed
    topics.AUDIO_STATUS: TEXT,  # media status
    topics.VIDEO_STATUS: TEXT,
    topics.SESSION_EVENTS: TEXT,  # restarts, gaps, lab hosts lost and back
    topics.VIDEO_PREVIEW: IMAGE,
    ROSOUT: LOG,
}

#: std_msgs/msg/Float64MultiArray as JSON (a frame: column 0 the timestamps, docs/ARCHITECTURE.md).
FRAME_SCHEMA: dict[str, Any] = {
    "title": "hri_physio.Frame",
    "description": "std_msgs/msg/Float64MultiArray as JSON: a frame of samples x channels, row-major; "
                   "channel 0 is each sample's source timestamp (s); NaN and inf are null",
    "type": "object",
    "properties": {
        "layout": {
            "type": "object",
            "properties": {
                "dim": {"type": "array", "items": {
                    "type": "object",
                    "properties": {"label": {"type": "string"}, "size": {"type": "integer"},
                                   "stride": {"type": "integer"}},
                    "required": ["label", "size", "stride"]}},
                "data_offset": {"type": "integer"},
            },
            "required": ["dim", "data_offset"],
        },
        "data": {"type": "array", "items": {"type": ["number", "null"]}},
    },
    "required": ["layout", "data"],
}
#: std_msgs/msg/String as JSON: the topic's text (most hold one JSON object with a ``t`` field).
TEXT_SCHEMA: dict[str, Any] = {
    "title": "hri_physio.Text",
    "description": "std_msgs/msg/String as JSON: the text the topic carries (events and states: one JSON "
                   "object with its session time t; robot commands: one command line)",
    "type": "object",
    "properties": {"data": {"type": "string"}},
    "required": ["data"],
}

_HOST = re.compile(r"^(?:[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?)(?:\.[A-Za-z0-9-]{1,63})*$")


def parse_live(value: str) -> tuple[str, int]:
    """``[HOST:]PORT`` (``PORT`` alone: on 127.0.0.1) -> (host, port); ValueError says what is expected
    (the configuration model adds the value given)."""
    text = value.strip()
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    elif host.startswith("[") and host.endswith("]"):
        host = host[1:-1]  # [::1]:8765
    if not host or not (_HOST.match(host) or ":" in host):
        raise ValueError(f"expected [HOST:]PORT, e.g. {DEFAULT_LIVE} or 8765")
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ValueError(f"expected [HOST:]PORT with a port from 1 to 65535, e.g. {DEFAULT_LIVE}")
    return host, int(port_text)


def _finite(values: Iterable[float]) -> list[float | None]:
    return [v if math.isfinite(v) else None for v in values]


def frame_message(dims: Sequence[tuple[str, int, int]], data_offset: int, data: Iterable[float]) -> dict:
    """A Float64MultiArray's fields as a :data:`FRAME_SCHEMA` message."""
    return {"layout": {"dim": [{"label": label, "size": int(size), "stride": int(stride)}
                               for label, size, stride in dims],
                       "data_offset": int(data_offset)},
            "data": _finite(float(v) for v in data)}


def text_message(text: str) -> dict:
    """A String's text as a :data:`TEXT_SCHEMA` message."""
    return {"data": text}


#: rcl_interfaces/msg/Log levels -> foxglove.Log levels (1 DEBUG .. 5 FATAL; 0 unknown).
_LOG_LEVELS = {10: 1, 20: 2, 30: 3, 40: 4, 50: 5}


def log_level(ros_level: int) -> int:
    return _LOG_LEVELS.get(int(ros_level), 0)


class Demand:
    """Which topics viewers watch: subscriptions per topic, counted per client (a client that
    disconnects unsubscribes from each of its channels). The node subscribes on ROS only to the topics
    some client watches, so with no viewer it holds no subscription at all. Not thread-safe: the node
    holds its lock around it."""

    def __init__(self) -> None:
        self._clients: dict[str, set[int]] = {}

    def subscribe(self, topic: str, client: int) -> None:
        self._clients.setdefault(topic, set()).add(client)

    def unsubscribe(self, topic: str, client: int) -> None:
        self._clients.get(topic, set()).discard(client)

    def watched(self) -> set[str]:
        return {topic for topic, clients in self._clients.items() if clients}

    def changes(self, subscribed: set[str]) -> tuple[set[str], set[str]]:
        """(topics to subscribe to, topics to drop) given the ROS subscriptions held now."""
        watched = self.watched()
        return watched - subscribed, subscribed - watched


class LiveViewConfig(NodeConfig):
    """Where the live view serves the session (Foxglove's WebSocket protocol)."""

    host: str = option(DEFAULT_HOST, "address to listen on: 127.0.0.1 (this host only) unless told "
                       "otherwise; 0.0.0.0 = every interface (anyone who reaches the port sees the "
                       "participant's data)", min_length=1)
    port: int = option(DEFAULT_PORT, "TCP port of the WebSocket server (0: any free port, logged)",
                       ge=0, le=65535)
    name: str = option("HRI Physio session", "the server's name, shown by Foxglove", min_length=1)

    @field_validator("host")
    @classmethod
    def _host(cls, value: str) -> str:
        parse_live(f"{value}:1" if ":" not in value else f"[{value}]:1")
        return value

"""The one place that knows how QT's own services are reached (client and server side).

QT serves gesture play, speech configuration, volume and motor velocity with its own
service types (``qt_gesture_controller/gesture_play``, ``qt_robot_interface/speech_config``,
``qt_robot_interface/setting_setVolume``, ``qt_motors_controller/set_velocity``). When
their Python interface packages are importable (a real QT installation), backend ``qt``
uses them as they are. Without them (pip-wheel ROS 2 cannot build new interface types)
backend ``json`` serves the same request/response fields over two std_msgs/String topics:

* ``<service>/request``: ``{"id": "<unique>", "t": <sec>, <request fields>}``
* ``<service>/reply``:   ``{"id": "<same>", "t": <sec>, "status": <bool>, "message": "<why>"}``

e.g. ``/qt_robot/gesture/play/request`` ``{"id": "...", "name": "marching", "speed": 1.05}``.
Replies are matched to requests by id, so several clients may share a server. A client
treats the service as available once its request publisher has a subscriber and its reply
subscription has a publisher (the equivalent of ``wait_for_service``). Backend ``auto``
(the default) picks ``qt`` when the QT packages import, else ``json``; mock_qt_robot and
qt_controller make the same choice, so they always speak the same way.
"""

from __future__ import annotations

import importlib
import json
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from hri_physio_bridge import topics
from hri_physio_bridge.qos import command_qos
from hri_physio_bridge.waiting import Clock, wait_until
from qt_controller.config import SERVICE_BACKENDS as BACKENDS
from qt_controller.robot_interface import Outcome


@dataclass(frozen=True)
class ServiceSpec:
    name: str  # the QT service name
    qt_module: str  # Python module of QT's service types
    qt_types: tuple[str, ...]  # class names tried in order (ROS 2 style, then ROS 1 style)
    fields: tuple[tuple[str, type], ...]  # request fields and their types; the response is `status`


GESTURE_PLAY = ServiceSpec(
    topics.QT_GESTURE_PLAY,
    "qt_gesture_controller.srv",
    ("GesturePlay", "gesture_play"),
    (("name", str), ("speed", float)),
)
SPEECH_CONFIG = ServiceSpec(
    topics.QT_SPEECH_CONFIG,
    "qt_robot_interface.srv",
    ("SpeechConfig", "speech_config"),
    (("language", str), ("pitch", int), ("speed", int)),
)
SET_VOLUME = ServiceSpec(
    topics.QT_SET_VOLUME,
    "qt_robot_interface.srv",
    ("SettingSetVolume", "setting_setVolume"),
    (("volume", int),),
)
SET_VELOCITY = ServiceSpec(
    topics.QT_SET_VELOCITY,
    "qt_motors_controller.srv",
    ("SetVelocity", "set_velocity"),
    (("parts", list), ("velocity", int)),
)
ALL_SERVICES = (GESTURE_PLAY, SPEECH_CONFIG, SET_VOLUME, SET_VELOCITY)


def find_qt_type(spec: ServiceSpec) -> Any | None:
    """QT's service class for ``spec`` if its interface package imports, else None."""
    try:
        module = importlib.import_module(spec.qt_module)
    except ImportError:
        return None
    for name in spec.qt_types:
        srv = getattr(module, name, None)
        if srv is not None:
            return srv
    return None


def resolve_backend(backend: str, spec: ServiceSpec) -> str:
    """``auto`` -> ``qt`` or ``json``; ``qt`` without the QT packages is an error."""
    if backend not in BACKENDS:
        raise ValueError(f"service backend must be one of {', '.join(BACKENDS)}, not {backend!r}")
    found = find_qt_type(spec) is not None
    if backend == "qt" and not found:
        raise ValueError(
            f"service backend 'qt' needs {spec.qt_module} ({'/'.join(spec.qt_types)}), which is not "
            "importable here; use 'json' or 'auto'"
        )
    if backend == "auto":
        return "qt" if found else "json"
    return backend


def coerce_request(spec: ServiceSpec, request: Mapping[str, Any]) -> dict[str, Any]:
    """Check a JSON request has every field with the right type; raises ValueError."""
    out: dict[str, Any] = {}
    for name, kind in spec.fields:
        if name not in request:
            raise ValueError(f"missing field {name!r}")
        value = request[name]
        if kind is float and isinstance(value, int | float) and not isinstance(value, bool):
            value = float(value)
        elif kind is int and isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ValueError(f"field {name!r} must be {kind.__name__}, got {value!r}")
        if kind is list and not all(isinstance(v, str) for v in value):
            raise ValueError(f"field {name!r} must be a list of strings, got {value!r}")
        out[name] = value
    return out


def _now(node: Node) -> float:
    return node.get_clock().now().nanoseconds * 1e-9


class ServiceClient:
    """Calls one QT service; :meth:`call` blocks the calling thread (never the executor)."""

    def __init__(self, node: Node, spec: ServiceSpec, backend: str = "auto",
                 clock: Clock = time.monotonic) -> None:
        self.node = node
        self.spec = spec
        self.backend = resolve_backend(backend, spec)
        self._clock = clock
        self._lock = threading.Lock()
        self._pending: dict[str, tuple[threading.Event, list[dict[str, Any]]]] = {}
        if self.backend == "qt":
            self._client = node.create_client(find_qt_type(spec), spec.name)
        else:
            self._pub = node.create_publisher(String, spec.name + "/request", command_qos())
            self._sub = node.create_subscription(String, spec.name + "/reply", self._on_reply, command_qos())

    def available(self) -> bool:
        if self.backend == "qt":
            return self._client.service_is_ready()
        return self._pub.get_subscription_count() > 0 and self._sub.get_publisher_count() > 0

    def wait_available(self, timeout: float) -> bool:
        return wait_until(self.available, timeout, clock=self._clock, poll=0.02)

    def call(self, timeout: float, **fields: Any) -> Outcome:
        """Send one request; success only if the robot answered ``status: true`` in time."""
        start = self._clock()
        if not self.wait_available(timeout):
            return Outcome.failure(f"service {self.spec.name} is not available (is the robot running?)")
        left = max(0.0, timeout - (self._clock() - start))
        if self.backend == "qt":
            return self._call_typed(left, fields)
        return self._call_json(left, fields)

    def _call_typed(self, timeout: float, fields: Mapping[str, Any]) -> Outcome:
        request = self._client.srv_type.Request()
        for key, value in fields.items():
            setattr(request, key, value)
        done = threading.Event()
        future = self._client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            self._client.remove_pending_request(future)
            return Outcome.failure(f"no reply from {self.spec.name} within {timeout:g} s")
        response = future.result()
        if response is None or not response.status:
            return Outcome.failure(f"{self.spec.name} answered status false")
        return Outcome.success()

    def _call_json(self, timeout: float, fields: Mapping[str, Any]) -> Outcome:
        rid = uuid.uuid4().hex
        done = threading.Event()
        box: list[dict[str, Any]] = []
        with self._lock:
            self._pending[rid] = (done, box)
        try:
            self._pub.publish(String(data=json.dumps({"id": rid, "t": _now(self.node), **fields})))
            if not done.wait(timeout):
                return Outcome.failure(f"no reply from {self.spec.name} within {timeout:g} s")
        finally:
            with self._lock:
                self._pending.pop(rid, None)
        reply = box[0]
        message = str(reply.get("message", ""))
        if reply.get("status") is not True:
            return Outcome.failure(
                f"{self.spec.name} answered status false" + (f": {message}" if message else "")
            )
        return Outcome.success(message)

    def _on_reply(self, msg: String) -> None:
        try:
            reply = json.loads(msg.data)
            rid = reply["id"]
        except (ValueError, TypeError, KeyError):
            self.node.get_logger().warning(
                f"ignoring malformed reply on {self.spec.name}/reply: {msg.data!r}"
            )
            return
        with self._lock:
            entry = self._pending.get(rid)
        if entry is not None:  # replies to other clients' requests are not ours
            entry[1].append(reply)
            entry[0].set()


Handler = Callable[[dict[str, Any]], Outcome]


class ServiceServer:
    """Serves one QT service by calling ``handler(fields) -> Outcome`` (used by mock_qt_robot)."""

    def __init__(self, node: Node, spec: ServiceSpec, handler: Handler, backend: str = "auto") -> None:
        self.node = node
        self.spec = spec
        self.handler = handler
        self.backend = resolve_backend(backend, spec)
        if self.backend == "qt":
            self._srv = node.create_service(find_qt_type(spec), spec.name, self._on_typed)
        else:
            self._pub = node.create_publisher(String, spec.name + "/reply", command_qos())
            self._sub = node.create_subscription(String, spec.name + "/request", self._on_request,
                                                 command_qos())

    def _on_typed(self, request: Any, response: Any) -> Any:
        fields = {name: getattr(request, name) for name, _kind in self.spec.fields}
        if "parts" in fields:
            fields["parts"] = list(fields["parts"])
        response.status = bool(self.handler(fields))
        return response

    def _on_request(self, msg: String) -> None:
        try:
            request = json.loads(msg.data)
            if not isinstance(request, dict) or not isinstance(request.get("id"), str):
                raise ValueError("a request is a JSON object with a string 'id'")
        except ValueError as exc:
            self.node.get_logger().warning(f"ignoring malformed request on {self.spec.name}/request: {exc}")
            return
        try:
            outcome = self.handler(coerce_request(self.spec, request))
        except ValueError as exc:
            outcome = Outcome.failure(f"bad request: {exc}")
        reply = {"id": request["id"], "t": _now(self.node), "status": outcome.ok, "message": outcome.message}
        self._pub.publish(String(data=json.dumps(reply)))

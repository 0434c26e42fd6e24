"""The QT service adapter's std-only JSON request/reply over real rclpy: one server, several callers."""

from __future__ import annotations

import json
import threading
from typing import Any

import pytest

from helpers import wait_until
from hri_physio_bridge.ros_tools import ExecutorThread
from qt_controller import qt_services as qs
from qt_controller.robot_interface import Outcome


@pytest.mark.ros
def test_json_request_reply_roundtrip_shared_server_and_errors(ros_context: Any) -> None:
    from rclpy.node import Node
    from std_msgs.msg import String

    server_node = Node("test_server", context=ros_context)
    client_node = Node("test_clients", context=ros_context)
    seen: list[dict[str, Any]] = []

    def handler(fields: dict[str, Any]) -> Outcome:
        seen.append(fields)
        if fields["name"] == "bad":
            return Outcome.failure("unknown gesture 'bad'")
        return Outcome.success(f"playing {fields['name']}")

    qs.ServiceServer(server_node, qs.GESTURE_PLAY, handler, "json")
    a = qs.ServiceClient(client_node, qs.GESTURE_PLAY, "json")
    b = qs.ServiceClient(client_node, qs.GESTURE_PLAY, "json")
    missing = qs.ServiceClient(client_node, qs.SET_VOLUME, "json")
    raw_replies: list[dict[str, Any]] = []
    client_node.create_subscription(String, "/qt_robot/gesture/play/reply",
                                    lambda m: raw_replies.append(json.loads(m.data)), 10)
    raw = client_node.create_publisher(String, "/qt_robot/gesture/play/request", 10)
    spinner = ExecutorThread(server_node, client_node, context=ros_context)
    try:
        assert a.wait_available(20) and b.wait_available(20)
        results: dict[str, Outcome] = {}

        def call(key: str, client: qs.ServiceClient) -> None:
            results[key] = client.call(10, name=key, speed=1.5)

        threads = [threading.Thread(target=call, args=kc) for kc in (("one", a), ("two", b), ("bad", a))]
        for t in threads:
            t.start()
        for t in threads:
            t.join(15)
        assert results["one"] == Outcome(True, "playing one")  # each caller got its own answer
        assert results["two"] == Outcome(True, "playing two")
        assert not results["bad"].ok
        assert results["bad"].message == "/qt_robot/gesture/play answered status false: unknown gesture 'bad'"
        assert sorted(f["name"] for f in seen) == ["bad", "one", "two"]
        assert all(f["speed"] == 1.5 for f in seen)

        n = len(raw_replies)
        raw.publish(String(data=json.dumps({"id": "r1", "name": "x"})))  # no speed
        raw.publish(String(data="not json"))  # ignored: no id to answer
        wait_until(lambda: any(r["id"] == "r1" for r in raw_replies[n:]), 20, "the reply to r1")
        r1 = next(r for r in raw_replies[n:] if r["id"] == "r1")
        assert r1["status"] is False and r1["message"] == "bad request: missing field 'speed'"
        assert isinstance(r1["t"], float)

        nobody = missing.call(0.3, volume=10)
        assert not nobody.ok and "/qt_robot/setting/setVolume is not available" in nobody.message
    finally:
        spinner.close()
        client_node.destroy_node()
        server_node.destroy_node()

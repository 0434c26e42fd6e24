"""live_view: the session's topics served to Foxglove over its WebSocket protocol, checked as a client.

The live view subscribes on ROS only to what a viewer watches: the client's subscriptions bring the
data, its leaving takes the subscriptions away.

One live_view process, fed by this test's own ROS publishers (no session: the session-level check is in
test_session.py); a WebSocket client connects, reads the advertised channels and schemas, subscribes and
decodes what comes.
"""

from __future__ import annotations

import json
import math
import re
import threading

import numpy as np
import psutil
import pytest

from helpers import NodeProcess, wait_until
from helpers.foxglove_ws import check_against_schema, watch
from hri_physio_bridge import topics
from hri_physio_bridge.frames import Frame

pytestmark = pytest.mark.ros

SERVING = re.compile(r"serving the session live on ws://([\d.]+):(\d+)")


def listening_addresses(pid: int) -> set[tuple[str, int]]:
    return {(c.laddr.ip, c.laddr.port) for c in psutil.Process(pid).net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN}


def test_a_client_subscribes_and_decodes_heart_rate_with_the_advertised_schema(ros_context) -> None:
    import rclpy
    from sensor_msgs.msg import CompressedImage
    from std_msgs.msg import String

    from hri_physio_bridge.qos import frame_qos, latched_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    node = rclpy.create_node("live_view_test", context=ros_context)
    hr_pub = node.create_publisher(type(frame_to_msg(Frame(np.zeros(1), np.zeros((1, 1))))),
                                   topics.POLAR_H10_HR, frame_qos())
    state_pub = node.create_publisher(String, topics.COACH_STATE, latched_qos())
    preview_pub = node.create_publisher(CompressedImage, topics.VIDEO_PREVIEW, 10)
    state_pub.publish(String(data=json.dumps({"t": 12.0, "phase": "warm-up", "zone": {"low": 120}})))
    stop = threading.Event()

    def publish_until_stopped() -> None:
        """Heart rate 20 times a second (every 7th NaN) and a preview: whatever comes after the subscription
        is what the client must decode."""
        i = 0
        while not stop.wait(0.05):
            bpm = math.nan if i % 7 == 3 else 60.0 + i % 50
            hr_pub.publish(frame_to_msg(Frame(np.array([1000.0 + i]), np.array([[bpm]]), ("hr",))))
            if i % 5 == 0:
                preview_pub.publish(CompressedImage(format="jpeg", data=b"\xff\xd8\xff\xe0fake"))
            i += 1

    with NodeProcess("live_view", "--port", "0") as live:
        try:
            live.wait_for_output("serving the session live", timeout=60)
            host, port = SERVING.search(live.output).groups()
            assert host == "127.0.0.1"  # this host only, unless told otherwise
            assert listening_addresses(live.proc.pid) == {("127.0.0.1", int(port))}
            publisher = threading.Thread(target=publish_until_stopped, daemon=True)
            publisher.start()
            seen = watch(f"ws://127.0.0.1:{port}", {topics.POLAR_H10_HR: 10, topics.COACH_STATE: 1,
                                                    topics.VIDEO_PREVIEW: 1}, timeout=90)
            # The client has gone: the live view drops its subscriptions (no viewer, no cost).
            wait_until(lambda: hr_pub.get_subscription_count() + state_pub.get_subscription_count() == 0,
                       60, "the live view to unsubscribe once its viewer left")
            live.wait_for_output("viewers watch 0 of", timeout=60)
        finally:
            stop.set()
        code = live.stop()
    node.destroy_node()
    assert code == 0, live.output

    assert seen.server_info is not None and seen.server_info["name"] == "HRI Physio session"
    # The channels are the session's topics, as the bag has them (foxglove_layout.json works on both).
    assert {topics.POLAR_H10_HR, topics.POLAR_H10_ECG, topics.COACH_STATE, topics.COACH_EVENTS,
            topics.QT_COMMANDS, topics.QT_MOCK_EVENTS, topics.AUDIO_STATUS, topics.VIDEO_STATUS,
            topics.VIDEO_PREVIEW} <= set(seen.channels)
    hr = seen.channels[topics.POLAR_H10_HR]
    assert (hr["encoding"], hr["schemaEncoding"]) == ("json", "jsonschema")
    assert hr["schemaName"] == "hri_physio.Frame"
    schema = json.loads(hr["schema"])
    values = []
    for _log_time, payload in seen.messages[topics.POLAR_H10_HR]:
        message = json.loads(payload)
        check_against_schema(message, schema)
        dims = [(d["label"], d["size"]) for d in message["layout"]["dim"]]
        assert dims == [("samples", 1), ("channels:t,hr", 2)]  # the frame layout: one sample [t, bpm]
        t, bpm = message["data"]
        values.append((t, bpm))
    stamps = [t for t, _ in values]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)  # in order, none twice
    for t, bpm in values:  # what was published, NaN as null
        i = int(t - 1000)
        assert bpm == (None if i % 7 == 3 else 60.0 + i % 50), (t, bpm)
    state = json.loads(seen.messages[topics.COACH_STATE][0][1])
    check_against_schema(state, json.loads(seen.channels[topics.COACH_STATE]["schema"]))
    assert json.loads(state["data"])["phase"] == "warm-up"  # the latched state, at once
    preview = seen.channels[topics.VIDEO_PREVIEW]
    assert preview["schemaName"] == "foxglove.CompressedImage"
    assert b"fake" in seen.messages[topics.VIDEO_PREVIEW][0][1]


def test_a_port_in_use_is_one_error_line(ros_context) -> None:
    with NodeProcess("live_view", "--port", "0") as first:
        first.wait_for_output("serving the session live", timeout=60)
        port = SERVING.search(first.output).group(2)
        with NodeProcess("live_view", "--port", port) as second:
            code = second.proc.wait(60)
            out = second.output
        first.stop()
    assert code == 2, out
    assert "Traceback" not in out
    errors = [line for line in out.splitlines() if line.startswith("live_view: error:")]
    assert len(errors) == 1 and f"cannot serve on 127.0.0.1:{port}" in errors[0], out

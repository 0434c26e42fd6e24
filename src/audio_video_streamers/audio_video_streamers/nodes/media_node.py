"""What the audio and video streamer nodes share: a player driven by a request topic, its status out."""

from __future__ import annotations

import json
import threading
from dataclasses import replace
from typing import Any, Protocol

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from std_msgs.msg import String

from audio_video_streamers.pacing import ClockTicks
from audio_video_streamers.status import MediaStatus, State
from hri_physio_bridge.node_runner import ManagedNode
from hri_physio_bridge.qos import command_qos, event_qos, latched_qos


class MediaPlayer(Protocol):
    """The part of AudioPlayer and VideoPlayer a node drives."""

    def request(self, text: str) -> None: ...

    def status(self, error: tuple[str, str] | None = None) -> MediaStatus: ...

    def run(self, stop: threading.Event) -> int: ...

    def close(self) -> None: ...


class MediaStreamerNode(ManagedNode):
    """A ROS 2 shell around one media player.

    The subclass builds its player (with ``clock=self.now`` and ``on_status=self.publish_status``) and
    hands it to :meth:`attach`, which subscribes the request topic and publishes the status at
    ``status_rate``. Every status message carries the node's name; the last one says STOPPED.

    A streamer that starts late or is restarted mid-session has missed the requests sent before it
    matched: it plays the latched current request (``current_topic``), unless a request reached it
    first. Nothing is requested twice: the latched request is only ever taken by a streamer that
    has had none.
    """

    player: MediaPlayer

    def __init__(self, prog: str, status_topic: str, **kwargs: Any) -> None:
        super().__init__(prog, **kwargs)
        self._publish_lock = threading.Lock()  # the player's thread and the executor both publish
        self.status_pub = self.create_publisher(String, status_topic, event_qos())
        self._requested = False  # a request (or the latched current one) was taken

    def attach(self, player: MediaPlayer, request_topic: str, current_topic: str, status_rate: float) -> None:
        self.player = player
        self.create_subscription(String, request_topic, self._on_request, command_qos())
        self.create_subscription(String, current_topic, self._on_current, latched_qos())
        self.create_timer(1.0 / status_rate, lambda: self.publish_status(self.player.status()))

    def clock_ticks(self) -> ClockTicks | None:
        """Under use_sim_time, ticks told of every step of ROS time (each /clock message, after the
        time is set), so the player's pacing waits for the step; None on wall time."""
        if not self.get_parameter("use_sim_time").value:
            return None
        ticks = ClockTicks()
        every = JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=Duration(nanoseconds=-1))
        clock = self.get_clock()
        self._jump_handle = clock.create_jump_callback(every, post_callback=lambda _jump: ticks.tick())
        return ticks

    def now(self) -> float:
        """The node's ROS time in seconds (follows /clock under use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_request(self, msg: String) -> None:
        self._requested = True
        self.player.request(msg.data)

    def _on_current(self, msg: String) -> None:
        if not self._requested:  # both callbacks run on the one executor thread
            self._requested = True
            self.get_logger().info(f"resuming the current request {msg.data!r} (started after it was sent)")
            self.player.request(msg.data)

    def publish_status(self, status: MediaStatus) -> None:
        data = status.as_dict()
        data["node"] = self.get_fully_qualified_name()
        with self._publish_lock:
            self.status_pub.publish(String(data=json.dumps(data)))

    def run(self, stop: threading.Event) -> int:
        return self.player.run(stop)

    def close(self) -> None:
        self.player.close()
        self.publish_status(replace(self.player.status(), state=State.STOPPED))

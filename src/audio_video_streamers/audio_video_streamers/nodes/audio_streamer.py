"""audio_streamer: plays what the coach asks on /audio_streamer/audio_name; status on /audio_streamer/status.

Examples::

    audio_streamer                                   # sound device if any, else the null sink
    audio_streamer --sink null --record-wav session.wav --initial relaxing
    audio_streamer --ros-args -p use_sim_time:=true -p fade:=2.0

Requests: ``beat:<bpm>``, ``relaxing``, ``file:<path>@<bpm>`` (stretched), ``<path>``, ``stop``.
"""

from __future__ import annotations

import json
import sys
import threading
from dataclasses import replace
from pathlib import Path
from typing import Any

from std_msgs.msg import String

from audio_video_streamers.audio.config import AudioStreamerConfig
from audio_video_streamers.audio.library import AudioLibrary
from audio_video_streamers.audio.player import AudioPlayer
from audio_video_streamers.audio.sinks import SinkError, open_sink
from audio_video_streamers.audio.stretch import StretchCache
from audio_video_streamers.status import MediaStatus, State
from hri_physio_bridge import topics
from hri_physio_bridge.node_runner import ManagedNode, logic_logger, run_node
from hri_physio_bridge.qos import command_qos, event_qos

PROG = "audio_streamer"


class AudioStreamerNode(ManagedNode):
    """ROS 2 shell around :class:`AudioPlayer`: request subscription, status publisher, the clock."""

    def __init__(self, config: AudioStreamerConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        log = logic_logger(self.get_name(), self.get_logger())
        self._publish_lock = threading.Lock()
        self.status_pub = self.create_publisher(String, topics.AUDIO_STATUS, event_qos())
        sink = open_sink(cfg.sink, cfg.rate, cfg.channels, self.now, log, device=cfg.device,
                         block=cfg.block, latency=cfg.latency, record_wav=cfg.record_wav,
                         record_format=cfg.record_format)
        cache = StretchCache(Path(cfg.cache_dir).expanduser() if cfg.cache_dir else None, log)
        library = AudioLibrary(cfg.rate, cfg.channels, declick=cfg.declick, stretch_cache=cache,
                               memory_bytes=cfg.memory_cache_mb * 2**20, log=log)
        media_dir = Path(cfg.media_dir).expanduser() if cfg.media_dir else None
        self.player = AudioPlayer(library, sink, fade=cfg.fade, block=cfg.block, clock=self.now,
                                  on_status=self.publish_status, media_dir=media_dir, log=log)
        self.create_subscription(String, topics.AUDIO_REQUEST, self._on_request, command_qos())
        self.create_timer(1.0 / cfg.status_rate, lambda: self.publish_status(self.player.status()))
        if cfg.initial:
            self.player.request(cfg.initial)

    def now(self) -> float:
        """The node's ROS time in seconds (follows /clock under use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_request(self, msg: String) -> None:
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
        final = self.player.status()
        self.publish_status(replace(final, state=State.STOPPED))


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, AudioStreamerConfig, AudioStreamerNode, argv=argv, startup_errors=(SinkError,),
        description="Play the coach's music: built-in beats at any tempo, a relaxing pad and user tracks "
        "(time-stretched to a tempo on request), cross-faded, looped, optionally recorded to WAV.",
        epilog="examples:" + __doc__.split("Examples::")[1].replace("``", "") if __doc__ else None,
    )


if __name__ == "__main__":
    sys.exit(main())

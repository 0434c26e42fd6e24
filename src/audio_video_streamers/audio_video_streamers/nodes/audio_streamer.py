"""audio_streamer: plays what the coach asks on /audio_streamer/audio_name; status on /audio_streamer/status.

Examples::

    audio_streamer                                   # sound device if any, else the null sink
    audio_streamer --sink null --record-wav session.wav --initial relaxing
    audio_streamer --ros-args -p use_sim_time:=true -p fade:=2.0

Requests: ``beat:<bpm>``, ``relaxing``, ``file:<path>@<bpm>`` (stretched), ``<path>``, ``stop``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

from audio_video_streamers.audio.config import AudioStreamerConfig
from audio_video_streamers.audio.library import AudioLibrary
from audio_video_streamers.audio.player import AudioPlayer
from audio_video_streamers.audio.sinks import SinkError, open_sink
from audio_video_streamers.audio.stretch import StretchCache
from audio_video_streamers.nodes.media_node import MediaStreamerNode
from hri_physio_bridge import topics
from hri_physio_bridge.node_runner import logic_logger, run_node

PROG = "audio_streamer"


class AudioStreamerNode(MediaStreamerNode):
    """ROS 2 shell around :class:`AudioPlayer`: request subscription, status publisher, the clock."""

    def __init__(self, config: AudioStreamerConfig, **kwargs: Any) -> None:
        super().__init__(PROG, topics.AUDIO_STATUS, **kwargs)
        self.config = cfg = self.declare_config(config)
        log = logic_logger(self.get_name(), self.get_logger())
        sink = open_sink(cfg.sink, cfg.rate, cfg.channels, self.now, log, device=cfg.device,
                         block=cfg.block, latency=cfg.latency, record_wav=cfg.record_wav,
                         record_format=cfg.record_format, ticks=self.clock_ticks())
        cache = StretchCache(Path(cfg.cache_dir).expanduser() if cfg.cache_dir else None, log)
        library = AudioLibrary(cfg.rate, cfg.channels, declick=cfg.declick, stretch_cache=cache,
                               memory_bytes=cfg.memory_cache_mb * 2**20, log=log)
        media_dir = Path(cfg.media_dir).expanduser() if cfg.media_dir else None
        self.attach(AudioPlayer(library, sink, fade=cfg.fade, block=cfg.block, clock=self.now,
                                on_status=self.publish_status, media_dir=media_dir, log=log),
                    topics.AUDIO_REQUEST, topics.AUDIO_CURRENT, cfg.status_rate)
        if cfg.preload:
            started = time.monotonic()
            ready = self.player.preload(cfg.preload)
            self.get_logger().info(f"prepared {ready} of {len(cfg.preload)} preloaded tracks in "
                                   f"{time.monotonic() - started:.1f} s")
        if cfg.initial:
            self.player.request(cfg.initial)


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, AudioStreamerConfig, AudioStreamerNode, argv=argv, startup_errors=(SinkError,),
        description="Play the coach's music: built-in beats at any tempo, a relaxing pad and user tracks "
        "(time-stretched to a tempo on request), cross-faded, looped, optionally recorded to WAV.",
        epilog="examples:" + __doc__.split("Examples::")[1].replace("``", "") if __doc__ else None,
    )


if __name__ == "__main__":
    sys.exit(main())

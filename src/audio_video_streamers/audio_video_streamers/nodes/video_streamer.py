"""video_streamer: shows what the coach asks for on /video_streamer/video_name; status and a preview out.

Examples::

    video_streamer                                   # a window if there is a display, else offscreen
    video_streamer --display offscreen --preview-rate 2
    video_streamer --ros-args -p use_sim_time:=true

Requests: ``splash``, ``relaxing``, ``marching``, ``step_up``, ``lateral``, ``arms_forward``
(``@<bpm>`` pins the tempo, otherwise the audio streamer's), ``<path>`` or ``file:<path>``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from sensor_msgs.msg import CompressedImage
from std_msgs.msg import String

from audio_video_streamers.nodes.media_node import MediaStreamerNode
from audio_video_streamers.status import State
from audio_video_streamers.video.config import VideoStreamerConfig
from audio_video_streamers.video.display import DisplayError, open_display
from audio_video_streamers.video.player import VideoPlayer
from audio_video_streamers.video.preview import encode_jpeg
from hri_physio_bridge import topics
from hri_physio_bridge.node_runner import logic_logger, run_node
from hri_physio_bridge.qos import event_qos

PROG = "video_streamer"
PLAYING = (str(State.PLAYING), str(State.FADING))


class VideoStreamerNode(MediaStreamerNode):
    """ROS 2 shell around :class:`VideoPlayer`: requests, the audio tempo, status and preview topics."""

    player: VideoPlayer

    def __init__(self, config: VideoStreamerConfig, **kwargs: Any) -> None:
        super().__init__(PROG, topics.VIDEO_STATUS, **kwargs)
        self.config = cfg = self.declare_config(config)
        log = logic_logger(self.get_name(), self.get_logger())
        self.preview_pub = self.create_publisher(CompressedImage, topics.VIDEO_PREVIEW, 10)
        display = open_display(cfg.display, log, fullscreen=cfg.fullscreen)
        player = VideoPlayer(
            display, size=(cfg.width, cfg.height), fps=cfg.fps, preview_rate=cfg.preview_rate,
            default_tempo=cfg.tempo, title=cfg.title, clock=self.now, on_status=self.publish_status,
            on_preview=self.publish_preview, log=log,
            media_dir=Path(cfg.media_dir).expanduser() if cfg.media_dir else None, ticks=self.clock_ticks(),
        )
        self.attach(player, topics.VIDEO_REQUEST, topics.VIDEO_CURRENT, cfg.status_rate)
        if cfg.follow_audio:
            self.create_subscription(String, topics.AUDIO_STATUS, self._on_audio_status, event_qos())
        player.request(cfg.initial)

    def _on_audio_status(self, msg: String) -> None:
        try:
            status = json.loads(msg.data)
        except ValueError:
            return
        if isinstance(status, dict) and status.get("state") in PLAYING:
            tempo = status.get("tempo")
            self.player.set_audio_tempo(float(tempo) if isinstance(tempo, int | float) else None)

    def publish_preview(self, frame: np.ndarray, t: float) -> None:
        msg = CompressedImage()
        msg.header.stamp.sec = int(t)
        msg.header.stamp.nanosec = min(round((t - int(t)) * 1e9), 999_999_999)
        msg.header.frame_id = self.get_name()
        msg.format = "jpeg"
        msg.data = encode_jpeg(frame, self.config.preview_quality)
        self.preview_pub.publish(msg)


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, VideoStreamerConfig, VideoStreamerNode, argv=argv, startup_errors=(DisplayError,),
        description="Show the coach's videos: reference videos from files (looped, at their frame rate) "
        "and built-in screens (splash, relaxing, activity placeholders at the music's tempo), "
        "with a JPEG preview of the screen for the session bag.",
        epilog="examples:" + __doc__.split("Examples::")[1].replace("``", "") if __doc__ else None,
    )


if __name__ == "__main__":
    sys.exit(main())

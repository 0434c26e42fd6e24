"""The video_streamer's options, declared once (flags, --conf YAML, ROS parameters, --help)."""

from __future__ import annotations

from typing import Literal

from audio_video_streamers.requests import TEMPO_MAX, TEMPO_MIN, MediaDir
from hri_physio_bridge.config import NodeConfig, option


class VideoStreamerConfig(NodeConfig):
    display: Literal["auto", "window", "offscreen"] = option(
        "auto", "auto = a window when a display exists, else offscreen; window = a window or fail; "
        "offscreen = shown nowhere: only the frames the previews need are drawn (same pace, same previews)")
    fullscreen: bool = option(False, "show the window full screen")
    width: int = option(640, "frame width (files are scaled to fit, aspect kept)", unit="px", ge=64, le=7680)
    height: int = option(480, "frame height", unit="px", ge=48, le=4320)
    fps: float = option(30.0, "frame rate of the built-in screens (files play at their own rate)",
                        unit="Hz", gt=0.0, le=120.0)
    preview_rate: float = option(1.0, "JPEG previews of the screen on /video_streamer/preview "
                                 "(0 = off)", unit="Hz", ge=0.0, le=30.0)
    preview_quality: int = option(80, "JPEG quality of the previews", ge=1, le=100)
    tempo: float = option(120.0, "tempo of the activity placeholders until the audio streamer reports "
                          "one", unit="BPM", ge=TEMPO_MIN, le=TEMPO_MAX)
    follow_audio: bool = option(True, "activity placeholders move at the tempo /audio_streamer/status "
                                "reports as playing")
    title: str = option("HRI Physio", "the name on the splash screen")
    media_dir: MediaDir = option("", "directory for relative file names in requests (empty = the working "
                            "directory)")
    initial: str = option("splash", "what to show at start", min_length=1)
    status_rate: float = option(1.0, "periodic status messages (also on every change)", unit="Hz",
                                gt=0.0, le=50.0)

"""The audio_streamer's options, declared once (flags, --conf YAML, ROS parameters, --help)."""

from __future__ import annotations

from typing import Literal

from audio_video_streamers.requests import MediaDir
from hri_physio_bridge.config import NodeConfig, option


class AudioStreamerConfig(NodeConfig):
    sink: Literal["auto", "device", "null"] = option(
        "auto", "where the mix goes: auto = the sound device when PortAudio and an output exist, "
        "else the null sink; device = the sound device or fail; null = no sound, samples consumed "
        "at the node clock's rate (sim time under use_sim_time)")
    device: str = option("", "sounddevice output device (name or index; empty = the default output)")
    record_wav: str = option("", "write exactly what is played to this WAV file (empty = no recording)")
    record_format: Literal["pcm16", "float"] = option("pcm16", "sample format of the recording")
    fade: float = option(1.0, "cross-fade between the old and the new track on a request "
                         "(0 = swap at once)", unit="s", ge=0.0, le=30.0)
    declick: float = option(0.02, "fade out/in around the loop point of a file, so a loop never clicks "
                            "(built-in sources loop seamlessly)", unit="s", ge=0.0, le=2.0)
    rate: int = option(44100, "output sample rate", unit="Hz", ge=8000, le=192000)
    channels: int = option(2, "output channels (1 = mono, 2 = stereo)", ge=1, le=2)
    block: int = option(1024, "frames rendered per block", ge=64, le=16384)
    latency: float = option(0.1, "how far playback runs ahead of the clock (device buffer, null sink "
                            "lead)", unit="s", gt=0.0, le=2.0)
    media_dir: MediaDir = option("", "directory for relative file names in requests (empty = the working "
                            "directory)")
    cache_dir: str = option("~/.cache/hri_physio/stretch", "where time-stretched tracks are kept between "
                            "runs (empty = memory only)")
    memory_cache_mb: int = option(512, "decoded tracks kept in memory", unit="MB", ge=0)
    initial: str = option("", "request to play at start (e.g. relaxing; empty = silence until a request)")
    preload: list[str] = option([], "requests to prepare at start-up (synthesised, decoded, stretched), so "
                                "the first time each is asked for it plays at once instead of after its "
                                "preparation (seconds for a file to stretch); one that cannot be prepared "
                                "is logged and tried again when asked for")
    status_rate: float = option(1.0, "periodic status messages (also on every change)", unit="Hz",
                                gt=0.0, le=50.0)

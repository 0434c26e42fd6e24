"""Both streamers as console-script nodes over real rclpy: requests in, status and preview out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile as sf

from audio_video_streamers.video.preview import decode_jpeg
from helpers import NodeProcess, own_lines, wait_until
from helpers.media import green_mask
from hri_physio_bridge import topics
from hri_physio_bridge.ros_tools import ExecutorThread, clock_message

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / "bin"


class MediaProbe:
    """Sends requests (command QoS, as qt_controller) and collects both streamers' status and previews."""

    def __init__(self, context: Any) -> None:
        from rclpy.node import Node
        from sensor_msgs.msg import CompressedImage
        from std_msgs.msg import String

        from hri_physio_bridge.qos import command_qos, event_qos

        self._string = String
        self.node = Node("media_probe", context=context)
        self.lock = threading.Lock()
        self.audio: list[dict] = []
        self.video: list[dict] = []
        self.previews: list[tuple[float, np.ndarray]] = []
        self.audio_pub = self.node.create_publisher(String, topics.AUDIO_REQUEST, command_qos())
        self.video_pub = self.node.create_publisher(String, topics.VIDEO_REQUEST, command_qos())
        for topic, into in ((topics.AUDIO_STATUS, self.audio), (topics.VIDEO_STATUS, self.video)):
            self.node.create_subscription(String, topic, lambda m, into=into: self._add(into, m), event_qos())
        self.node.create_subscription(CompressedImage, topics.VIDEO_PREVIEW, self._on_preview, 10)
        self._spinner = ExecutorThread(self.node, context=context)

    def _add(self, into: list[dict], msg: Any) -> None:
        with self.lock:
            into.append(json.loads(msg.data))

    def _on_preview(self, msg: Any) -> None:
        assert msg.format == "jpeg"
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self.lock:
            self.previews.append((stamp, decode_jpeg(bytes(msg.data))))

    def send_audio(self, text: str) -> None:
        self.audio_pub.publish(self._string(data=text))

    def send_video(self, text: str) -> None:
        self.video_pub.publish(self._string(data=text))

    def wait_audio(self, what: str, predicate: Any, timeout: float = 30.0) -> dict:
        return self._wait(self.audio, what, predicate, timeout)

    def wait_video(self, what: str, predicate: Any, timeout: float = 30.0) -> dict:
        return self._wait(self.video, what, predicate, timeout)

    def _wait(self, items: list[dict], what: str, predicate: Any, timeout: float) -> dict:
        found: list[dict] = []

        def check() -> bool:
            with self.lock:
                found[:] = [s for s in items if predicate(s)]
            return bool(found)

        wait_until(check, timeout, lambda: f"{what}; last: {items[-1] if items else None}")
        return found[0]

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()


def run(script: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / script), *args], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


def test_streamers_play_what_is_requested_and_report_it(ros_context: Any, tmp_path: Path) -> None:
    wav = tmp_path / "played.wav"
    probe = MediaProbe(ros_context)
    audio = NodeProcess("audio_streamer", "--sink", "null", "--record-wav", str(wav),
                        "--cache-dir", str(tmp_path / "cache"), "--fade", "0.5")
    video = NodeProcess("video_streamer", "--display", "offscreen", "--preview-rate", "2",
                        "--width", "320", "--height", "240")
    try:
        with audio, video:
            wait_until(lambda: probe.node.count_subscribers(topics.AUDIO_REQUEST) >= 1
                       and probe.node.count_subscribers(topics.VIDEO_REQUEST) >= 1, 60,
                       lambda: f"the streamers' request subscriptions\n{audio.output}\n{video.output}")

            # Audio: a beat, then a bad tempo that changes nothing.
            probe.send_audio("beat:120")
            playing = probe.wait_audio("beat:120 playing",
                                       lambda s: s["state"] == "playing" and s.get("source") == "beat:120")
            assert playing["tempo"] == 120.0 and playing["sink"] == "null" and playing["kind"] == "beat"
            probe.send_audio("beat:0")
            error = probe.wait_audio("an error for beat:0", lambda s: s["state"] == "error")
            assert error["request"] == "beat:0" and "outside" in error["error"]
            assert error["source"] == "beat:120"
            after = probe.wait_audio("beat:120 still playing after the error",
                                     lambda s: s["requests"]["failed"] == 1 and s["state"] == "playing")
            assert after["source"] == "beat:120"

            # Video: the splash by default, previews moving; an activity at the music's tempo.
            wait_until(lambda: len(probe.previews) >= 6, 30, "six previews")
            with probe.lock:
                (t0, first), (_, second) = probe.previews[1], probe.previews[2]
                t5 = probe.previews[5][0]
            # 2 Hz on the node's clock, never faster: a busy machine may stamp a preview late (and
            # the next ones catch up), so the rate is checked over 4 intervals with room for that.
            assert first.shape == (240, 320, 3) and 4 / (t5 - t0) <= 2.0 * 1.25, (t0, t5)
            assert (green_mask(first) != green_mask(second)).sum() > 100
            probe.wait_video("the splash offscreen",
                             lambda s: s.get("source") == "splash" and s["display"] == "offscreen")
            probe.send_video("marching")
            marching = probe.wait_video("marching", lambda s: s.get("source") == "marching")
            assert marching["tempo"] == 120.0 and marching["kind"] == "activity"
            probe.send_audio("beat:130")
            probe.wait_video("marching at the new tempo", lambda s: s.get("source") == "marching"
                             and s.get("tempo") == 130.0)
            probe.send_video("/nonexistent/clip.mp4")
            bad = probe.wait_video("a video error", lambda s: s["state"] == "error")
            assert bad["request"] == "/nonexistent/clip.mp4" and bad["source"] == "marching"

            # A burst: every request is received and accounted for (KEEP_ALL, reliable).
            burst = [f"beat:{100 + i}" for i in range(30)]
            for text in burst:
                probe.send_audio(text)
            total = 3 + len(burst)
            settled = probe.wait_audio("the whole burst settled", lambda s: s["requests"]["received"] == total
                                       and not s["pending"] and s["state"] == "playing")
            counts = settled["requests"]
            assert counts["started"] + counts["failed"] + counts["superseded"] == total
            assert settled["source"] == "beat:129"

            assert audio.stop(signal.SIGINT) == 0, audio.output
            assert video.stop(signal.SIGINT) == 0, video.output
    finally:
        probe.close()
    y, sr = sf.read(str(wav), always_2d=True)
    assert sr == 44100 and y.shape[1] == 2 and len(y) > sr and np.abs(y).max() > 0.1


class ClockDriver:
    """Publishes /clock from a thread: ``speed`` x wall time, starting at ``start``."""

    def __init__(self, context: Any, start: float = 1000.0, speed: float = 3.0, period: float = 0.01) -> None:
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        self.node = Node("media_test_clock", context=context)
        self.pub = self.node.create_publisher(Clock, "/clock", 10)
        self.t, self.step, self.period = start, speed * period, period
        self._alive = True
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while self._alive:
            self.t += self.step
            self.pub.publish(clock_message(self.t))
            time.sleep(self.period)

    def close(self) -> None:
        self._alive = False
        self._thread.join(2.0)
        self.node.destroy_node()


def test_the_null_sink_plays_at_sim_time_rate(ros_context: Any, tmp_path: Path) -> None:
    clock = ClockDriver(ros_context, speed=3.0)
    probe = MediaProbe(ros_context)
    try:
        with NodeProcess("audio_streamer", "--sink", "null", "--initial", "beat:120", "--status-rate", "2",
                         "--cache-dir", "", "--ros-args", "-p", "use_sim_time:=true") as audio:
            first = probe.wait_audio("beat:120 playing on sim time",
                                     lambda s: s["state"] == "playing" and s["t"] > 1000.0, timeout=60)
            later = probe.wait_audio("8 sim seconds later", lambda s: s["state"] == "playing"
                                     and s["t"] >= first["t"] + 8.0, timeout=60)
            played = later["elapsed"] - first["elapsed"]
            assert played == pytest.approx(later["t"] - first["t"], abs=0.4), (first, later)
            assert audio.stop(signal.SIGINT) == 0, audio.output
    finally:
        probe.close()
        clock.close()


def test_a_restarted_streamer_plays_the_latched_current_request_once(ros_context: Any) -> None:
    """A streamer that starts after the requests were sent (a restart mid-session) plays the last one,
    as qt_controller latches it; a request that reaches it later wins, and nothing is played twice."""
    from std_msgs.msg import String

    from hri_physio_bridge.qos import latched_qos

    probe = MediaProbe(ros_context)
    current = probe.node.create_publisher(String, topics.AUDIO_CURRENT, latched_qos())
    current.publish(String(data="beat:90"))  # sent before the streamer exists
    current.publish(String(data="beat:132"))
    audio = NodeProcess("audio_streamer", "--sink", "null")
    try:
        with audio:
            playing = probe.wait_audio("the latched beat:132 playing", lambda s: s.get("source") == "beat:132"
                                       and s["state"] == "playing", timeout=60)
            assert playing["requests"]["received"] == 1, playing  # only the last one, once
            assert "resuming the current request 'beat:132'" in audio.output
            wait_until(lambda: probe.node.count_subscribers(topics.AUDIO_REQUEST) >= 1, 60, "requests")
            probe.send_audio("beat:100")
            probe.wait_audio("the new request playing", lambda s: s.get("source") == "beat:100")
            current.publish(String(data="beat:100"))  # as the controller latches each request it sends
            last = probe.wait_audio("both counted", lambda s: s["requests"]["started"] == 2)
            assert last["source"] == "beat:100"
            assert audio.stop(signal.SIGINT) == 0, audio.output
        assert audio.output.count("resuming the current request") == 1
    finally:
        probe.close()


@pytest.mark.parametrize(
    ("script", "args", "fragment"),
    [
        ("audio_streamer", ["--sink", "null", "--record-wav", "/nonexistent/dir/out.wav"], "record_wav"),
        ("audio_streamer", ["--ros-args", "-p", "fade:=-1.0"], "fade"),
        ("audio_streamer", ["--ros-args", "-p", "sink:=speakers"], "sink"),
        ("video_streamer", ["--ros-args", "-p", "preview_rate:=-2.0"], "preview_rate"),
        ("video_streamer", ["--ros-args", "-p", "tempo:=300.0"], "tempo"),
    ],
)
def test_bad_configuration_is_one_line_and_status_2(script: str, args: list[str], fragment: str) -> None:
    p = run(script, *args)
    assert p.returncode == 2, p.stderr
    lines = own_lines(p.stderr)
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error:") and fragment in lines[0], p.stderr
    assert "Traceback" not in p.stderr, p.stderr


def test_a_window_without_a_display_is_a_startup_error() -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    p = subprocess.run([str(BIN / "video_streamer"), "--display", "window"], capture_output=True, text=True,
                       timeout=60, env=env, stdin=subprocess.DEVNULL)
    assert p.returncode == 2 and "no display server" in p.stderr and len(own_lines(p.stderr)) == 1


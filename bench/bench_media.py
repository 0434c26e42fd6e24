"""Benchmarks of the audio and video streamers, measured side by side on this machine.

1. Audio: CPU % of one core of the ``audio_streamer`` node process (null sink, real time)
   with nothing playing, playing ``beat:120``, playing while recording to WAV, and fading
   continuously (a new request every half fade).
2. Video: CPU % of one core of the ``video_streamer`` node process, offscreen at 640x480 and
   30 fps with a 1 Hz preview, for the splash, an activity placeholder and a 640x480 30 fps
   video file, and the splash with the preview off; with the frame rate achieved.
3. Both under a simulated clock at ``--sim-speed`` x real time (the session's default, 30x):
   the null sink plays ``beat:120`` at that rate, the video shows the picture due at each
   moment at no more than 1.33 x 30 frames per wall second.
4. Tempo: the tempo measured on the recording (kick onsets, a line through them; the same
   measure as the tests) against the requested one, for ``beat:<bpm>`` and for a 100 BPM
   track time-stretched with ``file:<path>@<bpm>``.

CPU % comes from the node process's user + system time over a wall-time window (psutil).

Run: ``source scripts/env.sh && python bench/bench_media.py [--seconds 10] [--skip-video] ...``
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "media"))  # the tempo measure and test media of the tests

from media_helpers import VirtualClock, measure_tempo, write_drum_clip  # noqa: E402

BIN = Path(sys.prefix) / "bin"
TEMPOS = (110.0, 115.0, 120.0, 125.0, 130.0, 135.0)


# ----------------------------------------------------------------------------------------------
# Node processes and a probe
class Probe:
    """Publishes requests and keeps the latest status of each streamer."""

    def __init__(self) -> None:
        import rclpy
        from std_msgs.msg import String

        from hri_physio_bridge import topics
        from hri_physio_bridge.qos import command_qos, event_qos
        from hri_physio_bridge.ros_tools import ExecutorThread

        rclpy.init()
        self._string, self.topics = String, topics
        self.node = rclpy.create_node(f"bench_media_{os.getpid()}")
        self.latest: dict[str, dict] = {}
        self.fading_seen = 0
        self.pubs = {t: self.node.create_publisher(String, t, command_qos())
                     for t in (topics.AUDIO_REQUEST, topics.VIDEO_REQUEST)}
        for topic in (topics.AUDIO_STATUS, topics.VIDEO_STATUS):
            self.node.create_subscription(String, topic, lambda m, t=topic: self._on_status(t, m),
                                          event_qos())
        self.spinner = ExecutorThread(self.node)

    def _on_status(self, topic: str, msg: Any) -> None:
        status = json.loads(msg.data)
        self.latest[topic] = status
        self.fading_seen += status.get("state") == "fading"

    def send(self, topic: str, text: str) -> None:
        self.pubs[topic].publish(self._string(data=text))

    def wait(self, topic: str, predicate: Callable[[dict], bool], timeout: float = 60.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            status = self.latest.get(topic)
            if status is not None and predicate(status):
                return status
            time.sleep(0.05)
        raise RuntimeError(f"no status on {topic} matched within {timeout} s: {self.latest.get(topic)}")

    def start_clock(self, speed: float, step: float = 0.1) -> None:
        """Publish /clock at ``speed`` x wall time in ``step`` sim-s steps (as hri_physio_session)."""
        from rosgraph_msgs.msg import Clock

        from hri_physio_bridge.ros_tools import clock_message

        pub = self.node.create_publisher(Clock, "/clock", 10)
        self.clock_running = True
        start_sim, start_wall = float(int(time.time())), time.monotonic()

        def run() -> None:
            t = start_sim
            while self.clock_running:
                target = start_sim + (time.monotonic() - start_wall) * speed
                while t + step <= target:
                    t += step
                    pub.publish(clock_message(t))
                time.sleep(step / speed)

        threading.Thread(target=run, daemon=True).start()

    def close(self) -> None:
        import rclpy

        self.clock_running = False
        self.spinner.close()
        self.node.destroy_node()
        rclpy.try_shutdown()


def start(script: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / script), *args], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
                            env=dict(os.environ), stdin=subprocess.DEVNULL)


def cpu_percent(proc: subprocess.Popen, seconds: float, during: Callable[[], None] | None = None) -> float:
    """CPU % of one core used by ``proc`` over ``seconds`` of wall time (``during`` runs meanwhile)."""
    p = psutil.Process(proc.pid)
    stop = threading.Event()
    worker = threading.Thread(target=lambda: during and during_loop(during, stop), daemon=True)
    c0, t0 = p.cpu_times(), time.monotonic()
    worker.start()
    time.sleep(seconds)
    c1, t1 = p.cpu_times(), time.monotonic()
    stop.set()
    worker.join()
    return 100.0 * ((c1.user - c0.user) + (c1.system - c0.system)) / (t1 - t0)


def during_loop(action: Callable[[], None], stop: threading.Event) -> None:
    while not stop.is_set():
        action()


def stop_process(proc: subprocess.Popen) -> None:
    proc.send_signal(2)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        proc.kill()


# ----------------------------------------------------------------------------------------------
def bench_audio(probe: Probe, seconds: float, tmp: Path) -> None:
    topics = probe.topics
    rows: list[tuple[str, float, str]] = []
    proc = start("audio_streamer", "--sink", "null", "--fade", "1.0", "--cache-dir", "")
    try:
        probe.wait(topics.AUDIO_STATUS, lambda s: s["state"] == "stopped")
        rows.append(("nothing playing", cpu_percent(proc, seconds), ""))
        probe.send(topics.AUDIO_REQUEST, "beat:120")
        probe.wait(topics.AUDIO_STATUS, lambda s: s["state"] == "playing" and s.get("source") == "beat:120")
        rows.append(("playing beat:120", cpu_percent(proc, seconds), ""))
        tempos = iter([120.0, 125.0] * 10_000)

        def swap() -> None:
            probe.send(topics.AUDIO_REQUEST, f"beat:{next(tempos):g}")
            time.sleep(0.5)

        probe.fading_seen = 0
        cpu = cpu_percent(proc, seconds, during=swap)
        state = probe.wait(topics.AUDIO_STATUS, lambda s: True)
        rows.append(("fading (a request every 0.5 s, fade 1 s)", cpu,
                     f"{probe.fading_seen} 'fading' statuses; {state['requests']['received']} requests"))
    finally:
        stop_process(proc)
    proc = start("audio_streamer", "--sink", "null", "--initial", "beat:120", "--cache-dir", "",
                 "--record-wav", str(tmp / "bench.wav"))
    try:
        probe.latest.pop(topics.AUDIO_STATUS, None)
        probe.wait(topics.AUDIO_STATUS, lambda s: s["state"] == "playing")
        rows.append(("playing beat:120 + record_wav (pcm16)", cpu_percent(proc, seconds), ""))
    finally:
        stop_process(proc)
    print(f"\naudio_streamer, null sink at real time, 44.1 kHz stereo, {seconds:g} s per row")
    print(f"{'scenario':48s} {'CPU % of one core':>18}  note")
    for name, cpu, note in rows:
        print(f"{name:48s} {cpu:18.1f}  {note}")


def write_moving_clip(path: Path, frames: int = 90, fps: float = 30.0,
                      size: tuple[int, int] = (640, 480)) -> Path:
    """A 640x480 MJPG clip with a gradient and a moving ball (decoding cost like real footage)."""
    w, h = size
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    ramp = np.linspace(0, 255, w, dtype=np.uint8)
    rng = np.random.default_rng(0)
    for i in range(frames):
        frame = np.dstack([np.tile(ramp, (h, 1)), np.tile(ramp[::-1], (h, 1)), np.full((h, w), 90, np.uint8)])
        frame = cv2.add(frame, rng.integers(0, 25, frame.shape, dtype=np.uint8))
        cv2.circle(frame, (int(w * i / frames), h // 2), 60, (255, 255, 255), -1)
        writer.write(frame)
    writer.release()
    return path


def bench_video(probe: Probe, seconds: float, tmp: Path) -> None:
    topics = probe.topics
    clip = write_moving_clip(tmp / "clip640.avi")
    rows: list[tuple[str, float, float]] = []

    def measure(proc: subprocess.Popen, request: str | None, label: str) -> None:
        if request is not None:
            probe.send(topics.VIDEO_REQUEST, request)
        probe.wait(topics.VIDEO_STATUS, lambda s: s.get("source") == (request or "splash"))
        before = probe.wait(topics.VIDEO_STATUS, lambda s: True)
        cpu = cpu_percent(proc, seconds)
        after = probe.wait(topics.VIDEO_STATUS, lambda s: s["t"] > before["t"])
        fps = (after["shown"] - before["shown"]) / (after["t"] - before["t"])
        rows.append((label, cpu, fps))

    common = ("--display", "offscreen", "--width", "640", "--height", "480", "--fps", "30")
    proc = start("video_streamer", *common, "--preview-rate", "1")
    try:
        measure(proc, None, "splash, preview 1 Hz")
        measure(proc, "marching", "marching placeholder, preview 1 Hz")
        measure(proc, str(clip), "640x480 30 fps MJPG file, preview 1 Hz")
    finally:
        stop_process(proc)
    probe.latest.pop(topics.VIDEO_STATUS, None)
    proc = start("video_streamer", *common, "--preview-rate", "0")
    try:
        measure(proc, None, "splash, preview off")
    finally:
        stop_process(proc)
    print(f"\nvideo_streamer offscreen, 640x480, 30 fps, {seconds:g} s per row")
    print(f"{'scenario':48s} {'CPU % of one core':>18} {'frames/s shown':>15}")
    for name, cpu, fps in rows:
        print(f"{name:48s} {cpu:18.1f} {fps:15.1f}")


#: A node that does nothing but follow /clock (spun like the streamers: an executor on a thread).
IDLE_NODE = """
import signal, threading, rclpy
from rclpy.parameter import Parameter
from hri_physio_bridge.ros_tools import ExecutorThread
rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
node = rclpy.create_node("bench_idle", parameter_overrides=[Parameter("use_sim_time", value=True)])
node.create_timer(1.0, lambda: None)
spinner = ExecutorThread(node)
stop = threading.Event()
signal.signal(signal.SIGINT, lambda *_: stop.set())
stop.wait()
spinner.close()
"""


def bench_sim_time(probe: Probe, seconds: float, speed: float) -> None:
    topics = probe.topics
    probe.start_clock(speed)
    sim = ("--ros-args", "-p", "use_sim_time:=true")
    rows: list[tuple[str, float, str]] = []
    idle = subprocess.Popen([sys.executable, "-c", IDLE_NODE], env=dict(os.environ), stdin=subprocess.DEVNULL)
    try:
        time.sleep(3.0)  # let it start and subscribe to /clock
        rows.append(("reference: an idle rclpy node on sim time", cpu_percent(idle, seconds),
                     "what /clock costs any node"))
    finally:
        stop_process(idle)
    probe.latest.clear()
    audio = start("audio_streamer", "--sink", "null", "--cache-dir", "", *sim)
    try:
        probe.wait(topics.AUDIO_STATUS, lambda s: s["state"] == "stopped" and s["t"] > 1.0)
        rows.append(("audio_streamer, nothing playing", cpu_percent(audio, seconds), ""))
        probe.send(topics.AUDIO_REQUEST, "beat:120")
        first = probe.wait(topics.AUDIO_STATUS, lambda s: s["state"] == "playing")
        wall0 = time.monotonic()
        cpu = cpu_percent(audio, seconds)
        last = probe.wait(topics.AUDIO_STATUS, lambda s: s["t"] > first["t"])
        rate = (last["elapsed"] - first["elapsed"]) / (time.monotonic() - wall0)
        rows.append(("audio_streamer playing beat:120", cpu, f"{rate:.1f} s of music per wall second"))
    finally:
        stop_process(audio)
    for preview in ("1", "0"):
        probe.latest.pop(topics.VIDEO_STATUS, None)
        video = start("video_streamer", "--display", "offscreen", "--width", "640", "--height", "480",
                      "--preview-rate", preview, *sim)
        try:
            first = probe.wait(topics.VIDEO_STATUS, lambda s: s.get("source") == "splash" and s["t"] > 1.0)
            wall0 = time.monotonic()
            cpu = cpu_percent(video, seconds)
            last = probe.wait(topics.VIDEO_STATUS, lambda s, f=first: s["t"] > f["t"] + 1.0)
            wall = time.monotonic() - wall0
            label = "preview 1 Hz of sim time" if preview == "1" else "preview off"
            rows.append((f"video_streamer splash, {label}", cpu,
                         f"{(last['shown'] - first['shown']) / wall:.1f} frames/wall s, "
                         f"{(last['previews'] - first['previews']) / wall:.1f} previews/wall s"))
        finally:
            stop_process(video)
    print(f"\nunder /clock at {speed:g}x real time (use_sim_time), {seconds:g} s per row")
    print(f"{'scenario':48s} {'CPU % of one core':>18}  note")
    for name, cpu, note in rows:
        print(f"{name:48s} {cpu:18.1f}  {note}")


def render(request: str, seconds: float, media_dir: Path, out: Path, cache: Path) -> dict:
    """Play ``request`` for ``seconds`` on a virtual clock (as fast as the CPU goes) into ``out``."""
    from audio_video_streamers.audio.library import AudioLibrary
    from audio_video_streamers.audio.player import AudioPlayer
    from audio_video_streamers.audio.sinks import NullSink, RecordingSink
    from audio_video_streamers.audio.stretch import StretchCache

    clock = VirtualClock()
    sink = RecordingSink(NullSink(44100, 2, clock, sleep=clock.sleep), out, "float")
    library = AudioLibrary(44100, 2, declick=0.02, stretch_cache=StretchCache(cache))
    player = AudioPlayer(library, sink, fade=0.0, clock=clock, media_dir=media_dir)
    player.request(request)
    player.prepare_pending()
    stop = threading.Event()
    end = clock() + seconds
    while clock() < end:
        player.step(stop)
    status = player.status().as_dict()
    player.close()
    return status


def bench_tempo(tmp: Path, seconds: float) -> None:
    clip = write_drum_clip(tmp / "track100.wav", 100.0, beats=32)
    print(f"\ntempo measured on the recording ({seconds:g} s each): kick onsets, a line through them")
    print(f"{'requested':>10} {'beat: measured':>15} {'error':>8} {'stretched measured':>19} {'error':>8}"
          f" {'track tempo found':>18}")
    worst_beat = worst_stretch = 0.0
    for bpm in TEMPOS:
        render(f"beat:{bpm:g}", seconds, tmp, tmp / "beat.wav", tmp / "cache")
        beat, _ = measure_tempo(tmp / "beat.wav")
        status = render(f"file:{clip.name}@{bpm:g}", seconds, tmp, tmp / "stretch.wav", tmp / "cache")
        stretched, _ = measure_tempo(tmp / "stretch.wav")
        worst_beat = max(worst_beat, abs(beat - bpm))
        worst_stretch = max(worst_stretch, abs(stretched - bpm))
        print(f"{bpm:10.1f} {beat:15.3f} {beat - bpm:+8.3f} {stretched:19.3f} {stretched - bpm:+8.3f}"
              f" {status['file_tempo']:18.2f}")
    print(f"worst error: beat {worst_beat:.3f} BPM, stretched {worst_stretch:.3f} BPM (goal <= 0.5: "
          f"{'MET' if max(worst_beat, worst_stretch) <= 0.5 else 'NOT MET'})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="wall seconds per CPU row (default 10)")
    parser.add_argument("--skip-audio", action="store_true")
    parser.add_argument("--skip-video", action="store_true")
    parser.add_argument("--skip-tempo", action="store_true")
    parser.add_argument("--sim-speed", type=float, default=30.0,
                        help="speed of the simulated clock for section 3 (default 30; 0 = skip)")
    args = parser.parse_args()
    # A domain of our own unless one is set: the bench must not talk to a running system.
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(215, 232)))
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}, python "
          f"{sys.version.split()[0]}, ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}")
    with tempfile.TemporaryDirectory(prefix="bench_media_") as tmp_dir:
        tmp = Path(tmp_dir)
        if not (args.skip_audio and args.skip_video and args.sim_speed <= 0):
            probe = Probe()
            try:
                if not args.skip_audio:
                    bench_audio(probe, args.seconds, tmp)
                if not args.skip_video:
                    bench_video(probe, args.seconds, tmp)
                if args.sim_speed > 0:
                    bench_sim_time(probe, args.seconds, args.sim_speed)
            finally:
                probe.close()
        if not args.skip_tempo:
            bench_tempo(tmp, 30.0)


if __name__ == "__main__":
    main()

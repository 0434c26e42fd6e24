"""neurokit_processor as a real node (subprocess, real rclpy): CLI, configuration, ROS 2 in/out,
LSL out, parity of what it publishes with NeuroKit2 on the same samples, clean exit."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pylsl
import pytest
from test_parity import nk_direct_ecg

from helpers import NodeProcess, RosFrameCollector, wait_until
from hri_physio_processing.features import HEART_SCALARS, SIGNAL_FEATURES
from proc_helpers import random_chunks

pytestmark = [pytest.mark.ros]
FS = 130
OUTPUTS = (*SIGNAL_FEATURES["ecg"], *HEART_SCALARS)


class Outputs:
    """Subscribe to every output of a processor prefix (frames and the JSON status)."""

    def __init__(self, collector: RosFrameCollector, prefix: str) -> None:
        from std_msgs.msg import String

        from hri_physio_bridge.qos import frame_qos

        self.collector = collector
        self.frames = {name: collector.subscribe_frames(f"{prefix}/{name}") for name in OUTPUTS}
        self.status: list[dict] = []
        self._lock = threading.Lock()

        def on_status(msg: String) -> None:
            with self._lock:
                self.status.append(json.loads(msg.data))

        collector.node.create_subscription(String, f"{prefix}/status", on_status, frame_qos(100))

    def windows(self) -> list[dict]:
        with self._lock:
            return [s for s in self.status if s.get("event") == "window"]

    def joined(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        frames = list(self.frames[name])
        if not frames:
            return np.empty(0), np.empty(0)
        return (np.concatenate([f.timestamps for f in frames]),
                np.concatenate([f.values[:, 0] for f in frames]))


@pytest.fixture
def collector(ros_context):
    c = RosFrameCollector(ros_context)
    yield c
    c.close()


def test_help_and_bad_configuration(tmp_path: Path) -> None:
    exe = str(Path(sys.prefix) / "bin" / "neurokit_processor")
    ok = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0 and "window-seconds" in ok.stdout and "rmssd" in ok.stdout
    for args, match in (
        (["--hop-seconds", "100"], "hop_seconds"),
        (["--mode", "emg"], "mode"),
        (["--input", "lsl:X"], "output_prefix is required"),
        (["--input", "nope:X"], "unknown stream scheme"),
    ):
        bad = subprocess.run([exe, *args, "--resolve-timeout", "0.1"], capture_output=True, text=True,
                             timeout=60)
        assert bad.returncode != 0 and match in bad.stderr, (args, bad.stderr)
        assert "Traceback" not in bad.stderr
    conf = tmp_path / "bad.yaml"
    conf.write_text("window_seconds: 60\nbogus: 1\n")
    bad = subprocess.run([exe, "--conf", str(conf)], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "unknown option(s) ['bogus']" in bad.stderr
    conf.write_text("window_seconds: [60\n")
    bad = subprocess.run([exe, "--conf", str(conf)], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "not valid YAML" in bad.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_clean_exit_on_signal_while_waiting(sig: int, lsl_name: str) -> None:
    topic = f"/test/{lsl_name.split('/')[0]}/idle{int(sig)}"
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}") as proc:
        proc.wait_for_output("connected to")
        assert proc.stop(sig) == 0, proc.output
    assert "Traceback" not in proc.output


def test_ctrl_c_while_an_lsl_input_has_not_appeared(lsl_name: str) -> None:
    args = ("--input", f"lsl:{lsl_name}/never", "--resolve-timeout", "60", "--output-prefix",
            f"/test/{lsl_name.split('/')[0]}/never")
    with NodeProcess("neurokit_processor", *args) as proc:
        time.sleep(3.0)  # well inside the resolve timeout
        t0 = time.monotonic()
        assert proc.stop(signal.SIGINT, timeout=10) == 0, proc.output
        assert time.monotonic() - t0 < 3.0, proc.output
    assert "Traceback" not in proc.output


def publish_stream(ros_context, topic: str, t: np.ndarray, x: np.ndarray, chunks: list[tuple[int, int]],
                   ready) -> None:
    """Publish frames like physio_receiver would, waiting for the processor's subscription."""
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    node = Node("ecg_source", context=ros_context)
    pub = node.create_publisher(Float64MultiArray, topic, frame_qos())
    try:
        wait_until(lambda: pub.get_subscription_count() > 0 and ready(), 30, "processor subscription")
        for i, (a, b) in enumerate(chunks):
            pub.publish(frame_to_msg(Frame(t[a:b], x[a:b].reshape(-1, 1))))
            if i % 50 == 49:
                time.sleep(0.05)  # stay well inside the reliable queue depth
        pub.wait_for_all_acked()
    finally:
        node.destroy_node()


def test_ros_in_ros_out_matches_neurokit_and_timestamps(mitdb, ros_context, collector, tmp_path: Path,
                                                      lsl_name: str) -> None:
    """The node's published features equal NeuroKit2 on each window; stamps line up with windows."""
    tag = lsl_name.split("/")[0]
    topic, prefix = f"/test/{tag}/ecg_in", f"/test/{tag}/ecg"
    n = 75 * FS
    t, x = 2000.0 + mitdb.t[:n], mitdb.x[:n]
    conf = tmp_path / "proc.yaml"  # a ROS params file serves --params-file
    conf.write_text(
        "neurokit_processor:\n  ros__parameters:\n"
        f"    input: ros:{topic}\n    output_prefix: {prefix}\n    window_seconds: 30\n    hop_seconds: 10\n"
        "    sampling_rate: 130\n    wait_for_consumers: 30.0\n"
    )
    out = Outputs(collector, prefix)
    rng = np.random.default_rng(4)
    chunks = random_chunks(n, rng, 1, 260)
    with NodeProcess("neurokit_processor", "--ros-args", "--params-file", str(conf)) as proc:
        proc.wait_for_output("every output has a consumer", 30)
        publish_stream(ros_context, topic, t, x, chunks, lambda: True)
        wait_until(lambda: len(out.windows()) >= 5, 60, lambda: f"windows; node said:\n{proc.output}")
        assert proc.stop(signal.SIGINT) == 0, proc.output  # flushes the final window on exit
        wait_until(lambda: len(out.windows()) >= 6, 10, "the final window")
    wins = out.windows()
    assert [w["window"]["t_end"] for w in wins] == pytest.approx(
        [t[30 * FS - 1], t[40 * FS - 1], t[50 * FS - 1], t[60 * FS - 1], t[70 * FS - 1], t[-1]])
    for k, st in enumerate(wins):
        w = st["window"]
        a = int(np.searchsorted(t, w["t_start"]))
        assert t[a] == w["t_start"] and t[a + w["samples"] - 1] == w["t_end"] == st["t"]
        _, _, ref = nk_direct_ecg(x[a : a + w["samples"]])
        for name in HEART_SCALARS:
            frame = out.frames[name][k]
            assert frame.timestamps.tolist() == [w["t_end"]]  # stamped with the window's end
            value = frame.values[0, 0]
            if name in ("lf", "lfhf", "hf"):
                assert math.isnan(value) and name in st["nan"]
            else:
                assert value == pytest.approx(ref[name], rel=1e-9), name
    clean_t, _ = out.joined("clean")
    np.testing.assert_array_equal(clean_t, t)  # every sample once, source timestamps kept
    peak_t, mask = out.joined("rpeaks")
    beats = peak_t[mask == 1]
    beat_t, beat_hr = out.joined("beat_hr")
    np.testing.assert_array_equal(beat_t, beats[1:])
    np.testing.assert_allclose(beat_hr, 60.0 / np.diff(beats), rtol=1e-9)


@pytest.mark.lsl
def test_lsl_outputs(mitdb, ros_context, lsl_name: str, tmp_path: Path) -> None:
    """lsl_output publishes every output on LSL too, with the source timestamps."""
    tag = lsl_name.split("/")[0]
    topic, prefix = f"/test/{tag}/lsl_in", f"/test/{tag}/ecg_lsl"
    n = 25 * FS
    t, x = 3000.0 + mitdb.t[:n], mitdb.x[:n]
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}", "--output-prefix", prefix,
                     "--window-seconds", "10", "--hop-seconds", "5", "--min-window-seconds", "5",
                     "--lsl-output", "true", "--lsl-prefix", f"{lsl_name}/proc") as proc:
        proc.wait_for_output("connected to")
        infos = pylsl.resolve_byprop("name", f"{lsl_name}/proc/hr", 1, 20)
        assert infos, proc.output
        inlet = pylsl.StreamInlet(infos[0])
        inlet.open_stream(10)
        assert infos[0].nominal_srate() == 0 and infos[0].channel_count() == 1
        publish_stream(ros_context, topic, t, x, [(i, min(n, i + 130)) for i in range(0, n, 130)],
                       lambda: True)
        got: list[tuple[float, float]] = []
        deadline = time.monotonic() + 30
        while len(got) < 4 and time.monotonic() < deadline:
            data, stamps = inlet.pull_chunk(timeout=0.5)
            got.extend((s, d[0]) for s, d in zip(stamps, data, strict=True))
        assert proc.stop() == 0, proc.output
    assert [s for s, _ in got[:4]] == pytest.approx([t[10 * FS - 1], t[15 * FS - 1], t[20 * FS - 1],
                                                     t[25 * FS - 1]])
    assert all(60 < v < 90 for _, v in got[:4])  # record 100 beats at about 75 bpm

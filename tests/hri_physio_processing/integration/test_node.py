"""neurokit_processor as a real node (subprocess, real rclpy): CLI, configuration, missing inputs,
ROS 2 in/out, LSL out, parity of what it publishes with NeuroKit2 on the same samples, clean exit."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pylsl
import pytest

from helpers import NEUROKIT_START, NodeProcess, own_lines, resolve_lsl, wait_until
from helpers.processing import Outputs, nk_direct_ecg, random_chunks
from hri_physio_processing.features import FREQUENCY_SCALARS, HEART_SCALARS

pytestmark = pytest.mark.ros
FS = 130
EXE = str(Path(sys.prefix) / "bin" / "neurokit_processor")


def run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([EXE, *args], capture_output=True, text=True, timeout=timeout, env=dict(os.environ),
                          stdin=subprocess.DEVNULL)


def test_help() -> None:
    ok = run("--help")
    assert ok.returncode == 0 and "window-seconds" in ok.stdout and "rmssd" in ok.stdout


@pytest.mark.parametrize("args,fragment", [
    (["--hop-seconds", "100"], "hop_seconds"),
    (["--mode", "emg"], "--mode"),
    (["--input", "lsl:X"], "output_prefix is required"),
    (["--input", "nope:X"], "unknown stream scheme"),
    (["--input", "ros:bad"], "ros:/bad"),  # was accepted and reported as 'bad/clean'
    (["--window-seconds", "long"], "window_seconds"),
    (["--ros-args", "-p", "window_seconds:=abc"], "window_seconds"),
    (["--ros-args", "-p", "min_beats:=2.5"], "min_beats"),
    (["--ros-args", "-p", "lsl_output:=perhaps"], "lsl_output"),
    (["--ros-args", "-p", "colour:=red"], "colour"),
    (["--ros-args", "--params-file", "/nonexistent/processor.yaml"], "/nonexistent/processor.yaml"),
])
def test_bad_configuration_is_one_line_and_status_2(args: list[str], fragment: str) -> None:
    bad = run(*args)
    assert bad.returncode == 2, (args, bad.stderr)
    assert fragment in bad.stderr and "Traceback" not in bad.stderr, (args, bad.stderr)
    assert len(own_lines(bad.stderr)) <= 3, bad.stderr  # argparse adds its usage lines


def test_bad_conf_files(tmp_path: Path) -> None:
    conf = tmp_path / "bad.yaml"
    conf.write_text("window_seconds: 60\nbogus: 1\n")
    bad = run("--conf", str(conf))
    assert bad.returncode == 2 and "bogus" in bad.stderr and "Traceback" not in bad.stderr
    conf.write_text("window_seconds: [60\n")
    bad = run("--conf", str(conf))
    assert bad.returncode == 2 and "not valid YAML" in bad.stderr
    conf.write_text("buffer: 7800\nwindow: 7150\ninput: ros:/physio/polar_h10/ecg\n")  # the seed's keys
    assert run("--conf", str(conf), "--hop-seconds", "3").returncode == 2  # hop given twice


def test_a_missing_csv_input_is_an_error_at_once(tmp_path: Path) -> None:
    """It used to retry forever at 98 % CPU, logging 'still waiting' thousands of times a second."""
    missing = tmp_path / "missing.csv"
    bad = run("--input", f"csv:{missing}", "--output-prefix", "/test/missing_csv", timeout=60)
    assert bad.returncode == 1, bad.stderr
    errors = [line for line in bad.stderr.splitlines() if "ERROR" in line]
    assert len(errors) == 1 and str(missing) in errors[0], bad.stderr
    assert "still waiting" not in bad.stderr and "Traceback" not in bad.stderr


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def test_an_lsl_input_still_to_appear_is_waited_for_idly(lsl_name: str, collector) -> None:
    prefix = f"/test/{lsl_name.split('/')[0]}/later"
    out = Outputs(collector, prefix)
    args = ("--input", f"lsl:{lsl_name}/later", "--resolve-timeout", "0.2", "--output-prefix", prefix)
    with NodeProcess("neurokit_processor", *args) as proc:

        def attempts() -> int:
            with out._lock:
                return max((s["attempts"] for s in out.status if s.get("event") == "waiting_for_input"),
                           default=0)

        wait_until(lambda: attempts() >= 1, NEUROKIT_START,
                   lambda: f"a waiting_for_input status\n{proc.output}")
        cpu0, t0, first = _cpu_seconds(proc.proc.pid), time.monotonic(), attempts()
        # Three more attempts (each logged at once if the log were not rate-limited) to measure over.
        wait_until(lambda: attempts() >= first + 3, 60, "three more attempts to open the input")
        cpu = (_cpu_seconds(proc.proc.pid) - cpu0) / (time.monotonic() - t0)
        assert proc.proc.poll() is None, proc.output
        assert proc.stop(signal.SIGINT) == 0, proc.output
    assert proc.output.count("still waiting") == 1, proc.output  # rate-limited: one line per 30 s
    assert cpu < 0.5, f"{cpu:.0%} CPU while waiting"
    assert "Traceback" not in proc.output


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_clean_exit_on_signal_while_waiting(sig: int, lsl_name: str, collector) -> None:
    topic = f"/test/{lsl_name.split('/')[0]}/idle{int(sig)}"
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}") as proc:
        wait_until(lambda: collector.node.count_subscribers(topic) > 0, NEUROKIT_START,
                   lambda: f"the processor's subscription:\n{proc.output}")
        assert proc.stop(sig) == 0, proc.output
    assert "Traceback" not in proc.output


def test_ctrl_c_while_an_lsl_input_has_not_appeared(lsl_name: str) -> None:
    args = ("--input", f"lsl:{lsl_name}/never", "--resolve-timeout", "60", "--output-prefix",
            f"/test/{lsl_name.split('/')[0]}/never")
    with NodeProcess("neurokit_processor", *args) as proc:
        proc.wait_for_output("opening", NEUROKIT_START)  # now inside a 60 s resolve
        assert proc.stop(signal.SIGINT, timeout=15) == 0, proc.output
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
        wait_until(lambda: pub.get_subscription_count() > 0 and ready(), NEUROKIT_START,
                   "processor subscription")
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
        "    hrv_window_seconds: 0.0\n"  # LF, HF, LF/HF per window, as NeuroKit2 on it (long window: below)
    )
    out = Outputs(collector, prefix)
    rng = np.random.default_rng(4)
    chunks = random_chunks(n, rng, 1, 260)
    with NodeProcess("neurokit_processor", "--ros-args", "--params-file", str(conf)) as proc:
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
            if name in FREQUENCY_SCALARS:
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
def test_lsl_outputs(mitdb, ros_context, collector, lsl_name: str, tmp_path: Path) -> None:
    """lsl_output publishes every output on LSL too, with the source timestamps."""
    tag = lsl_name.split("/")[0]
    topic, prefix = f"/test/{tag}/lsl_in", f"/test/{tag}/ecg_lsl"
    n = 25 * FS
    t, x = 3000.0 + mitdb.t[:n], mitdb.x[:n]
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}", "--output-prefix", prefix,
                     "--window-seconds", "10", "--hop-seconds", "5", "--min-window-seconds", "5",
                     "--lsl-output", "true", "--lsl-prefix", f"{lsl_name}/proc") as proc:
        wait_until(lambda: collector.node.count_subscribers(topic) > 0, NEUROKIT_START,  # outputs first
                   lambda: f"the processor's subscription:\n{proc.output}")
        infos = resolve_lsl(f"{lsl_name}/proc/hr")
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

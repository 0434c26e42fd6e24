"""physio_receiver end to end: real pylsl outlets/inlets, real rclpy, the node as a subprocess.

A counter channel proves that every sample arrives exactly once, in order,
with its original LSL timestamp (the technique of mne-lsl's tests).
"""

from __future__ import annotations

import itertools
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pylsl
import pytest

from helpers import NodeProcess, RosFrameCollector, concat_new_samples, resolve_lsl, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.lsl]

RATE = 130.0


def counter_outlet(name: str, channels: int = 2, fmt: int = pylsl.cf_double64,
                   source_id: str = "") -> pylsl.StreamOutlet:
    info = pylsl.StreamInfo(name, "ECG", channels, RATE, fmt, source_id or name)
    return pylsl.StreamOutlet(info)


def push_counter(outlet: pylsl.StreamOutlet, start: int, n: int, t0: float, chunk: int = 13,
                 channels: int = 2, realtime: bool = False) -> np.ndarray:
    """Push samples [i, -i, ...] stamped t0 + i/RATE; returns the timestamps pushed."""
    stamps = t0 + np.arange(start, start + n) / RATE
    for i in range(start, start + n, chunk):
        j = min(i + chunk, start + n)
        rows = [[float(k) * (1 if c == 0 else -c) for c in range(channels)] for k in range(i, j)]
        outlet.push_chunk(rows, timestamp=list(stamps[i - start : j - start]))
        if realtime:
            time.sleep((j - i) / RATE)
    return stamps


def check_counter(ts: np.ndarray, vs: np.ndarray, stamps: np.ndarray, start: int = 0) -> None:
    n = len(stamps)
    assert len(vs) == n, f"expected {n} samples, got {len(vs)}"
    np.testing.assert_array_equal(vs[:, 0], np.arange(start, start + n))  # once each, in order
    np.testing.assert_array_equal(vs[:, 1], -np.arange(start, start + n))
    np.testing.assert_array_equal(ts, stamps)  # original LSL timestamps, bit for bit


@pytest.fixture
def collector(ros_context):
    c = RosFrameCollector(ros_context)
    yield c
    c.close()


@pytest.mark.parametrize("frame,overlap", [(1, 0), (73, 0), (10, 4)])
def test_lsl_to_ros_every_sample_once_in_order(lsl_name: str, collector: RosFrameCollector,
                                               frame: int, overlap: int, tmp_path: Path) -> None:
    topic = f"/test/{lsl_name.split('/')[0]}/ecg{frame}"
    outlet = counter_outlet(lsl_name)
    got = collector.subscribe_frames(topic)
    log = tmp_path / "rx.csv"
    with NodeProcess(
        "physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
        "--num-channels", "2", "--output-frame", str(frame), "--sample-overlap", str(overlap),
        "--log-data", "true", "--log-name", str(log), "--channel-names", "count,neg",
        "--wait-for-consumers", "20",
    ) as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        stamps = push_counter(outlet, 0, 1300, pylsl.local_clock())

        def progress() -> str:
            seen = {int(v) for f in got for v in f.values[:, 0]}
            missing = sorted(set(range(1300)) - seen)
            return f"frames ({len(seen)} samples so far; missing {missing[:40]})\n{rx.output}"

        wait_until(lambda: sum(f.num_samples for f in got) >= 1300 - frame, 30, progress)
        assert rx.stop(signal.SIGINT) == 0, rx.output
    ts, vs = concat_new_samples(got, frame, overlap)
    check_counter(ts, vs, stamps)
    assert all(f.channels == ("count", "neg") for f in got)
    if overlap:
        full = [f for f in got if f.num_samples == frame]
        for a, b in itertools.pairwise(full):
            np.testing.assert_array_equal(a.values[-overlap:], b.values[:overlap])
    # The CSV log holds every received sample too.
    logged = np.loadtxt(log, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(logged[:, 1], np.arange(1300))
    np.testing.assert_array_equal(logged[:, 0], stamps)


def test_ros_to_lsl_every_sample_once_in_order(lsl_name: str, ros_context) -> None:
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    topic = f"/test/{lsl_name.split('/')[0]}/to_lsl"
    node = Node("pub", context=ros_context)
    pub = node.create_publisher(Float64MultiArray, topic, frame_qos())
    with NodeProcess(
        "physio_receiver", "--input", f"ros:{topic}", "--output", f"lsl:{lsl_name}?type=ECG",
        "--num-channels", "2", "--output-frame", "5", "--dtype", "int32",
    ) as rx:
        rx.wait_for_output("connected")
        infos = resolve_lsl(lsl_name)
        assert infos, rx.output
        assert infos[0].channel_format() == pylsl.cf_int32 and infos[0].type() == "ECG"
        inlet = pylsl.StreamInlet(infos[0])
        inlet.open_stream(10)
        wait_until(lambda: pub.get_subscription_count() > 0, 20, "receiver subscription")
        t0 = 5000.0
        n = 600
        for i in range(0, n, 20):
            idx = np.arange(i, i + 20)
            pub.publish(frame_to_msg(Frame(t0 + idx / RATE, np.column_stack([idx, -idx]))))
        rows, stamps = [], []
        deadline = time.monotonic() + 30
        while len(rows) < n and time.monotonic() < deadline:
            data, ts = inlet.pull_chunk(timeout=0.5, max_samples=1000)
            rows.extend(data)
            stamps.extend(ts)
        assert rx.stop() == 0, rx.output
    check_counter(np.array(stamps), np.array(rows), t0 + np.arange(n) / RATE)
    node.destroy_node()


def test_lsl_to_lsl_and_lsl_to_csv(lsl_name: str, tmp_path: Path) -> None:
    out_csv = tmp_path / "out.csv"
    outlet = counter_outlet(lsl_name, fmt=pylsl.cf_int16)
    relay = f"{lsl_name}-relay"
    with NodeProcess(
        "physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"lsl:{relay}",
        "--num-channels", "2", "--dtype", "int16", "--output-frame", "7",
    ) as lsl_rx, NodeProcess(
        "physio_receiver", "--input", f"lsl:{relay}", "--output", f"csv:{out_csv}",
        "--num-channels", "2", "--dtype", "int16", "--output-frame", "3",
    ) as csv_rx:
        csv_rx.wait_for_output("connected", 30)
        lsl_rx.wait_for_output("connected", 30)
        wait_until(outlet.have_consumers, 20, "relay inlet")
        stamps = push_counter(outlet, 0, 500, pylsl.local_clock())

        def rows() -> int:
            return len(out_csv.read_text().splitlines()) - 1 if out_csv.exists() else 0

        # Frames of 7 then 3: the relay holds back 3 samples, the CSV end 2 more.
        wait_until(lambda: rows() >= 495, 30, lambda: f"csv rows\n{lsl_rx.output}\n{csv_rx.output}")
        assert lsl_rx.stop() == 0  # publishes its last 3 samples on the way out
        wait_until(lambda: rows() >= 498, 20, lambda: f"relay tail\n{lsl_rx.output}\n{csv_rx.output}")
        assert csv_rx.stop() == 0  # writes its last 2
    table = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    check_counter(table[:, 0], table[:, 1:], stamps)


def test_csv_replay_to_ros(collector: RosFrameCollector, tmp_path: Path) -> None:
    log = tmp_path / "session.csv"
    idx = np.arange(1000)
    stamps = 12345.678 + idx / RATE
    with log.open("w") as f:
        f.write("t,count,neg\n")
        for t, i in zip(stamps, idx, strict=True):
            f.write(f"{float(t)!r},{i},{-i}\n")
    topic = "/test/replay/ecg"
    got = collector.subscribe_frames(topic)
    with NodeProcess(
        "physio_receiver", "--input", f"csv:{log}?rate=0", "--output", f"ros:{topic}",
        "--num-channels", "2", "--output-frame", "64", "--wait-for-consumers", "20",
    ) as rx:
        code = rx.wait(60)  # the replay ends by itself at the end of the file
        assert code == 0, rx.output
        wait_until(lambda: sum(f.num_samples for f in got) >= 1000, 10, "replayed frames")
    ts, vs = concat_new_samples(got, 64, 0)
    check_counter(ts, vs, stamps)


def test_source_disappears_and_returns(lsl_name: str, collector: RosFrameCollector) -> None:
    topic = "/test/gap/ecg"
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, source_id="gap-src")
    with NodeProcess(
        "physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
        "--num-channels", "2", "--output-frame", "1", "--wait-for-consumers", "20",
    ) as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        t0 = pylsl.local_clock()
        first = push_counter(outlet, 0, 200, t0)
        wait_until(lambda: len(got) >= 200, 20, "first part")
        del outlet  # the strap goes out of range
        rx.wait_for_output("waiting for it to come back", 20)
        time.sleep(1.0)
        outlet = counter_outlet(lsl_name, source_id="gap-src")
        rx.wait_for_output("reconnected", 30)
        wait_until(outlet.have_consumers, 20, "reconnected inlet")
        second = push_counter(outlet, 400, 200, t0)
        wait_until(lambda: len(got) >= 400, 20, "second part")
        rx.wait_for_output("gap of 200 sample(s)", 10)
        assert rx.stop() == 0, rx.output
    ts, vs = concat_new_samples(got, 1, 0)
    np.testing.assert_array_equal(vs[:, 0], np.r_[0:200, 400:600])
    np.testing.assert_array_equal(ts, np.r_[first, second])
    expected_first_missing = f"from t={first[-1] + 1 / RATE:.4f} to t={second[0] - 1 / RATE:.4f}"
    assert expected_first_missing in rx.output


# -- bad input -------------------------------------------------------------------------


def test_stream_never_appears_names_it_and_lists_seen(lsl_name: str) -> None:
    other = counter_outlet(f"{lsl_name}-present")
    with NodeProcess(
        "physio_receiver", "--input", f"lsl:{lsl_name}-absent", "--output", "ros:/test/none",
        "--resolve-timeout", "1.5",
    ) as rx:
        code = rx.wait(30)
    assert code == 1
    assert f"name='{lsl_name}-absent'" in rx.output and "did not appear within 1.5 s" in rx.output
    assert f"{lsl_name}-present" in rx.output  # the streams it did see
    assert "Traceback" not in rx.output
    del other


@pytest.mark.parametrize("waiting_for", ["input", "consumer"])
def test_ctrl_c_while_waiting_exits_at_once(lsl_name: str, waiting_for: str) -> None:
    """SIGINT during a long wait (input not there yet, or no consumer) ends it, exit code 0."""
    tag = lsl_name.split("/")[0]
    if waiting_for == "input":
        outlet = None
        args = ["--input", f"lsl:{lsl_name}-never", "--resolve-timeout", "30"]
        waiting, stopped = "waiting up to 30 s for it", "stopped before the input"
    else:
        outlet = counter_outlet(lsl_name, channels=1)
        args = ["--input", f"lsl:{lsl_name}", "--wait-for-consumers", "30"]
        waiting, stopped = "waiting up to 30 s for a consumer", "stopped while waiting for a consumer"
    with NodeProcess("physio_receiver", *args, "--output", f"ros:/test/{tag}/ctrl_c") as rx:
        rx.wait_for_output(waiting, 30)  # what is tested: the line that says it waits, then a stop
        start = time.monotonic()
        code = rx.stop(signal.SIGINT, timeout=20)
        elapsed = time.monotonic() - start
    assert code == 0, rx.output
    # Well inside the 30 s wait: the stop ended it (an upper bound that load only makes looser).
    assert elapsed < 15.0, f"took {elapsed:.1f} s to exit after SIGINT:\n{rx.output}"
    assert "SIGINT received" in rx.output and stopped in rx.output, rx.output
    assert "did not appear" not in rx.output and "Traceback" not in rx.output, rx.output
    del outlet


def test_ros_input_bad_messages_rejected_counted_and_rate_limited(lsl_name: str, ros_context,
                                                                 tmp_path: Path) -> None:
    """Wrong channel count and broken layouts are rejected, named, counted; good samples all pass."""
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    topic = f"/test/{lsl_name.split('/')[0]}/bad_in"
    out_csv = tmp_path / "good.csv"
    node = Node("bad_pub", context=ros_context)
    pub = node.create_publisher(Float64MultiArray, topic, frame_qos())

    def good(start: int, n: int) -> Float64MultiArray:
        idx = np.arange(start, start + n)
        return frame_to_msg(Frame(7000.0 + idx / RATE, np.column_stack([idx, -idx])))

    def broken_layout() -> Float64MultiArray:
        msg = good(0, 2)
        msg.data = list(msg.data)[:-1]  # one value short of 2 samples x 3 columns
        return msg

    def unlabelled() -> Float64MultiArray:
        msg = good(0, 2)
        msg.layout.dim = [MultiArrayDimension(label="rows", size=2, stride=6), msg.layout.dim[1]]
        return msg

    with NodeProcess(
        "physio_receiver", "--input", f"ros:{topic}", "--output", f"csv:{out_csv}",
        "--num-channels", "2", "--output-frame", "5", "--status-period", "0.5",
    ) as rx:
        rx.wait_for_output("connected")
        wait_until(lambda: pub.get_subscription_count() > 0, 20, "receiver subscription")
        for i in range(0, 100, 10):
            pub.publish(good(i, 10))
        for k in range(5):
            idx = np.arange(3)
            pub.publish(frame_to_msg(Frame(8000.0 + k + idx / RATE, np.column_stack([idx, idx, idx]))))
        for _ in range(3):
            pub.publish(broken_layout())
        pub.publish(unlabelled())
        for i in range(100, 200, 10):
            pub.publish(good(i, 10))
        rx.wait_for_output("received 200 samples", 30)
        assert rx.proc.poll() is None, rx.output  # still running after the bad messages
        assert rx.stop(signal.SIGINT) == 0, rx.output
    node.destroy_node()
    table = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    check_counter(table[:, 0], table[:, 1:], 7000.0 + np.arange(200) / RATE)
    lines = rx.output.splitlines()
    channels = [ln for ln in lines if "message rejected: frame has 3 channel(s), num_channels is 2" in ln]
    layout = [ln for ln in lines if "message rejected: malformed frame layout" in ln]
    # Within 5 s: one line per kind, the first of each, however many messages came.
    assert len(channels) == 1 and "(1 message(s) rejected so far" in channels[0], rx.output
    assert len(layout) == 1 and "layout says 2 samples x 3 columns but data holds 5 values" in layout[0]
    assert "(1 message(s) rejected so far" in layout[0], rx.output
    assert "'rejected_messages': 9" in rx.output, rx.output  # every one counted
    assert "Traceback" not in rx.output


def test_conf_file_configures_the_receiver_end_to_end(lsl_name: str, tmp_path: Path,
                                                      collector: RosFrameCollector) -> None:
    """Every receiver option below comes from the YAML file; none from the command line."""
    topic = f"/test/{lsl_name.split('/')[0]}/conf"
    log = tmp_path / "conf_log.csv"
    conf = tmp_path / "receiver.yaml"
    conf.write_text(
        "# the seed's receiver keys\n"
        f"input: lsl:{lsl_name}\n"
        f"output: ros:{topic}\n"
        "dtype: int16\n"
        "sampling_rate: 130\n"
        "input_frame: 16\n"
        "output_frame: 6\n"
        "num_channels: 2\n"
        "sample_overlap: 2\n"
        "buffer_length: 600\n"
        "log_data: true\n"
        f"log_name: {log}\n"
        "channel_names: [count, neg]\n"
        "wait_for_consumers: 20\n"
    )
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, fmt=pylsl.cf_int16)  # the default dtype (float64) would refuse it
    with NodeProcess("physio_receiver", "--conf", str(conf)) as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        stamps = push_counter(outlet, 0, 302, pylsl.local_clock())  # 302 = 6 + 74 frames x 4 new
        wait_until(lambda: len(got) >= 75, 30,
                   lambda: f"75 frames, got {len(got)}\n{rx.output}")
        assert rx.stop(signal.SIGINT) == 0, rx.output
    assert "2 ch int16 @ 130 Hz, frames of 6 (overlap 2)" in rx.output, rx.output  # what it says it does
    assert {f.num_samples for f in got} == {6}
    assert all(f.channels == ("count", "neg") for f in got)
    ts, vs = concat_new_samples(got, 6, 2)
    check_counter(ts, vs, stamps)
    for a, b in itertools.pairwise(got):
        np.testing.assert_array_equal(a.values[-2:], b.values[:2])
    logged = np.loadtxt(log, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(logged[:, 1], np.arange(302))


@pytest.mark.parametrize(
    "fmt,channels,args,message",
    [
        (pylsl.cf_double64, 3, ["--num-channels", "2"], "it has 3 channel(s) but num_channels is 2"),
        (pylsl.cf_float32, 2, ["--num-channels", "2"], "its format is float32 but dtype is float64"),
    ],
)
def test_wrong_channel_count_or_dtype(lsl_name: str, fmt: int, channels: int, args: list,
                                      message: str) -> None:
    outlet = counter_outlet(lsl_name, channels=channels, fmt=fmt)
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", "ros:/test/x",
                     *args) as rx:
        code = rx.wait(30)
    assert code == 1 and message in rx.output and "Traceback" not in rx.output, rx.output
    del outlet


def test_nan_samples_are_reported_and_forwarded(lsl_name: str, collector: RosFrameCollector) -> None:
    topic = "/test/nan/ecg"
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, channels=1)
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
                     "--wait-for-consumers", "20", "--status-period", "0.5") as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        t0 = pylsl.local_clock()
        outlet.push_chunk([[1.0], [float("nan")], [float("inf")], [4.0]],
                          timestamp=[t0, t0 + 1 / RATE, t0 + 2 / RATE, t0 + 3 / RATE])
        # The inlet may take the four in one chunk or several (a busy machine splits them); the
        # warning names its first chunk's count at once, the status line the total.
        rx.wait_for_output("sample(s) with NaN/inf near t=")
        rx.wait_for_output("NaN/inf 2,")
        wait_until(lambda: len(got) >= 4, 20, "frames")
        assert rx.stop() == 0
    values = np.concatenate([f.values[:, 0] for f in got])
    assert values[0] == 1.0 and np.isnan(values[1]) and np.isinf(values[2]) and values[3] == 4.0


@pytest.mark.parametrize(
    "conf_text,args,message",
    [
        ("input: [unclosed\n", [], "is not valid YAML at line"),
        ("input: lsl:x\ncolour: red\n", [], "colour"),
        ("output_frame: 0\n", [], "output_frame"),
        ("", ["--input", "udp:1234"], "unknown stream scheme 'udp'"),
        ("", ["--input", "lsl:a?colour=red"], "colour"),
        ("", ["--output", "ros:relative/topic"], "output"),
        ("", ["--sample-overlap", "3", "--output-frame", "2"], "sample_overlap"),
        ("", ["--dtype", "complex"], "unknown dtype 'complex'"),
        ("", ["--input", "lsl:a", "--output", "lsl:b", "--wait-for-consumers", "5", "--min-consumers", "2"],
         "output lsl:b cannot count its listeners"),
        ("", ["--ros-args", "-p", "output_frame:=abc"], "output_frame"),
        ("", ["--ros-args", "-p", "sampling_rate:=fast"], "sampling_rate"),
        ("", ["--ros-args", "-p", "reconnect:=maybe"], "reconnect"),
        ("", ["--ros-args", "-p", "input:=udp:1"], "udp"),
        ("", ["--ros-args", "--params-file", "/nonexistent/params.yaml"], "/nonexistent/params.yaml"),
        ("", ["--ros-args", "-p"], "-p"),
    ],
)
def test_bad_configuration_one_clear_message(tmp_path: Path, conf_text: str, args: list,
                                             message: str) -> None:
    conf = tmp_path / "conf.yaml"
    conf.write_text(conf_text)
    with NodeProcess("physio_receiver", "--conf", str(conf), *args) as rx:
        code = rx.wait(30)
    assert code == 2, rx.output
    lines = rx.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("physio_receiver: error:"), rx.output
    assert message in lines[0], rx.output


@pytest.mark.parametrize("case", ["topic", "log_file"])
def test_an_output_that_cannot_be_opened_is_one_error_line(tmp_path: Path, case: str) -> None:
    """Found only when the streams open (after start-up): a bad topic name, a log file under a file."""
    src = tmp_path / "in.csv"
    src.write_text("t,v\n" + "".join(f"{100 + i / RATE!r},{i}\n" for i in range(10)))
    (tmp_path / "a_file").write_text("not a folder")
    args = (["--output", "ros:/bad topic"] if case == "topic" else
            ["--output", f"csv:{tmp_path / 'out.csv'}", "--log-data", "true",
             "--log-name", str(tmp_path / "a_file" / "log.csv")])
    with NodeProcess("physio_receiver", "--input", f"csv:{src}?rate=0", *args) as rx:
        code = rx.wait(60)
    assert code == 2, rx.output
    errors = [line for line in rx.output.splitlines() if line.startswith("physio_receiver: error:")]
    assert len(errors) == 1 and "cannot open" in errors[0], rx.output
    assert ("Invalid topic name" if case == "topic" else "a_file") in errors[0], rx.output
    assert "Traceback" not in rx.output
    assert not (tmp_path / "out.csv").exists()  # nothing left behind to block the corrected rerun


def test_broken_params_file_is_one_line(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("physio_receiver:\n  ros__parameters:\n    output_frame: [4\n")
    with NodeProcess("physio_receiver", "--ros-args", "--params-file", str(params)) as rx:
        assert rx.wait(30) == 2, rx.output
    lines = rx.output.strip().splitlines()
    assert len(lines) == 1 and str(params) in lines[0] and "not valid YAML" in lines[0], rx.output


def test_missing_conf_file_and_help() -> None:
    with NodeProcess("physio_receiver", "--conf", "/nonexistent/receiver.yaml") as rx:
        assert rx.wait(30) == 2
    assert "configuration file /nonexistent/receiver.yaml does not exist" in rx.output
    with NodeProcess("physio_receiver", "--help") as rx:
        assert rx.wait(30) == 0
    assert "--sample-overlap" in rx.output and "--conf" in rx.output


def test_params_file_and_interactive_console(lsl_name: str, tmp_path: Path,
                                             collector: RosFrameCollector) -> None:
    topic = "/test/params/ecg"
    params = tmp_path / "params.yaml"
    params.write_text(
        "physio_receiver:\n  ros__parameters:\n"
        f"    input: lsl:{lsl_name}\n    output: ros:{topic}\n    output_frame: 4\n"
        "    wait_for_consumers: 20.0\n"
    )
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, channels=1)
    with NodeProcess("physio_receiver", "--interactive", "--ros-args", "--params-file", str(params),
                     stdin=subprocess.PIPE) as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        rx.proc.stdin.write("pause\n")
        rx.proc.stdin.flush()
        rx.wait_for_output("paused")
        t0 = pylsl.local_clock()
        outlet.push_chunk([[float(i)] for i in range(8)], timestamp=[t0 + i / RATE for i in range(8)])
        # Received but held while paused: the status says so (asked until the 8 samples are in).
        def status_after_eight() -> bool:
            rx.proc.stdin.write("status\n")
            rx.proc.stdin.flush()
            return '"received_samples": 8' in rx.output

        wait_until(status_after_eight, 20, "a status with the 8 samples received", period=0.2)
        held = rx.output[rx.output.index('"received_samples": 8'):]
        assert '"published_samples": 0' in held and '"paused": true' in rx.output and got == []
        rx.proc.stdin.write("resume\n")
        rx.proc.stdin.flush()
        wait_until(lambda: len(got) >= 2, 20, "frames after resume")
        rx.proc.stdin.write("quit\n")
        rx.proc.stdin.flush()
        assert rx.wait(20) == 0, rx.output
    assert [f.num_samples for f in got] == [4, 4]


def test_lsl_string_markers_to_ros_json(lsl_name: str, ros_context) -> None:
    import json

    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String

    from hri_physio_bridge.qos import frame_qos

    topic = "/test/markers"
    node = Node("marker_sub", context=ros_context)
    got: list[dict] = []
    node.create_subscription(String, topic, lambda m: got.append(json.loads(m.data)), frame_qos())
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "Markers", 1, 0, pylsl.cf_string, lsl_name))
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
                     "--dtype", "string", "--sampling-rate", "0", "--wait-for-consumers", "20") as rx:
        wait_until(lambda: (executor.spin_once(timeout_sec=0.01),
                            outlet.have_consumers() and node.count_publishers(topic) > 0)[1], 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        texts = ["start", "phase: warm-up", 'say "hi", then ünïcode']
        for i, text in enumerate(texts):
            outlet.push_sample([text], 100.0 + i)
        wait_until(lambda: (executor.spin_once(timeout_sec=0.01), len(got) >= 3)[1], 20, lambda: rx.output)
        assert rx.stop() == 0
    assert got == [{"t": 100.0 + i, "data": text} for i, text in enumerate(texts)]
    executor.shutdown()
    node.destroy_node()


# -- the receiver checks what it is told --------------------------------------------------------


def test_a_500_hz_stream_read_at_130_hz_is_refused_naming_both_rates(lsl_name: str) -> None:
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(lsl_name, "ECG", 1, 500.0, pylsl.cf_double64, lsl_name))
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", "ros:/test/rate") as rx:
        code = rx.wait(30)
    assert code == 1, rx.output
    errors = [line for line in rx.output.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and "500 Hz" in errors[0] and "130 Hz" in errors[0], rx.output
    assert "connected" not in rx.output and "Traceback" not in rx.output, rx.output
    del outlet


def test_without_reconnect_a_lost_input_says_what_happens(lsl_name: str,
                                                          collector: RosFrameCollector) -> None:
    topic = f"/test/{lsl_name.split('/')[0]}/no_reconnect"
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, channels=1)
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
                     "--reconnect", "false", "--wait-for-consumers", "20") as rx:
        wait_until(lambda o=outlet: o.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        push_counter(outlet, 0, 100, pylsl.local_clock(), channels=1)
        wait_until(lambda: sum(f.num_samples for f in got) >= 100, 20, "the samples before the loss")
        del outlet
        code = rx.wait(30)
    assert code == 1, rx.output
    assert "input lost; reconnect is off: publishing what is buffered and exiting" in rx.output, rx.output
    assert "waiting for it to come back" not in rx.output and "Traceback" not in rx.output, rx.output
    assert sum(f.num_samples for f in got) == 100


def test_clock_jumps_are_counted_apart_from_gaps(lsl_name: str, collector: RosFrameCollector) -> None:
    """A sender's clock goes 5 s back, then returns: 2 clock jumps, 0 gaps, 0 missing, all forwarded."""
    topic = f"/test/{lsl_name.split('/')[0]}/jumps"
    got = collector.subscribe_frames(topic)
    outlet = counter_outlet(lsl_name, channels=1)
    with NodeProcess("physio_receiver", "--input", f"lsl:{lsl_name}", "--output", f"ros:{topic}",
                     "--output-frame", "13", "--wait-for-consumers", "20") as rx:
        wait_until(lambda: outlet.have_consumers() and collector.publishers(topic) > 0, 30,
                   lambda: f"the receiver's inlet and publisher\n{rx.output}")
        t0 = pylsl.local_clock()
        stamps = t0 + np.arange(1300) / RATE
        stamps[390:910] -= 5.0
        for i in range(0, 1300, 13):
            outlet.push_chunk([[float(k)] for k in range(i, i + 13)], timestamp=list(stamps[i:i + 13]))
        wait_until(lambda: sum(f.num_samples for f in got) >= 1300, 30, lambda: rx.output)
        assert rx.stop(signal.SIGINT) == 0, rx.output
    final = [line for line in rx.output.splitlines() if "stopped: {" in line][-1]
    assert "'clock_jumps': 2" in final and "'gaps': 0" in final and "'missing_samples': 0" in final, final
    values = np.concatenate([f.values[:, 0] for f in got])
    np.testing.assert_array_equal(values, np.arange(1300))
    np.testing.assert_array_equal(np.concatenate([f.timestamps for f in got]), stamps)


def test_csv_input_with_invalid_utf8_is_one_error_and_keeps_the_rows_before(tmp_path: Path) -> None:
    src = tmp_path / "session.csv"
    rows = b"".join(f"{100 + i / RATE!r},{i}\n".encode() for i in range(40))
    src.write_bytes(b"t,count\n" + rows + b"100.5,\xe9t\xe9\n" + b"100.6,41\n")
    out = tmp_path / "out.csv"
    with NodeProcess("physio_receiver", "--input", f"csv:{src}?rate=0", "--output", f"csv:{out}",
                     "--output-frame", "8") as rx:
        code = rx.wait(60)
    assert code == 1, rx.output
    assert f"{src}:42: not UTF-8 text" in rx.output and "Traceback" not in rx.output, rx.output
    assert "UnicodeDecodeError" not in rx.output, rx.output
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], np.arange(40))  # every row before the bad line

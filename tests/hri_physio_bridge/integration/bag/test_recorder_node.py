"""recorder node end to end: real rclpy publishers, the node as a subprocess, SIGINT/SIGTERM, SIGKILL."""

from __future__ import annotations

import contextlib
import signal
import statistics
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from helpers import NodeProcess, own_lines, wait_until
from helpers.bags import check_bag, read_with_mcap, read_with_rosbags
from hri_physio_bridge.bag.recovery import McapScanner

pytestmark = pytest.mark.ros


@pytest.fixture
def prefix() -> str:
    return f"/bagtest_{uuid.uuid4().hex[:8]}"


@pytest.fixture
def node(ros_context):
    from rclpy.node import Node

    n = Node(f"bag_pub_{uuid.uuid4().hex[:6]}", context=ros_context)
    yield n
    n.destroy_node()


def _wait_recorded(rec: NodeProcess, pub, topic: str) -> None:
    rec.wait_for_output(f"recording {topic} ", timeout=30)
    wait_until(lambda: pub.get_subscription_count() > 0, 30, f"recorder subscription on {topic}")
    time.sleep(0.2)  # let the subscriber side finish matching too


@contextlib.contextmanager
def _recording_one_topic(
    tmp_path: Path, node, topic: str, *options: str
) -> Iterator[tuple[NodeProcess, Any, Path]]:
    """A String publisher on ``topic`` and a recorder of it (with ``options``), matched."""
    bag = tmp_path / topic.rsplit("/", 1)[-1]
    pub = node.create_publisher(String, topic, 1000)
    with NodeProcess("recorder", topic, "-o", str(bag), "--discovery-period", "0.2", *options) as rec:
        _wait_recorded(rec, pub, topic)
        yield rec, pub, bag


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_records_all_topics_including_late_ones(
    tmp_path: Path, prefix: str, node, stop_signal: signal.Signals
) -> None:
    """Record, then stop with SIGINT (Ctrl-C) or SIGTERM (a launcher, systemd): exit 0, a
    summary, a complete bag with metadata.yaml."""
    bag = tmp_path / "all"
    chatter = node.create_publisher(String, f"{prefix}/chatter", 10)
    frames = node.create_publisher(Float64MultiArray, f"{prefix}/frames", 10)
    with NodeProcess("recorder", "-o", str(bag), "--discovery-period", "0.2", "--status-period", "1") as rec:
        _wait_recorded(rec, chatter, f"{prefix}/chatter")
        _wait_recorded(rec, frames, f"{prefix}/frames")
        sent_frames = []
        for i in range(150):
            chatter.publish(String(data=f"msg {i}"))
            f = Float64MultiArray(data=[float(i), -float(i), 0.5])
            f.layout.dim = [MultiArrayDimension(label="samples", size=1, stride=3)]
            frames.publish(f)
            sent_frames.append(f)
            time.sleep(0.004)
        # a topic that appears after recording started, latched (transient local)
        late = node.create_publisher(
            String, f"{prefix}/late", QoSProfile(depth=5, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        )
        late.publish(String(data="latched before discovery"))
        _wait_recorded(rec, late, f"{prefix}/late")
        late.publish(String(data="after discovery"))
        wait_until(lambda: "msg/s" in rec.output, 10, "a status report")
        time.sleep(0.5)
        assert rec.stop(stop_signal) == 0, rec.output
        out = rec.output
    assert f"{stop_signal.name} received: closing the bag" in out, out
    assert "bag closed" in out and f"{prefix}/chatter [std_msgs/msg/String]: 150 messages" in out, out
    assert (bag / "metadata.yaml").is_file()

    meta = check_bag(bag)  # rosbag2 checks, summary counts, installed type hashes
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    late_meta = topics[f"{prefix}/late"]["topic_metadata"]
    assert late_meta["offered_qos_profiles"][0]["durability"] == "transient_local"

    got = read_with_rosbags(bag)
    assert [m.data for t, _, m in got if t == f"{prefix}/chatter"] == [f"msg {i}" for i in range(150)]
    have_frames = [m for t, _, m in got if t == f"{prefix}/frames"]
    assert len(have_frames) == 150
    for have, want in zip(have_frames, sent_frames, strict=True):
        assert list(have.data) == list(want.data) and have.layout.dim[0].label == "samples"
    assert [m.data for t, _, m in got if t == f"{prefix}/late"] == [
        "latched before discovery",
        "after discovery",
    ]

    raw = read_with_mcap(bag / "all_0.mcap")
    stamps = [t for topic, t, _ in raw if topic == f"{prefix}/chatter"]
    assert stamps == sorted(stamps) and all(isinstance(t, int) and t > 1e18 for t in stamps)


def test_refuses_to_overwrite_and_bad_arguments(tmp_path: Path) -> None:
    exe = str(Path(sys.prefix) / "bin" / "recorder")
    (tmp_path / "exists").mkdir()
    r = subprocess.run([exe, "-o", str(tmp_path / "exists")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "never overwritten" in r.stderr and "Traceback" not in r.stderr
    assert len(own_lines(r.stderr)) == 1
    for args, text in (
        (["--regex", "("], "regular expression"),
        (["--session-id", "a b"], "session id"),
        (["--flush-period", "0"], "flush_period"),
        (["--poll-period", "-1"], "poll_period"),
        (["--repair", str(tmp_path / "x")], "does not exist"),
    ):
        r = subprocess.run(
            [exe, "-o", str(tmp_path / "new"), *args], capture_output=True, text=True, timeout=60
        )
        assert r.returncode != 0 and text in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
    for args, text in (
        (["--qos-depth", "0"], "qos_depth"),
        (["--compression", "lz4"], "--compression"),
        (["--ros-args", "-p", "qos_depth:=abc"], "qos_depth"),
        (["--ros-args", "-p", "compression:=lz4"], "compression"),
        (["--ros-args", "-p", "session_id:=Jane Doe"], "session_id"),
        (["--ros-args", "-p", "colour:=red"], "colour"),
        (["--ros-args", "--params-file", str(tmp_path / "missing.yaml")], "missing.yaml"),
    ):
        r = subprocess.run([exe, "-o", str(tmp_path / "never"), *args], capture_output=True, text=True,
                           timeout=60)
        lines = own_lines(r.stderr)
        assert r.returncode == 2 and "Traceback" not in r.stderr and text in lines[-1], (args, r.stderr)
        assert lines[-1].startswith("recorder: error:"), (args, r.stderr)
    assert not (tmp_path / "never").exists()  # nothing is created before the options are right
    r = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--flush-period" in r.stdout and "--poll-period" in r.stdout
    r = subprocess.run([str(Path(sys.prefix) / "bin" / "physio_recorder"), "--session-id", "a b"],
                       capture_output=True, text=True, timeout=60)
    lines = own_lines(r.stderr)
    assert r.returncode == 2 and lines[0].startswith("physio_recorder: error:") and "session" in lines[0]


def test_stamps_are_arrival_times_not_take_times(tmp_path: Path, prefix: str, node) -> None:
    """Messages are taken in batches every --poll-period, but each is stamped with the
    middleware's receive time: with a 0.5 s poll, stamps still match the send times closely."""
    with _recording_one_topic(tmp_path, node, f"{prefix}/tick", "--poll-period", "0.5") as (rec, pub, bag):
        sent_ns = []
        for i in range(40):
            sent_ns.append(time.time_ns())
            pub.publish(String(data=str(i)))
            time.sleep(0.03)
        time.sleep(0.8)
        assert rec.stop() == 0, rec.output
    got = _strings(read_with_mcap(bag / "tick_0.mcap"))
    assert [int(text) for _, _, text in got] == list(range(40))
    delays = [(t - s) / 1e9 for (_, t, _), s in zip(got, sent_ns, strict=True)]
    print(f"\nreceive stamp - send time with a 0.5 s poll: max {max(delays) * 1e3:.1f} ms")
    # Taken up to 0.5 s late, so take-time stamps would be 0.25 s late on the median; stamped on
    # arrival, the median is under a millisecond idle. A loaded machine can hold the middleware's
    # receive thread back for a moment (100.6 ms seen once with one core kept busy): the bound on
    # each is looser than the one on the median.
    assert all(-0.01 <= d < 0.25 for d in delays), delays
    assert statistics.median(delays) < 0.05, delays


def _strings(raw: list[tuple[str, int, bytes]]) -> list[tuple[str, int, str]]:
    from rclpy.serialization import deserialize_message

    return [(topic, t, deserialize_message(data, String).data) for topic, t, data in raw]


def test_sigkill_loses_at_most_the_flush_period_and_repair_works(tmp_path: Path, prefix: str, node) -> None:
    """Kill -9 mid-recording: everything from the first message sent up to flush_period
    (+ margin) before the kill is on disk; the bag then reads (with a warning) and repairs
    into a complete bag."""
    flush = 0.5
    margin = 1.5  # scheduling on a loaded 2-core machine; the design bound is flush + 0.125 s
    seconds = 5.0  # so that most of what was sent lies before the bound and must be recovered
    bag = tmp_path / "killed"
    pub = node.create_publisher(String, f"{prefix}/count", 100)
    with NodeProcess(
        "recorder",
        f"{prefix}/count",
        "-o",
        str(bag),
        "--discovery-period",
        "0.2",
        "--flush-period",
        str(flush),
    ) as rec:
        _wait_recorded(rec, pub, f"{prefix}/count")
        sent_at: list[float] = []  # monotonic send time of message i (its data is str(i))
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            sent_at.append(time.monotonic())
            pub.publish(String(data=str(len(sent_at) - 1)))
            time.sleep(0.002)
        kill_mono, kill_ns = time.monotonic(), time.time_ns()
        rec.proc.send_signal(signal.SIGKILL)
        assert rec.proc.wait(10) == -signal.SIGKILL
    assert not (bag / "metadata.yaml").exists()
    sent = len(sent_at)

    from rclpy.serialization import deserialize_message

    scanner = McapScanner(bag / "killed_0.mcap")
    recovered = [
        (m.log_time, int(deserialize_message(m.data, String).data)) for _c, _s, m in scanner.messages()
    ]
    values = [v for _, v in recovered]
    # the first message sent is there, and from it on every message, once, in order
    assert values and values[0] == 0, values[:5]
    assert values == list(range(len(values))), "recovered messages are not 0, 1, 2, ... in order"
    # bounded loss: what was sent more than flush + margin before the kill is all there
    must_have = sum(1 for t in sent_at if t < kill_mono - (flush + margin))
    lost = sent - len(values)
    lost_tail_s = kill_mono - sent_at[len(values)] if lost else 0.0  # oldest lost message's age
    newest_s = (kill_ns - recovered[-1][0]) / 1e9  # by the recorder's receive stamp
    print(
        f"\nSIGKILL after {seconds:g} s: sent {sent}, recovered {len(values)} (all of the first "
        f"{must_have} required), lost the last {lost} = {lost_tail_s:.3f} s of sending; newest recovered "
        f"message received {newest_s:.3f} s before the kill (flush period {flush} s)"
    )
    assert must_have > sent / 2  # the bound below is a real test, not a vacuous one
    assert len(values) >= must_have, (
        f"lost messages sent up to {lost_tail_s:.3f} s before the kill; the bound is {flush + margin} s"
    )
    assert lost_tail_s <= flush + margin and newest_s <= flush + margin

    exe = str(Path(sys.prefix) / "bin")
    info = subprocess.run([f"{exe}/replayer", str(bag), "--info"], capture_output=True, text=True, timeout=60)
    assert info.returncode == 0 and "complete:  no" in info.stdout and "recorder --repair" in info.stderr
    assert f"{prefix}/count [std_msgs/msg/String] {len(values)} msgs" in info.stdout

    fix = subprocess.run(
        [f"{exe}/recorder", "--repair", str(bag)], capture_output=True, text=True, timeout=60
    )
    assert fix.returncode == 0, fix.stderr
    assert f"recovered {len(values)} messages" in fix.stdout
    meta = check_bag(bag)
    assert meta["message_count"] == len(values)
    assert [int(m.data) for _, _, m in read_with_rosbags(bag)] == values


def test_messages_lost_to_a_full_queue_are_reported_not_silent(tmp_path: Path, prefix: str, node) -> None:
    """A queue of 5 taken every 0.5 s cannot hold a burst of 300: the recorder says how many
    never reached it (from the publisher's sequence numbers), exactly, and keeps the count in
    metadata.yaml."""
    import yaml

    options = ("--qos-depth", "5", "--poll-period", "0.5", "--status-period", "0.2")
    with _recording_one_topic(tmp_path, node, f"{prefix}/burst", *options) as (rec, pub, bag):
        pub.publish(String(data="0"))  # taken alone: the publisher's sequence is then known
        rec.wait_for_output("skipped; 1 messages", timeout=30)
        for i in range(1, 300):
            pub.publish(String(data=str(i)))
        time.sleep(1.2)
        assert rec.stop() == 0, rec.output
        out = rec.output
    got = [int(m.data) for _, _, m in read_with_rosbags(bag)]
    lost = 300 - len(got)
    assert got[0] == 0 and got[-1] == 299 and got == sorted(got) and lost > 0, got
    assert "never reached the recorder (its queue overflowed: raise --qos-depth" in out, out
    assert f"{prefix}/burst [std_msgs/msg/String]: {len(got)} messages, {lost} LOST (sequence gaps)" in out
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["lost_messages"] == f"{prefix}/burst: {lost}"
    info = subprocess.run([str(Path(sys.prefix) / "bin" / "replayer"), str(bag), "--info"],
                          capture_output=True, text=True, timeout=60)
    assert info.returncode == 0 and f"custom:    lost_messages: {prefix}/burst: {lost}" in info.stdout
    assert f"the recorder missed messages while recording this bag ({prefix}/burst: {lost})" in info.stderr


def test_messages_queued_at_the_stop_are_recorded(tmp_path: Path, prefix: str, node) -> None:
    """Stopped between two takes (a 5 s poll): what had arrived is still taken into the bag."""
    with _recording_one_topic(tmp_path, node, f"{prefix}/tail", "--poll-period", "5") as (rec, pub, bag):
        time.sleep(0.5)
        for i in range(50):
            pub.publish(String(data=str(i)))
        time.sleep(0.3)  # delivered to the recorder's queue, not yet taken
        assert rec.stop(signal.SIGINT) == 0, rec.output
    assert [int(m.data) for _, _, m in read_with_rosbags(bag)] == list(range(50))


#: Runs a console script with a file-size limit (RLIMIT_FSIZE), then execs it: the bag's writes fail
#: past the limit as they would on a full disk (EFBIG here, ENOSPC there; Python ignores SIGXFSZ).
_FILE_SIZE_LIMITED = (sys.executable, "-c", "import os, resource, sys; "
                      "resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[1]), int(sys.argv[1]))); "
                      "os.execv(sys.argv[2], sys.argv[2:])")


def test_a_disk_that_refuses_writes_ends_the_recording_clearly_and_repair_keeps_what_reached_it(
        tmp_path: Path, prefix: str, node) -> None:
    """Past the limit the recorder says why it stopped, once, exits 1, and --repair recovers every
    message flushed before (0, 1, 2, ... in order); the file-size limit stands in for a full disk."""
    import os

    limit = 400_000
    topic, bag = f"{prefix}/count", tmp_path / "full"
    pub = node.create_publisher(String, topic, 1000)
    rec = NodeProcess("recorder", topic, "-o", str(bag), "--discovery-period", "0.2", "--flush-period", "0.2",
                      prefix=(*_FILE_SIZE_LIMITED, str(limit)))
    with rec:
        _wait_recorded(rec, pub, topic)
        sent = 0
        deadline = time.monotonic() + 60
        while rec.proc.poll() is None and time.monotonic() < deadline:
            # Random text (about 2 kB a message) so that compression cannot keep it under the limit.
            pub.publish(String(data=f"{sent} {os.urandom(1000).hex()}"))
            sent += 1
            time.sleep(0.005)
        code = rec.proc.wait(30)
    lines = own_lines(rec.output)
    out = "\n".join(lines)
    assert code == 1, out
    assert sent * 2000 > limit  # the limit was reached, not the deadline
    failed = [line for line in lines if "recording failed:" in line]
    assert len(failed) == 1 and "File too large" in failed[0], failed
    assert "nothing after this is recorded" in failed[0]
    assert out.count("could not close the bag") == 1 and f"--repair {bag}" in out
    assert not (bag / "metadata.yaml").exists()

    exe = str(Path(sys.prefix) / "bin")
    fix = subprocess.run([f"{exe}/recorder", "--repair", str(bag)], capture_output=True, text=True,
                         timeout=60)
    assert fix.returncode == 0, fix.stderr
    values = [int(m.data.split()[0]) for _, _, m in read_with_rosbags(bag)]
    assert len(values) > 50 and values == list(range(len(values))), values[:5]
    assert check_bag(bag)["message_count"] == len(values)

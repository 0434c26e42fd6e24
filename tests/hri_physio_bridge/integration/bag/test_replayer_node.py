"""replayer node end to end: bytes, order, remapping, filtering, offset, /clock, errors."""

from __future__ import annotations

import itertools
import re
import signal
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, String

from helpers import NodeProcess, own_lines, wait_until
from helpers.bags import RawCollector, default_qos, make_bag, serialize
from hri_physio_bridge.bag.writer import BagWriter

pytestmark = pytest.mark.ros
NS = 1_000_000_000
T0 = 1_700_000_000 * NS
BIN = Path(sys.prefix) / "bin"


@pytest.fixture
def prefix() -> str:
    return f"/rptest_{uuid.uuid4().hex[:8]}"


@pytest.fixture
def collector(ros_context):
    c = RawCollector(ros_context, f"rp_collector_{uuid.uuid4().hex[:6]}")
    yield c
    c.close()


def _bag(tmp_path: Path, prefix: str) -> tuple[Path, list[bytes], list[bytes]]:
    msgs = []
    for i in range(40):
        msgs.append((f"{prefix}/a", T0 + i * 20_000_000, String(data=f"a{i}")))
        msgs.append(
            (f"{prefix}/f", T0 + i * 20_000_000 + 7_000_000, Float64MultiArray(data=[i * 0.5, 1.0, 2.0]))
        )
    written = make_bag(tmp_path / "src", msgs)
    a = [w for (t, _, _), w in zip(msgs, written, strict=True) if t.endswith("/a")]
    f = [w for (t, _, _), w in zip(msgs, written, strict=True) if t.endswith("/f")]
    return tmp_path / "src", a, f


def _decoded(raw: list[bytes], msg_type: type) -> list:
    """Messages as values: DDS may append up to 3 bytes of alignment padding on the wire."""
    from rclpy.serialization import deserialize_message

    return [deserialize_message(b, msg_type) for b in raw]


def _replay(*args: str, timeout: float = 60, script: str = "replayer") -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / script), *args], capture_output=True, text=True, timeout=timeout)


def test_plays_bytes_in_order_with_remap(tmp_path: Path, prefix: str, collector: RawCollector) -> None:
    bag, want_a, want_f = _bag(tmp_path, prefix)
    got_a = collector.subscribe(f"{prefix}/remapped", String)
    got_f = collector.subscribe(f"{prefix}/f", Float64MultiArray)
    r = _replay(
        str(bag),
        "--rate",
        "4",
        "--remap",
        f"{prefix}/a:={prefix}/remapped",
        "--wait-for-subscribers",
        "20",
        "--delay",
        "0.3",
    )
    assert r.returncode == 0, r.stderr
    wait_until(lambda: len(got_a) == 40 and len(got_f) == 40, 10, lambda: f"{len(got_a)}, {len(got_f)} msgs")
    assert _decoded(got_a, String) == _decoded(want_a, String)  # every message, in order
    assert _decoded(got_f, Float64MultiArray) == _decoded(want_f, Float64MultiArray)
    assert all(g[: len(w)] == w for g, w in zip(got_a + got_f, want_a + want_f, strict=True))  # same CDR
    assert f"{prefix}/a -> {prefix}/remapped: 40" in r.stderr


def test_topic_filter_rate_zero_start_offset_and_clock(
    tmp_path: Path, prefix: str, collector: RawCollector
) -> None:
    bag, _, want_f = _bag(tmp_path, prefix)
    got_a = collector.subscribe(f"{prefix}/a", String)
    got_f = collector.subscribe(f"{prefix}/f", Float64MultiArray)
    clock = collector.subscribe("/clock", Clock)
    r = _replay(
        str(bag),
        "--rate",
        "0",
        "--topics",
        f"{prefix}/f",
        "--start-offset",
        "0.2",
        "--clock",
        "--clock-step",
        "0.005",
        "--wait-for-subscribers",
        "20",
        "--delay",
        "0.3",
    )
    assert r.returncode == 0, r.stderr
    # offset 0.2 s: f messages at 7 ms + 20 ms * i >= 200 ms -> i >= 10
    wait_until(lambda: len(got_f) == 30, 10, lambda: f"{len(got_f)} f msgs")
    assert _decoded(got_f, Float64MultiArray) == _decoded(want_f[10:], Float64MultiArray) and got_a == []
    from rclpy.serialization import deserialize_message

    wait_until(lambda: clock and deserialize_message(clock[-1], Clock).clock.sec > 0, 10, "clock")
    ticks = [(c.clock.sec * NS + c.clock.nanosec) for c in (deserialize_message(b, Clock) for b in clock)]
    assert ticks[0] == T0 + 207_000_000  # first played message's time
    assert all(b - a == 5_000_000 for a, b in itertools.pairwise(ticks))
    assert ticks[-1] == T0 + 39 * 20_000_000 + 7_000_000


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_loop_until_stopped(
    tmp_path: Path, prefix: str, collector: RawCollector, stop_signal: signal.Signals
) -> None:
    """--loop plays until SIGINT (Ctrl-C) or SIGTERM (a launcher): a clean exit 0 and a summary."""
    bag, want_a, _ = _bag(tmp_path, prefix)
    got = collector.subscribe(f"{prefix}/a", String)
    with NodeProcess(
        "replayer",
        str(bag),
        "--loop",
        "--rate",
        "10",
        "--topics",
        f"{prefix}/a",
        "--wait-for-subscribers",
        "20",
    ) as rp:
        wait_until(lambda: len(got) > 90, 30, lambda: f"loop ({len(got)} msgs)")
        assert rp.stop(stop_signal) == 0, rp.output
    assert _decoded(got[:80], String) == _decoded(want_a + want_a, String)
    assert f"{stop_signal.name} received: stopping playback" in rp.output, rp.output
    assert "pass(es) (stopped)" in rp.output and "Traceback" not in rp.output, rp.output


def test_plays_a_killed_bag_with_a_warning(tmp_path: Path, prefix: str, collector: RawCollector) -> None:
    writer = BagWriter(tmp_path / "killed")
    from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition

    tn = "std_msgs/msg/String"
    writer.add_topic(
        f"{prefix}/a", tn, message_definition(tn), installed_type_hash(tn) or "", [default_qos()]
    )
    data = [serialize(String(data=f"k{i}")) for i in range(10)]
    for i, d in enumerate(data):
        writer.write(f"{prefix}/a", T0 + i * 1000, d)
    writer.flush()
    writer.write(f"{prefix}/a", T0 + 99_000, serialize(String(data="lost")))
    writer.abort()
    got = collector.subscribe(f"{prefix}/a", String)
    r = _replay(str(tmp_path / "killed"), "--rate", "0", "--wait-for-subscribers", "20", "--delay", "0.3")
    assert r.returncode == 0 and "did not finish" in r.stderr, r.stderr
    wait_until(lambda: len(got) == 10, 10, lambda: f"{len(got)} msgs")
    assert _decoded(got, String) == _decoded(data, String)


def test_clear_errors(tmp_path: Path) -> None:
    def one_line_error(r: subprocess.CompletedProcess, text: str) -> None:
        assert r.returncode == 2, r
        assert "Traceback" not in r.stderr and text in r.stderr, r.stderr
        assert len([x for x in r.stderr.splitlines() if x.startswith("replayer: error:")]) == 1, r.stderr

    one_line_error(_replay(str(tmp_path / "missing")), "does not exist")
    # damaged records and no readable message: corrupt or truncated, with file and byte offset
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(b"\x89MCAP0\r\n" + b"\x06" + b"\xff" * 40)
    for args in ((), ("--info",)):
        r = _replay(str(corrupt), *args)
        one_line_error(r, f"{corrupt} is corrupt or truncated: chunk record at byte 8 is cut short")
        assert "empty bag" not in r.stderr and "warning" not in r.stderr, r.stderr
    cut = BagWriter(tmp_path / "cut")  # a recording cut inside its first (and only) chunk
    cut.add_topic("/a", "std_msgs/msg/String", "string data\n", "", [])
    cut.write("/a", T0, serialize(String(data="x" * 200)))
    cut.flush()
    cut.abort()
    data = cut.path.read_bytes()
    cut.path.write_bytes(data[: len(data) - 50])
    one_line_error(_replay(str(tmp_path / "cut")), f"{cut.path} is corrupt or truncated: ")
    # a valid bag without messages stays an empty bag: finished, or killed before any flush
    killed_early = BagWriter(tmp_path / "killed_early")
    killed_early.add_topic("/a", "std_msgs/msg/String", "string data\n", "", [])
    killed_early.abort()
    r = _replay(str(tmp_path / "killed_early"))
    one_line_error(r, "empty bag")
    assert "corrupt" not in r.stderr, r.stderr
    (tmp_path / "junk.mcap").write_bytes(b"PK\x03\x04 a zip, not a bag" * 20)
    one_line_error(_replay(str(tmp_path / "junk.mcap")), "not an MCAP file")
    empty = BagWriter(tmp_path / "empty")
    empty.add_topic("/a", "std_msgs/msg/String", "string data\n", "", [])
    empty.close()
    one_line_error(_replay(str(tmp_path / "empty")), "empty bag")
    unknown = BagWriter(tmp_path / "unknown")
    unknown.add_topic("/x", "nonexistent_msgs/msg/Thing", "int32 a\n", "RIHS01_" + "0" * 64, [])
    unknown.write("/x", T0, b"\x00\x01\x00\x00\x05\x00\x00\x00")
    unknown.close()
    one_line_error(_replay(str(tmp_path / "unknown")), "not installed for /x [nonexistent_msgs/msg/Thing]")
    one_line_error(_replay(str(tmp_path / "unknown"), "--rate", "-1"), "rate")
    one_line_error(_replay(str(tmp_path / "unknown"), "--ros-args", "-p", "rate:=fast"), "rate")
    one_line_error(_replay(str(tmp_path / "unknown"), "--ros-args", "-p", "clock_step:=0"), "clock_step")
    one_line_error(_replay(str(tmp_path / "unknown"), "--ros-args", "-p", "topics:=[1, 2]"), "topics")
    one_line_error(_replay(str(tmp_path / "unknown"), "--ros-args", "-p", "colour:=red"), "colour")
    unknown = str(tmp_path / "unknown")
    one_line_error(_replay(unknown, "--ros-args", "--params-file", str(tmp_path / "no.yaml")), "no.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("physio_replayer:\n  ros__parameters: {rate: [1\n")
    one_line_error(_replay(unknown, "--ros-args", "--params-file", str(broken)), "broken.yaml")
    one_line_error(_replay(str(tmp_path / "unknown"), "--remap", "/x=/y"), "/from:=/to")
    one_line_error(_replay(str(tmp_path / "unknown"), "--topics", "/nope"), "not in the bag")
    r = _replay(str(tmp_path / "unknown"), "--info")
    assert r.returncode == 0 and "/x [nonexistent_msgs/msg/Thing] 1 msgs" in r.stdout
    r = _replay("--help")
    assert r.returncode == 0 and "--clock-step" in r.stdout


def test_info_checks_every_chunk_of_a_bag_with_flipped_bytes(tmp_path: Path) -> None:
    """400 bytes flipped mid-file: --info used to say "complete: yes" while playback stopped
    part-way; it now names the damaged chunk and how many messages it holds."""
    from std_msgs.msg import String as Msg

    n = 1000
    make_bag(tmp_path / "flipped", [("/a", T0 + i * 10_000_000, Msg(data=f"{i:05d} " + "x" * 80))
                                    for i in range(n)], chunk_size=4096)
    mcap = tmp_path / "flipped" / "flipped_0.mcap"
    data = bytearray(mcap.read_bytes())
    for i in range(len(data) // 2, len(data) // 2 + 400):
        data[i] ^= 0xFF
    mcap.write_bytes(bytes(data))

    info = _replay(str(tmp_path / "flipped"), "--info", script="physio_replayer")
    assert info.returncode == 0, info.stderr
    assert "complete:  no (" in info.stdout and "damaged chunk" in info.stdout, info.stdout
    damaged = [line for line in info.stdout.splitlines() if line.startswith("damaged:")]
    assert len(damaged) >= 1, info.stdout
    held = sum(int(re.search(r"(\d+) message\(s\) unreadable", line).group(1)) for line in damaged)
    assert f"holding {held} message(s)" in info.stdout

    # What --info says is lost is what a repair cannot bring back, and nothing more.
    fix = subprocess.run([str(BIN / "physio_recorder"), "--repair", str(tmp_path / "flipped")],
                         capture_output=True, text=True, timeout=60)
    assert fix.returncode == 0 and f"recovered {n - held} messages" in fix.stdout, fix.stdout + fix.stderr
    after = _replay(str(tmp_path / "flipped"), "--info")
    assert "complete:  yes" in after.stdout and f"messages:  {n - held}" in after.stdout, after.stdout


def test_new_names_and_old_names_run_the_same_command(tmp_path: Path) -> None:
    bag = tmp_path / "b"
    make_bag(bag, [("/a", T0, String(data="x"))])
    for script in ("physio_replayer", "replayer"):
        r = _replay(str(bag), "--info", script=script)
        assert r.returncode == 0 and "/a [std_msgs/msg/String] 1 msgs" in r.stdout, r.stderr
        r = _replay(str(bag), "--rate", "-1", script=script)
        assert r.returncode == 2 and own_lines(r.stderr)[0].startswith(f"{script}: error:"), r.stderr

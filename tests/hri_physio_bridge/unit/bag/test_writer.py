"""BagWriter + metadata + reader: round trip through independent readers, durability, refusal."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from std_msgs.msg import Float64MultiArray, String

from helpers.bags import check_bag, default_qos, make_bag, read_with_mcap, read_with_rosbags, serialize
from hri_physio_bridge.bag.errors import BagError, BagExistsError
from hri_physio_bridge.bag.metadata import metadata_problems
from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition, msg_dependencies
from hri_physio_bridge.bag.reader import BagReader
from hri_physio_bridge.bag.recovery import McapScanner
from hri_physio_bridge.bag.writer import BagWriter
from hri_physio_bridge.frames import Frame
from hri_physio_bridge.ros_frames import frame_to_msg, msg_to_frame

T0 = 1_700_000_000_000_000_000


def _frames(n: int, channels: int = 3) -> list[Float64MultiArray]:
    rng = np.random.default_rng(7)
    return [
        frame_to_msg(Frame(100.0 + i * 0.1 + np.arange(10) / 100, rng.normal(size=(10, channels))))
        for i in range(n)
    ]


def test_round_trip_through_rosbags_and_mcap_readers(tmp_path: Path) -> None:
    frames = _frames(50)
    strings = [String(data=f"event {i} ✓") for i in range(30)]
    msgs = [("/physio/sim/ecg", T0 + i * 10_000_000, m) for i, m in enumerate(frames)]
    msgs += [("/coach/events", T0 + 5_000_001 + i * 7_000_000, m) for i, m in enumerate(strings)]
    msgs.sort(key=lambda x: x[1])
    bag = tmp_path / "rt"
    written = make_bag(bag, msgs, chunk_size=4096)  # small chunks: many chunks and indexes

    meta = check_bag(bag)
    assert meta["message_count"] == 80
    assert meta["starting_time"]["nanoseconds_since_epoch"] == msgs[0][1]
    assert meta["duration"]["nanoseconds"] == msgs[-1][1] - msgs[0][1]

    got = read_with_rosbags(bag)
    assert [(t, s) for t, s, _ in got] == [(t, s) for t, s, _ in msgs]
    for (_, _, want), (_, _, have) in zip(msgs, got, strict=True):
        if isinstance(want, String):
            assert have.data == want.data
        else:
            assert [(d.label, d.size, d.stride) for d in have.layout.dim] == [
                (d.label, d.size, d.stride) for d in want.layout.dim
            ]
            np.testing.assert_array_equal(have.data, want.data)
    # mcap's reader sees the raw CDR unchanged, and our frames decode from it bit for bit
    from rclpy.serialization import deserialize_message

    raw = read_with_mcap(bag / "rt_0.mcap")
    assert [d for _, _, d in raw] == written
    ecg = [
        msg_to_frame(deserialize_message(d, Float64MultiArray)) for t, _, d in raw if t == "/physio/sim/ecg"
    ]
    for have, want in zip(ecg, frames, strict=True):
        np.testing.assert_array_equal(have.timestamps, msg_to_frame(want).timestamps)
        np.testing.assert_array_equal(have.values, msg_to_frame(want).values)


def test_schema_text_describes_exactly_the_installed_type() -> None:
    """rosbags rebuilds the type from our schema text and gets the installed RIHS01 hash."""
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.msg import get_types_from_msg

    name = "std_msgs/msg/Float64MultiArray"
    text = message_definition(name)
    parts = text.split("\n" + "=" * 80 + "\n")
    assert [p.split("\n", 1)[0] for p in parts[1:]] == [
        "MSG: std_msgs/MultiArrayLayout",
        "MSG: std_msgs/MultiArrayDimension",
    ]
    types = get_types_from_msg(parts[0], name)
    for part in parts[1:]:
        head, body = part.split("\n", 1)
        pkg, typ = head.removeprefix("MSG: ").split("/")
        types.update(get_types_from_msg(body, f"{pkg}/msg/{typ}"))
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    assert store.hash_rihs01(name) == installed_type_hash(name)


def test_msg_dependencies_ignore_comments_constants_and_bounds() -> None:
    text = "# pkg/NotAType x\nuint8 A=1\nstring<=5 s\ngeometry_msgs/Point[] p\nHeader h # c\nint32[4] a\n"
    assert msg_dependencies(text, "mypkg") == ["geometry_msgs/Point", "mypkg/Header"]


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    bag = tmp_path / "b"
    make_bag(bag, [("/a", T0, String(data="x"))])
    before = sorted(p.name for p in bag.iterdir())
    with pytest.raises(BagExistsError, match="never overwritten"):
        BagWriter(bag)
    assert sorted(p.name for p in bag.iterdir()) == before


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _add_string_topic(writer: BagWriter, topic: str = "/s") -> None:
    tn = "std_msgs/msg/String"
    writer.add_topic(topic, tn, message_definition(tn), installed_type_hash(tn) or "", [default_qos()])


def test_age_flush_puts_old_messages_on_disk_while_recording(tmp_path: Path) -> None:
    """A slow topic's messages reach the file within flush_period, not at 768 KiB."""
    clock = FakeClock()
    writer = BagWriter(tmp_path / "d", flush_period=1.0, fsync_period=None, monotonic=clock)
    _add_string_topic(writer)
    for i in range(5):
        writer.write("/s", T0 + i, serialize(String(data=f"m{i}")))
        clock.t += 0.1
    assert _recovered(writer.path) == []  # chunk still open (0.4 s old)
    clock.t = 1.05
    writer.tick()  # the chunk is now older than flush_period
    assert _recovered(writer.path) == [f"m{i}" for i in range(5)]
    writer.write("/s", T0 + 10, serialize(String(data="late")))
    assert _recovered(writer.path) == [f"m{i}" for i in range(5)]
    writer.abort()  # like a crash: the open chunk is lost, the flushed one is not
    assert _recovered(writer.path) == [f"m{i}" for i in range(5)]


def test_size_flush(tmp_path: Path) -> None:
    clock = FakeClock()
    writer = BagWriter(
        tmp_path / "d", chunk_size=2048, flush_period=100.0, fsync_period=None, monotonic=clock
    )
    _add_string_topic(writer)
    payload = "x" * 500
    for i in range(22):
        writer.write("/s", T0 + i, serialize(String(data=f"{i}:{payload}")))
    on_disk = _recovered(writer.path)
    assert len(on_disk) == 20  # five full chunks of four ~540-byte messages; two pending
    assert on_disk == [f"{i}:{payload}" for i in range(len(on_disk))]
    writer.close()
    assert len(_recovered(writer.path)) == 22


def _recovered(path: Path) -> list[str]:
    from rclpy.serialization import deserialize_message

    return [deserialize_message(m.data, String).data for _c, _s, m in McapScanner(path).messages()]


def test_metadata_problems_found(tmp_path: Path) -> None:
    bag = tmp_path / "m"
    make_bag(bag, [("/a", T0, String(data="x")), ("/a", T0 + 5, String(data="y"))])
    good = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert metadata_problems(good, bag) == []

    def broken(edit) -> list[str]:
        doc = yaml.safe_load((bag / "metadata.yaml").read_text())
        edit(doc["rosbag2_bagfile_information"])
        return metadata_problems(doc, bag, strict=True)

    assert any("relative" in p for p in broken(lambda m: m.update(relative_file_paths=["/abs/m_0.mcap"])))
    assert any("does not exist" in p for p in broken(lambda m: m.update(relative_file_paths=["x.mcap"])))
    assert any("message_count" in p for p in broken(lambda m: m.update(message_count=3)))
    assert any("storage_identifier" in p for p in broken(lambda m: m.update(storage_identifier="sqlite3")))
    assert any("version" in p for p in broken(lambda m: m.update(version=10)))
    assert any(
        "type_description_hash" in p
        for p in broken(
            lambda m: m["topics_with_message_count"][0]["topic_metadata"].update(type_description_hash="x")
        )
    )
    assert any(
        "QoS" in p
        for p in broken(
            lambda m: m["topics_with_message_count"][0]["topic_metadata"].update(
                offered_qos_profiles=[{"depth": 1}]
            )
        )
    )


def test_reader_orders_filters_and_offsets(tmp_path: Path) -> None:
    msgs = [("/a" if i % 2 else "/b", T0 + i * 1_000_000, String(data=str(i))) for i in range(40)]
    make_bag(tmp_path / "r", msgs, chunk_size=1024)
    bag = BagReader(tmp_path / "r")
    assert bag.complete and bag.message_count == 40 and bag.warnings == []
    assert bag.topics["/a"].message_count == 20 and bag.topics["/a"].type == "std_msgs/msg/String"
    assert [m.log_time_ns for m in bag.messages()] == [t for _, t, _ in msgs]
    only_a = list(bag.messages(["/a"], start_ns=T0 + 20_000_000))
    assert [m.log_time_ns for m in only_a] == [T0 + i * 1_000_000 for i in range(21, 40, 2)]
    # the bare .mcap file (copied out of its directory) plays the same
    bare = tmp_path / "copy.mcap"
    shutil.copy(tmp_path / "r" / "r_0.mcap", bare)
    assert [m.data for m in BagReader(bare).messages()] == [m.data for m in bag.messages()]


def test_reader_errors_are_one_liners(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="does not exist"):
        BagReader(tmp_path / "nope")
    (tmp_path / "junk.mcap").write_bytes(b"this is not mcap at all" * 10)
    with pytest.raises(BagError, match="not an MCAP file"):
        BagReader(tmp_path / "junk.mcap")
    (tmp_path / "zero.mcap").write_bytes(b"")
    with pytest.raises(BagError, match=r"zero\.mcap is not an MCAP file \(empty: 0 bytes\)"):
        BagReader(tmp_path / "zero.mcap")
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(BagError, match="not a rosbag2 directory"):
        BagReader(tmp_path / "emptydir")
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(BagError, match="neither"):
        BagReader(tmp_path / "x.txt")
    bag = tmp_path / "badmeta"
    make_bag(bag, [("/a", T0, String(data="x"))])
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed")
    with pytest.raises(BagError, match="not readable YAML"):
        BagReader(bag)

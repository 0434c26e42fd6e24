"""RecordingSession: which topics get recorded, which are skipped (and said so once), stamps."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from std_msgs.msg import String

from helpers.bags import default_qos, serialize
from hri_physio_bridge.bag.msgdefs import UnknownTypeError, import_message_type, installed_type_hash
from hri_physio_bridge.bag.recording import RecordingSession
from hri_physio_bridge.bag.recovery import McapScanner
from hri_physio_bridge.bag.topic_selection import TopicSelector
from hri_physio_bridge.bag.writer import BagWriter


def test_skips_are_reported_once_with_reasons(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    log = logging.getLogger("test.recording")
    writer = BagWriter(tmp_path / "s")
    session = RecordingSession(writer, TopicSelector(), log, wall_ns=lambda: 4200)
    graph = [
        ("/a", ["std_msgs/msg/String"]),
        ("/b", ["foo_msgs/msg/Bar"]),
        ("/c", ["std_msgs/msg/String", "std_msgs/msg/Int32"]),
        ("/_hidden/x", ["std_msgs/msg/String"]),
    ]
    with caplog.at_level(logging.WARNING, logger="test.recording"):
        cands = session.candidates(graph)
        session.candidates(graph)  # polled again: no new warnings
    assert [c.topic for c in cands] == ["/a"] and cands[0].msg_class is String
    assert "foo_msgs/msg/Bar is not installed" in session.skipped["/b"]
    assert "2 types" in session.skipped["/c"]
    assert len(caplog.records) == 2

    qos = [default_qos()]
    assert session.start_topic(cands[0], qos, ["INVALID"])  # no graph hash: the installed one is used
    assert writer.topics["/a"].type_description_hash == installed_type_hash("std_msgs/msg/String")
    assert session.candidates(graph) == []  # recorded topics are not offered again
    session.on_message(
        "/a", serialize(String(data="x")), {"received_timestamp": 1000, "source_timestamp": 900}
    )
    session.on_message("/a", serialize(String(data="y")), None)  # no message info: wall clock
    assert "1 topic(s) recorded, 2 skipped; 2 messages" in session.status()
    writer.close()
    got = [(m.log_time, m.publish_time) for _c, _s, m in McapScanner(writer.path).messages()]
    assert got == [(1000, 900), (4200, 4200)]


def test_conflicting_hashes_are_not_recorded(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / "h")
    session = RecordingSession(writer, TopicSelector(), logging.getLogger("test.recording"))
    (cand,) = session.candidates([("/a", ["std_msgs/msg/String"])])
    assert not session.start_topic(cand, [default_qos()] * 2, ["RIHS01_" + "1" * 64, "RIHS01_" + "2" * 64])
    assert "different type hashes" in session.skipped["/a"] and "/a" not in writer.topics
    writer.close()


def test_import_message_type() -> None:
    assert import_message_type("std_msgs/msg/String") is String
    with pytest.raises(UnknownTypeError, match="not installed"):
        import_message_type("std_msgs/msg/NoSuchType")
    with pytest.raises(UnknownTypeError, match="not a ROS 2 type name"):
        import_message_type("String")


def test_sequence_gaps_are_counted_per_publisher_reported_and_kept_in_metadata(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Two publishers on one topic, each with its own sequence; one skips 3 then 2 messages."""
    import yaml

    now = [0.0]
    writer, session = _hr_session(tmp_path / "g", now)
    data = serialize(String(data="x"))

    def take(seq: int, gid: bytes) -> None:
        info = {"received_timestamp": 1000 + seq, "publication_sequence_number": seq,
                "publisher_gid": {"implementation_identifier": "rmw_fastrtps_cpp", "data": gid}}
        session.on_message("/hr", data, info)

    a, b = b"\x01" * 16, b"\x02" * 16
    with caplog.at_level(logging.WARNING, logger="test.recording"):
        for seq in (500, 501):  # joined a running publisher: its first seen message is no gap
            take(seq, a)
        for seq in (1, 2, 3):  # the other publisher interleaves its own sequence
            take(seq, b)
        take(505, a)  # 502-504 missed
        now[0] = 1.0
        take(508, a)  # 506-507 missed: counted, summarised in the next line (rate limited)
        session.on_message("/hr", data, {"publication_sequence_number": None})  # unsupported: skipped
    assert session.lost == {"/hr": 5}
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "/hr: 3 message(s) from one publisher never reached the recorder (its queue overflowed: raise "
        "--qos-depth; or a best-effort link dropped them) (3 message(s) lost so far; repeats are "
        "summarised at most every 5 s)"
    ]
    assert "8 messages" in session.status() and ", 5 lost" in session.status()
    session.finish()
    info = writer.close()
    assert session.summary_lines(info) == ["/hr [std_msgs/msg/String]: 8 messages, 5 LOST (sequence gaps)"]
    meta = yaml.safe_load((tmp_path / "g" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["lost_messages"] == "/hr: 5"


def test_a_message_delivered_after_another_is_logged_after_it(tmp_path: Path) -> None:
    """A restarted publisher's first messages, repaired by DDS after a later one was received: the bag
    keeps the order the topic delivered them in (a reader goes by log time), other topics untouched."""
    from rosbags.highlevel import AnyReader

    writer, session = _hr_session(tmp_path / "r", [0.0])
    (cand,) = session.candidates([("/x", ["std_msgs/msg/String"])])
    assert session.start_topic(cand, [default_qos()], [])
    delivered = [("/hr", "a", 5_000), ("/hr", "b", 2_000), ("/x", "x", 3_000), ("/hr", "c", 2_000),
                 ("/hr", "d", 9_000)]
    for topic, text, received in delivered:
        session.on_message(topic, serialize(String(data=text)), {"received_timestamp": received})
    writer.close()
    with AnyReader([tmp_path / "r"]) as reader:
        got = [(c.topic, reader.deserialize(raw, c.msgtype).data, t) for c, t, raw in reader.messages()]
    assert got == [("/x", "x", 3_000), ("/hr", "a", 5_000), ("/hr", "b", 5_001), ("/hr", "c", 5_002),
                   ("/hr", "d", 9_000)]


def test_no_loss_leaves_no_lost_entry(tmp_path: Path) -> None:
    writer, session = _hr_session(tmp_path / "n", [0.0])
    for seq in range(1, 50):
        session.on_message("/hr", serialize(String(data="x")),
                           {"publication_sequence_number": seq, "publisher_gid": {"data": b"\x03" * 16}})
    session.finish()
    writer.close()
    assert session.lost == {} and "lost" not in session.status()
    assert "lost_messages" not in (tmp_path / "n" / "metadata.yaml").read_text()


def test_low_disk_space_is_warned_early_and_not_every_report(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from hri_physio_bridge.bag.recording import LOW_DISK_BYTES

    now = [0.0]
    writer, session = _hr_session(tmp_path / "d", now)
    gb = 1_000_000_000
    with caplog.at_level(logging.WARNING, logger="test.recording"):
        writer.stats.file_bytes = 50_000_000  # 50 MB in 5 s: 10 MB/s
        assert not session.check_disk(10 * gb, 5.0)  # 1000 s left: fine
        writer.stats.file_bytes += 50_000_000
        assert session.check_disk(5 * gb, 5.0)  # 500 s left at 10 MB/s: warn
        now[0] = 5.0
        writer.stats.file_bytes += 50_000_000
        assert session.check_disk(4 * gb, 5.0)  # still low, but warned 5 s ago: quiet
        now[0] = 70.0
        assert session.check_disk(LOW_DISK_BYTES - 1, 65.0)  # nothing written: low by size alone
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        f"low disk space for {writer.bag_dir}: 5.00 GB free, about 8 min at 10.00 MB/s; free some "
        "space or the recording stops when the disk is full",
        f"low disk space for {writer.bag_dir}: 0.50 GB free; free some space or the recording stops "
        "when the disk is full",
    ]
    writer.close()


def _hr_session(bag: Path, now: list[float]) -> tuple[BagWriter, RecordingSession]:
    """A session recording /hr (std_msgs/String) into ``bag``, on the fake clock ``now``."""
    writer = BagWriter(bag)
    session = RecordingSession(writer, TopicSelector(), logging.getLogger("test.recording"),
                               monotonic=lambda: now[0])
    (cand,) = session.candidates([("/hr", ["std_msgs/msg/String"])])
    assert session.start_topic(cand, [default_qos()], [])
    return writer, session

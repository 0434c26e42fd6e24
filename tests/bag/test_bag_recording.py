"""RecordingSession: which topics get recorded, which are skipped (and said so once), stamps."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from bagkit import default_qos, serialize
from std_msgs.msg import String

from hri_physio_bridge.bag.msgdefs import UnknownTypeError, import_message_type, installed_type_hash
from hri_physio_bridge.bag.recording import RecordingSession
from hri_physio_bridge.bag.recovery import McapScanner
from hri_physio_bridge.bag.topics import TopicSelector
from hri_physio_bridge.bag.writer import BagWriter


def test_skips_are_reported_once_with_reasons(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    log = logging.getLogger("test.recording")
    writer = BagWriter(tmp_path / "s")
    session = RecordingSession(writer, TopicSelector(), log, wall_ns=lambda: 42)
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
    assert got == [(1000, 900), (42, 42)]


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

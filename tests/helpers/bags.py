"""Helpers for the bag tests: build bags, read them back with independent readers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hri_physio_bridge.bag.metadata import METADATA_FILE, metadata_problems
from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition
from hri_physio_bridge.bag.recorded_qos import qos_to_dict
from hri_physio_bridge.bag.writer import BagWriter


def serialize(msg: Any) -> bytes:
    from rclpy.serialization import serialize_message

    return serialize_message(msg)


def default_qos() -> dict[str, Any]:
    from rclpy.qos import QoSProfile

    return qos_to_dict(QoSProfile(depth=10))


def type_name(msg: Any) -> str:
    module = type(msg).__module__.split(".")  # std_msgs.msg._string
    return f"{module[0]}/{module[1]}/{type(msg).__name__}"


def make_bag(path: Path, messages: list[tuple[str, int, Any]], **writer_args: Any) -> list[bytes]:
    """A closed bag holding ``(topic, log_time_ns, msg)``; topics registered on first use.

    Returns the CDR bytes written: serializing the same message twice may differ in the
    (uninitialised) alignment padding, so raw comparisons must use these very bytes.
    """
    writer = BagWriter(path, **writer_args)
    written = []
    for topic, t_ns, msg in messages:
        if topic not in writer.topics:
            tn = type_name(msg)
            writer.add_topic(
                topic, tn, message_definition(tn), installed_type_hash(tn) or "", [default_qos()]
            )
        written.append(serialize(msg))
        writer.write(topic, t_ns, written[-1])
    writer.close()
    return written


def read_with_rosbags(bag: Path) -> list[tuple[str, int, Any]]:
    """Every message via rosbags' AnyReader, types built from the bag's own definitions."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = []
    with AnyReader([bag], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for conn, t, raw in reader.messages():
            out.append((conn.topic, t, reader.deserialize(raw, conn.msgtype)))
    return out


def read_with_mcap(mcap_file: Path) -> list[tuple[str, int, bytes]]:
    """Every message via the ``mcap`` library's indexed reader (needs a summary)."""
    from mcap.reader import make_reader

    with mcap_file.open("rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        assert reader.get_summary() is not None, f"{mcap_file} has no summary"
        return [(ch.topic, m.log_time, m.data) for _s, ch, m in reader.iter_messages(log_time_order=True)]


def check_bag(bag: Path) -> dict[str, Any]:
    """The checks a rosbag2 reader makes, plus: metadata agrees with the MCAP summary and the
    type hashes are those of the installed message definitions. Returns the metadata."""
    import yaml
    from mcap.reader import make_reader

    doc = yaml.safe_load((bag / METADATA_FILE).read_text())
    assert metadata_problems(doc, bag, strict=True) == []
    meta = doc["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    (rel,) = meta["relative_file_paths"]
    with (bag / rel).open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert summary.statistics.message_count == meta["message_count"]
    for entry in meta["topics_with_message_count"]:
        tm = entry["topic_metadata"]
        assert counts.get(tm["name"], 0) == entry["message_count"], tm["name"]
        assert tm["type_description_hash"] == installed_type_hash(tm["type"]), tm["name"]
    return meta


class RawCollector:
    """An rclpy node on its own executor thread keeping every raw message of some topics."""

    def __init__(self, context: Any, name: str = "bag_collector") -> None:
        from rclpy.node import Node

        from hri_physio_bridge.ros_tools import ExecutorThread

        self.node = Node(name, context=context)
        self.messages: dict[str, list[bytes]] = {}
        self._spinner = ExecutorThread(self.node, context=context)

    def subscribe(self, topic: str, msg_type: Any, qos: Any = None) -> list[bytes]:
        from rclpy.qos import QoSProfile

        got = self.messages.setdefault(topic, [])
        self.node.create_subscription(msg_type, topic, got.append, qos or QoSProfile(depth=1000), raw=True)
        return got

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()

"""rosbag2 ``metadata.yaml`` (format version 9, what Jazzy writes): build, write, load, check.

The same document is stored inside the MCAP file as the ``rosbag2`` metadata record
(``serialized_metadata``), as rosbag2's MCAP plugin does, so a bare ``.mcap`` copied out of
its directory still describes itself.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import yaml

from hri_physio_bridge.bag.errors import BagError

VERSION = 9
STORAGE_ID = "mcap"
METADATA_FILE = "metadata.yaml"
ROOT_KEY = "rosbag2_bagfile_information"
HASH_RE = re.compile(r"^RIHS01_[0-9a-f]{64}$")
#: custom_data key under which the recorder lists the messages it missed, per topic.
LOST_KEY = "lost_messages"
QOS_KEYS = (
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
)


def default_ros_distro() -> str:
    return os.environ.get("ROS_DISTRO") or "jazzy"


@dataclass
class TopicInfo:
    name: str
    type: str
    offered_qos_profiles: list[dict[str, Any]] = field(default_factory=list)
    type_description_hash: str = ""
    serialization_format: str = "cdr"
    message_count: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {
            "topic_metadata": {
                "name": self.name,
                "type": self.type,
                "serialization_format": self.serialization_format,
                "offered_qos_profiles": self.offered_qos_profiles,
                "type_description_hash": self.type_description_hash,
            },
            "message_count": self.message_count,
        }


@dataclass
class BagInfo:
    """What ``metadata.yaml`` says about a single-file MCAP bag."""

    relative_file: str
    topics: list[TopicInfo]
    starting_time_ns: int = 0
    duration_ns: int = 0
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = field(default_factory=default_ros_distro)

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics)

    def as_dict(self) -> dict[str, Any]:
        start = {"nanoseconds_since_epoch": int(self.starting_time_ns)}
        duration = {"nanoseconds": int(self.duration_ns)}
        return {
            ROOT_KEY: {
                "version": VERSION,
                "storage_identifier": STORAGE_ID,
                "duration": duration,
                "starting_time": start,
                "message_count": self.message_count,
                "topics_with_message_count": [t.as_dict() for t in self.topics],
                "compression_format": "",  # zstd is chunk (storage) compression inside the MCAP
                "compression_mode": "",
                "relative_file_paths": [self.relative_file],
                "files": [
                    {
                        "path": self.relative_file,
                        "starting_time": dict(start),  # copies: no YAML anchors/aliases
                        "duration": dict(duration),
                        "message_count": self.message_count,
                    }
                ],
                "custom_data": dict(self.custom_data) or None,
                "ros_distro": self.ros_distro,
            }
        }

    def to_yaml(self, root: bool = True) -> str:
        doc = self.as_dict()
        return yaml.safe_dump(
            doc if root else doc[ROOT_KEY], sort_keys=False, default_flow_style=False, width=1000
        )


def write_metadata(bag_dir: Path, info: BagInfo) -> Path:
    """Write ``metadata.yaml`` atomically (temporary file, fsync, rename)."""
    path = bag_dir / METADATA_FILE
    tmp = path.with_suffix(".yaml.tmp")
    with tmp.open("w", encoding="utf-8") as fh:
        fh.write(info.to_yaml())
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)
    _fsync_dir(bag_dir)
    return path


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def load_metadata(bag_dir: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping, checked as rosbag2 checks it."""
    path = bag_dir / METADATA_FILE
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BagError(f"{bag_dir} has no {METADATA_FILE}") from None
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BagError(f"{path} is not readable YAML: {str(exc).splitlines()[0]}") from None
    problems = metadata_problems(doc, bag_dir)
    if problems:
        raise BagError(f"{path}: " + "; ".join(problems))
    return doc[ROOT_KEY]


def _int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _qos_problems(name: str, profiles: Any) -> list[str]:
    if isinstance(profiles, str):  # version <= 8 stored a YAML string
        return [f"topic {name}: offered_qos_profiles must be a list in version {VERSION}"]
    if not isinstance(profiles, list):
        return [f"topic {name}: offered_qos_profiles is not a list"]
    out = []
    for p in profiles:
        missing = [k for k in QOS_KEYS if not isinstance(p, Mapping) or k not in p]
        if missing:
            out.append(f"topic {name}: QoS profile lacks {missing}")
    return out


def metadata_problems(doc: Any, bag_dir: Path | None = None, strict: bool = False) -> list[str]:
    """Everything a rosbag2 reader would trip on (empty list: the metadata is sound).

    ``strict`` also requires every topic to carry a type description hash (what our
    recorder always writes for installed types)."""
    if not isinstance(doc, Mapping) or not isinstance(doc.get(ROOT_KEY), Mapping):
        return [f"top-level key {ROOT_KEY!r} missing"]
    m = doc[ROOT_KEY]
    out: list[str] = []
    version = m.get("version")
    if not _int(version) or not 1 <= version <= VERSION:
        out.append(f"version {version!r} is not a rosbag2 version this reader knows (1..{VERSION})")
    if m.get("storage_identifier") != STORAGE_ID:
        out.append(f"storage_identifier {m.get('storage_identifier')!r} is not {STORAGE_ID!r}")
    rel = m.get("relative_file_paths")
    if not isinstance(rel, list) or not rel:
        out.append("relative_file_paths is empty")
        rel = []
    for p in rel:
        pp = PurePosixPath(str(p))
        if pp.is_absolute() or ".." in pp.parts:
            out.append(f"file path {p!r} is not relative to the bag directory")
        elif bag_dir is not None and not (bag_dir / pp).is_file():
            out.append(f"file {p!r} listed in metadata does not exist")
    for key, sub in (("duration", "nanoseconds"), ("starting_time", "nanoseconds_since_epoch")):
        if not isinstance(m.get(key), Mapping) or not _int(m[key].get(sub)):
            out.append(f"{key}.{sub} missing or not a non-negative integer")
    topics = m.get("topics_with_message_count")
    if not isinstance(topics, list):
        out.append("topics_with_message_count is not a list")
        topics = []
    total = 0
    names = set()
    for t in topics:
        tm = t.get("topic_metadata") if isinstance(t, Mapping) else None
        if not isinstance(tm, Mapping):
            out.append("a topic entry lacks topic_metadata")
            continue
        name = tm.get("name")
        if not isinstance(name, str) or not name.startswith("/"):
            out.append(f"topic name {name!r} is not absolute")
        if name in names:
            out.append(f"topic {name} listed twice")
        names.add(name)
        if not isinstance(tm.get("type"), str) or tm["type"].count("/") != 2:
            out.append(f"topic {name}: type {tm.get('type')!r} is not 'pkg/msg/Type'")
        if tm.get("serialization_format") != "cdr":
            out.append(f"topic {name}: serialization_format {tm.get('serialization_format')!r} is not 'cdr'")
        h = tm.get("type_description_hash", "")  # absent before version 8
        if not isinstance(h, str) or ((h or strict) and not HASH_RE.match(h)):
            # rosbag2 accepts an empty hash (publishers from before Iron offer none)
            out.append(f"topic {name}: type_description_hash {h!r} is not RIHS01_<64 hex>")
        out += _qos_problems(str(name), tm.get("offered_qos_profiles"))
        count = t.get("message_count")
        if not _int(count):
            out.append(f"topic {name}: message_count {count!r} is not a non-negative integer")
        else:
            total += count
    if m.get("message_count") != total:
        out.append(f"message_count {m.get('message_count')!r} != sum over topics {total}")
    files = m.get("files")
    if isinstance(files, list) and files:
        if [f.get("path") for f in files if isinstance(f, Mapping)] != rel:
            out.append("files[].path does not match relative_file_paths")
        file_total = sum(int(f.get("message_count", 0)) for f in files if isinstance(f, Mapping))
        if file_total != total:
            out.append(f"files[].message_count sum {file_total} != {total}")
    if m.get("compression_mode", "") not in ("", "file", "message"):
        out.append(f"compression_mode {m.get('compression_mode')!r} is unknown")
    custom = m.get("custom_data")
    if custom is not None and not (
        isinstance(custom, Mapping) and all(isinstance(v, str) for v in custom.values())
    ):
        out.append("custom_data must map strings to strings")
    return out

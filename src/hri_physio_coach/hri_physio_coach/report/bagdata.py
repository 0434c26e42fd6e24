"""A session bag as tables: JSON event streams, numeric frame streams and the sim clock (no rclpy).

Messages come from the project's own reader (:class:`hri_physio_bridge.bag.reader.BagReader`,
which also reads a bag whose recorder was killed) and are deserialised with a ``rosbags``
typestore. Only what the report needs is decoded: ``std_msgs/String`` (JSON events, statuses,
speech), ``std_msgs/Float64MultiArray`` frames (physiology, see :mod:`hri_physio_bridge.frames`),
``/clock`` and the coach's ``/rosout`` lines.
"""

from __future__ import annotations

import json
import struct
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.reader import BagReader
from hri_physio_bridge.frames import FrameFormatError, decode_layout

STRING_TYPE = "std_msgs/msg/String"
ARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
LOG_TYPE = "rcl_interfaces/msg/Log"
CLOCK_TOPIC = "/clock"
ROSOUT_TOPIC = "/rosout"
#: Loggers whose /rosout lines are kept (the coach says which HR topic it listens to).
KEPT_LOGGERS = ("qt_physio_coach",)

_TYPESTORE = get_typestore(Stores.LATEST)


class ReportError(ValueError):
    """The input cannot give a report (not a bag, empty, no coach events): one line."""


@dataclass(frozen=True)
class JsonMessage:
    log_ns: int
    data: dict[str, Any]


@dataclass
class FrameStream:
    """Every sample of one numeric frame topic, with the receive time of its frame."""

    topic: str
    channels: tuple[str, ...]
    log_ns: np.ndarray  # int64, one per sample (the frame's receive time)
    source_t: np.ndarray  # float64, the sample's own timestamp (source clock)
    values: np.ndarray  # float64, samples x channels
    frames: int
    bad_frames: int = 0  # messages that did not have the frame layout

    @property
    def num_samples(self) -> int:
        return int(self.source_t.shape[0])

    def column(self, names: tuple[str, ...]) -> np.ndarray:
        """The first channel whose name is in ``names`` (case-insensitive), else the first channel."""
        lower = [c.lower() for c in self.channels]
        index = next((lower.index(n) for n in names if n in lower), 0)
        return self.values[:, index]


@dataclass
class BagTables:
    path: Path
    complete: bool
    warnings: list[str]
    topic_types: dict[str, str]
    message_counts: dict[str, int]
    custom_data: dict[str, str]
    start_ns: int | None
    end_ns: int | None
    json: dict[str, list[JsonMessage]] = field(default_factory=dict)
    text: dict[str, list[tuple[int, str]]] = field(default_factory=dict)  # non-JSON strings
    frames: dict[str, FrameStream] = field(default_factory=dict)
    clock: tuple[np.ndarray, np.ndarray] | None = None  # (receive ns, clock seconds)
    log_lines: list[tuple[int, str, str]] = field(default_factory=list)  # (ns, logger, text)
    undecodable: dict[str, int] = field(default_factory=dict)


class _FrameBuilder:
    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.channels: tuple[str, ...] | None = None
        self.log_ns: list[np.ndarray] = []
        self.source_t: list[np.ndarray] = []
        self.values: list[np.ndarray] = []
        self.frames = 0
        self.bad = 0

    def add(self, log_ns: int, msg: Any) -> None:
        try:
            dims = [(d.label, int(d.size), int(d.stride)) for d in msg.layout.dim]
            frame = decode_layout(dims, int(msg.layout.data_offset), msg.data)
        except FrameFormatError:
            self.bad += 1
            return
        if self.channels is None:
            self.channels = frame.channels
        elif frame.channels != self.channels:
            self.bad += 1  # a stream does not change its channels mid-session
            return
        self.frames += 1
        self.log_ns.append(np.full(frame.num_samples, log_ns, dtype=np.int64))
        self.source_t.append(frame.timestamps)
        self.values.append(frame.values.astype(np.float64))

    def build(self) -> FrameStream | None:
        if self.channels is None:
            return None
        width = len(self.channels)
        return FrameStream(
            self.topic, self.channels,
            np.concatenate(self.log_ns) if self.log_ns else np.empty(0, np.int64),
            np.concatenate(self.source_t) if self.source_t else np.empty(0),
            np.concatenate(self.values) if self.values else np.empty((0, width)),
            self.frames, self.bad,
        )


def read_bag(path: Path) -> BagTables:
    """Decode a bag's events, frames and clock; raises :class:`ReportError` on unreadable input."""
    try:
        reader = BagReader(path)
    except BagError as exc:
        raise ReportError(str(exc)) from None
    types = {name: info.type for name, info in reader.topics.items()}
    tables = BagTables(
        path=Path(path), complete=reader.complete, warnings=list(reader.warnings), topic_types=types,
        message_counts={name: info.message_count for name, info in reader.topics.items()},
        custom_data=dict(reader.custom_data), start_ns=reader.start_ns, end_ns=reader.end_ns,
    )
    if reader.message_count == 0:
        raise ReportError(f"{path} holds no messages: nothing to report")
    wanted = [t for t, ty in types.items() if ty in (STRING_TYPE, ARRAY_TYPE, CLOCK_TYPE)
              or (t == ROSOUT_TOPIC and ty == LOG_TYPE)]
    builders: dict[str, _FrameBuilder] = {}
    json_msgs: dict[str, list[JsonMessage]] = defaultdict(list)
    text_msgs: dict[str, list[tuple[int, str]]] = defaultdict(list)
    clock_ns: list[int] = []
    clock_s: list[float] = []
    undecodable: dict[str, int] = defaultdict(int)
    try:
        for m in reader.messages(wanted):
            if m.type == CLOCK_TYPE:
                t = _clock_seconds(m.data)
                if t is None:
                    undecodable[m.topic] += 1
                else:
                    clock_ns.append(m.log_time_ns)
                    clock_s.append(t)
                continue
            try:
                msg = _TYPESTORE.deserialize_cdr(m.data, m.type)
            except Exception:  # a damaged or foreign payload: count it, keep the rest
                undecodable[m.topic] += 1
                continue
            if m.type == STRING_TYPE:
                try:
                    data = json.loads(msg.data)
                except (json.JSONDecodeError, TypeError):
                    data = None
                if isinstance(data, dict):
                    json_msgs[m.topic].append(JsonMessage(m.log_time_ns, data))
                else:
                    text_msgs[m.topic].append((m.log_time_ns, str(msg.data)))
            elif m.type == ARRAY_TYPE:
                builders.setdefault(m.topic, _FrameBuilder(m.topic)).add(m.log_time_ns, msg)
            elif m.type == LOG_TYPE and msg.name.split(".")[-1] in KEPT_LOGGERS:
                tables.log_lines.append((m.log_time_ns, msg.name, msg.msg))
    except BagError as exc:
        tables.warnings.append(f"stopped reading: {exc}")
    for topic, builder in builders.items():
        stream = builder.build()
        if stream is not None:
            tables.frames[topic] = _sorted(stream)
    tables.json = {t: sorted(v, key=lambda j: j.log_ns) for t, v in json_msgs.items()}
    tables.text = {t: sorted(v) for t, v in text_msgs.items()}
    if len(clock_ns) >= 2:
        order = np.argsort(np.asarray(clock_ns, dtype=np.int64), kind="stable")
        tables.clock = (np.asarray(clock_ns, dtype=np.int64)[order], np.asarray(clock_s)[order])
    tables.undecodable = dict(undecodable)
    for topic, n in tables.undecodable.items():
        tables.warnings.append(f"{n} message(s) on {topic} could not be decoded and were skipped")
    return tables


def _clock_seconds(data: bytes) -> float | None:
    """``rosgraph_msgs/Clock`` (one ``builtin_interfaces/Time``) from its CDR bytes.

    Decoded by hand: a session bag holds one per sim step (10 per sim second), and the generic
    deserialiser would spend most of the reading time on them.
    """
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        return None
    sec, nanosec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return sec + nanosec * 1e-9


def _sorted(stream: FrameStream) -> FrameStream:
    """Samples in receive order (a summary-less file is read in file order)."""
    if stream.num_samples and np.any(np.diff(stream.log_ns) < 0):
        order = np.argsort(stream.log_ns, kind="stable")
        stream.log_ns, stream.source_t, stream.values = (
            stream.log_ns[order], stream.source_t[order], stream.values[order])
    return stream

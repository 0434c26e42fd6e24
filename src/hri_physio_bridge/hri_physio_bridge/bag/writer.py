"""A rosbag2 (MCAP storage) writer that keeps what it has recorded on disk while it runs.

Why not ``rosbags.rosbag2.Writer``: its MCAP storage keeps the open chunk in memory until it
holds 1 MiB, and chunk/message indexes, summary and ``metadata.yaml`` only at ``close()``.
A slow topic (a heart rate every second) may then sit in memory for hours, and a SIGKILL
loses it. This writer uses the ``mcap`` library's ``Writer`` (Foxglove's reference
implementation, zstd chunks with CRCs and message indexes) and closes the open chunk
itself when it is ``chunk_size`` bytes large *or* ``flush_period`` seconds old, writing it
through to the operating system (``flush``), and ``fsync``-ing at most every
``fsync_period`` seconds. Loss bounds on a crash:

* process killed (SIGKILL, segfault, OOM): at most the last ``flush_period`` seconds
  (+ the caller's tick period, see :meth:`BagWriter.tick`), since flushed chunks live in the
  kernel's page cache;
* machine loses power: at most the last ``max(flush_period, fsync_period)`` seconds.

The MCAP file follows rosbag2's MCAP plugin: profile ``ros2``, one ``ros2msg`` schema per
type, one ``cdr`` channel per topic with ``offered_qos_profiles`` and ``topic_type_hash``
channel metadata, and a ``rosbag2`` metadata record holding the bag's metadata; a clean
``close()`` adds the summary and ``metadata.yaml``. A bag whose writer died lacks both and
is recovered by :mod:`hri_physio_bridge.bag.recovery`.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from mcap.writer import CompressionType, Writer

from hri_physio_bridge.bag.errors import BagError, BagExistsError
from hri_physio_bridge.bag.metadata import BagInfo, TopicInfo, write_metadata

#: MCAP metadata record written at the start: the session's custom data survives a crash.
SESSION_RECORD = "hri_physio_session"
DEFAULT_CHUNK_SIZE = 768 * 1024  # rosbag2's MCAP default
DEFAULT_FLUSH_PERIOD = 1.0
DEFAULT_FSYNC_PERIOD = 5.0
#: Bytes an MCAP message record adds to its payload (opcode, length, channel, seq, 2 times).
MESSAGE_OVERHEAD = 1 + 8 + 2 + 4 + 8 + 8 + 4


def _library() -> str:
    try:
        return f"hri_physio_bridge recorder; mcap-python {version('mcap')}"
    except PackageNotFoundError:  # pragma: no cover - mcap is a dependency
        return "hri_physio_bridge recorder"


def qos_yaml(profiles: list[dict[str, Any]]) -> str:
    """Offered QoS profiles as the YAML string rosbag2 puts in MCAP channel metadata."""
    return yaml.safe_dump(profiles, sort_keys=False, default_flow_style=False) if profiles else ""


@dataclass
class TopicStats:
    info: TopicInfo
    channel_id: int
    bytes: int = 0


@dataclass
class WriterStats:
    messages: int = 0
    bytes: int = 0  # message payload bytes
    chunks_flushed: int = 0
    fsyncs: int = 0
    file_bytes: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    per_topic: dict[str, int] = field(default_factory=dict)


class BagWriter:
    """Write one rosbag2 directory ``bag_dir`` holding ``<name>_0.mcap``.

    Thread-safe: messages may come from executor threads while a timer calls :meth:`tick`.
    """

    def __init__(
        self,
        bag_dir: Path | str,
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        flush_period: float = DEFAULT_FLUSH_PERIOD,
        fsync_period: float | None = DEFAULT_FSYNC_PERIOD,
        compression: str = "zstd",
        custom_data: dict[str, str] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        if chunk_size < 1024:
            raise BagError(f"chunk size must be at least 1024 bytes, got {chunk_size}")
        if flush_period <= 0:
            raise BagError(f"flush period must be positive, got {flush_period}")
        if compression not in ("zstd", "none"):
            raise BagError(f"compression must be 'zstd' or 'none', got {compression!r}")
        self.bag_dir = Path(bag_dir)
        self.file_name = f"{self.bag_dir.name}_0.mcap"
        self.path = self.bag_dir / self.file_name
        self.chunk_size = chunk_size
        self.flush_period = flush_period
        self.fsync_period = fsync_period
        self.custom_data = dict(custom_data or {})
        self._monotonic = monotonic
        self._lock = threading.Lock()
        self._topics: dict[str, TopicStats] = {}
        self._schemas: dict[str, int] = {}
        self.stats = WriterStats()
        try:
            self.bag_dir.mkdir(parents=True, exist_ok=False)
        except FileExistsError:
            raise BagExistsError(f"{self.bag_dir} exists already; a recording is never overwritten") from None
        except OSError as exc:
            raise BagError(f"cannot create bag directory {self.bag_dir}: {exc.strerror}") from None
        self._file: BinaryIO | None = self.path.open("xb")
        self._mcap = Writer(
            self._file,
            chunk_size=2**62,  # chunks are closed here (size or age), never inside mcap
            compression=CompressionType.ZSTD if compression == "zstd" else CompressionType.NONE,
        )
        self._mcap.start(profile="ros2", library=_library())
        if self.custom_data:
            self._mcap.add_metadata(SESSION_RECORD, dict(self.custom_data))
        self._pending_bytes = 0  # uncompressed bytes in the open chunk
        self._chunk_opened: float | None = None  # monotonic time of the open chunk's first message
        self._last_fsync = monotonic()
        self._dirty_since_fsync = False
        self._closed = False
        self._flush_locked(force_fsync=True)  # header on disk: the bag is recognisable at once

    # -- topics --------------------------------------------------------------
    @property
    def topics(self) -> dict[str, TopicInfo]:
        with self._lock:
            return {name: ts.info for name, ts in self._topics.items()}

    def add_topic(
        self,
        name: str,
        type_name: str,
        definition: str,
        type_hash: str,
        offered_qos_profiles: list[dict[str, Any]],
    ) -> int:
        """Register ``name``; returns the channel id to pass to :meth:`write`."""
        with self._lock:
            self._check_open()
            if name in self._topics:
                raise BagError(f"topic {name} is already recorded")
            schema_id = self._schemas.get(type_name)
            if schema_id is None:
                schema_id = self._mcap.register_schema(
                    name=type_name, encoding="ros2msg", data=definition.encode("utf-8")
                )
                self._schemas[type_name] = schema_id
            channel_id = self._mcap.register_channel(
                topic=name,
                message_encoding="cdr",
                schema_id=schema_id,
                metadata={
                    "offered_qos_profiles": qos_yaml(offered_qos_profiles),
                    "topic_type_hash": type_hash,
                },
            )
            info = TopicInfo(name, type_name, list(offered_qos_profiles), type_hash)
            self._topics[name] = TopicStats(info, channel_id)
            self.stats.per_topic[name] = 0
            return channel_id

    # -- messages ------------------------------------------------------------
    def write(
        self, topic: str, log_time_ns: int, data: bytes, publish_time_ns: int = 0, sequence: int = 0
    ) -> None:
        """Append one serialized (CDR) message received at ``log_time_ns``."""
        with self._lock:
            self._check_open()
            ts = self._topics.get(topic)
            if ts is None:
                raise BagError(f"topic {topic} was not added to the bag")
            self._mcap.add_message(
                channel_id=ts.channel_id,
                log_time=log_time_ns,
                data=data,
                publish_time=publish_time_ns or log_time_ns,
                sequence=sequence & 0xFFFFFFFF,
            )
            size = len(data)
            ts.info.message_count += 1
            ts.bytes += size
            st = self.stats
            st.messages += 1
            st.bytes += size
            st.per_topic[topic] += 1
            if st.first_ns is None or log_time_ns < st.first_ns:
                st.first_ns = log_time_ns
            if st.last_ns is None or log_time_ns > st.last_ns:
                st.last_ns = log_time_ns
            self._pending_bytes += size + MESSAGE_OVERHEAD
            now = self._monotonic()
            if self._chunk_opened is None:
                self._chunk_opened = now
            if self._pending_bytes >= self.chunk_size or now - self._chunk_opened >= self.flush_period:
                self._flush_locked()

    def tick(self) -> None:
        """Call periodically (every ``flush_period / 4`` or so): closes a chunk that got old
        while no message arrived, and fsyncs when due. Bounds the loss on a crash."""
        with self._lock:
            if self._closed:
                return
            now = self._monotonic()
            if self._chunk_opened is not None and now - self._chunk_opened >= self.flush_period:
                self._flush_locked()
            elif self._due_fsync(now):
                self._fsync_locked(now)

    def flush(self, fsync: bool = True) -> None:
        """Close the open chunk now and write it through (and fsync it)."""
        with self._lock:
            self._check_open()
            self._flush_locked(force_fsync=fsync)

    def _due_fsync(self, now: float) -> bool:
        return (
            self.fsync_period is not None
            and self._dirty_since_fsync
            and now - self._last_fsync >= self.fsync_period
        )

    def _flush_locked(self, force_fsync: bool = False) -> None:
        assert self._file is not None
        if self._chunk_opened is not None:
            self.stats.chunks_flushed += 1
        self._mcap.flush()  # closes the open chunk (if it holds messages) and flushes the stream
        self._pending_bytes = 0
        self._chunk_opened = None
        self._dirty_since_fsync = True
        self.stats.file_bytes = self._file.tell()
        now = self._monotonic()
        if force_fsync or self._due_fsync(now):
            self._fsync_locked(now)

    def _fsync_locked(self, now: float) -> None:
        assert self._file is not None
        self._file.flush()
        os.fsync(self._file.fileno())
        self._last_fsync = now
        self._dirty_since_fsync = False
        self.stats.fsyncs += 1

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f"bag {self.bag_dir} is closed")

    # -- close ---------------------------------------------------------------
    def info(self) -> BagInfo:
        with self._lock:
            return self._info_locked()

    def _info_locked(self) -> BagInfo:
        st = self.stats
        start = st.first_ns or 0
        duration = (st.last_ns - st.first_ns) if st.first_ns is not None and st.last_ns is not None else 0
        return BagInfo(
            relative_file=self.file_name,
            topics=[ts.info for ts in self._topics.values()],
            starting_time_ns=start,
            duration_ns=duration,
            custom_data=self.custom_data,
        )

    def close(self) -> BagInfo:
        """Write the summary and ``metadata.yaml``; the bag is then complete."""
        with self._lock:
            self._check_open()
            assert self._file is not None
            info = self._info_locked()
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": info.to_yaml(root=False)})
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self.stats.file_bytes = self._file.tell()
            self._file.close()
            self._file = None
            self._closed = True
        write_metadata(self.bag_dir, info)
        return info

    def abort(self) -> None:
        """Stop without a summary (what a crash leaves, minus the unflushed tail)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            file, self._file = self._file, None
            if file is not None:
                # A disk that refuses the buffered tail leaves what a crash leaves; the caller said why.
                with contextlib.suppress(OSError):
                    file.close()

    @property
    def closed(self) -> bool:
        return self._closed

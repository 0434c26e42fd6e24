"""Open a rosbag2 directory (MCAP storage) or a bare ``.mcap`` file for playback.

Complete files are read through their summary (chunk indexes, log-time order). A file
whose writer died (no summary) is read with the damage-tolerant scanner of
:mod:`~hri_physio_bridge.bag.recovery`, in file order, with a warning (naming the first
damaged or cut-short record, if any). A bag with damaged records and not one readable
message is refused as corrupt or truncated, which a valid bag without messages is not.
Every problem becomes a one-line :class:`~hri_physio_bridge.bag.errors.BagError`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Schema

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.integrity import DamagedChunk, check_chunks, open_file
from hri_physio_bridge.bag.metadata import LOST_KEY, METADATA_FILE, TopicInfo, load_metadata
from hri_physio_bridge.bag.recovery import McapScanner, topic_info_from_channel


@dataclass(frozen=True)
class BagMessage:
    topic: str
    type: str
    log_time_ns: int
    data: bytes


@dataclass
class _File:
    path: Path
    complete: bool
    channels: dict[int, Channel] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    start_ns: int | None = None
    end_ns: int | None = None
    damage: str = ""  # incomplete files: the first damaged or cut-short record ("" if none)
    damaged: list[DamagedChunk] | None = None  # None: not checked yet (complete files)
    unreadable: int = 0  # messages in damaged chunks (complete files: exact, from the summary)


def _summary(path: Path) -> _File:
    """Read a file's summary; a missing/unreadable summary marks the file incomplete."""
    with open_file(path) as fh:
        try:
            reader = SeekingReader(fh)
        except (McapError, ValueError, EOFError) as exc:
            size = path.stat().st_size
            why = str(exc).strip() or type(exc).__name__
            raise BagError(f"{path} is not an MCAP file ({'empty: 0 bytes' if size == 0 else why})") from None
        try:
            summary = reader.get_summary()
        except Exception:
            summary = None
    if summary is None or summary.statistics is None:
        return _scan(path)
    st = summary.statistics
    return _File(
        path,
        True,
        dict(summary.channels),
        dict(summary.schemas),
        dict(st.channel_message_counts),
        st.message_start_time if st.message_count else None,
        st.message_end_time if st.message_count else None,
    )


def _scan(path: Path) -> _File:
    scanner = McapScanner(path)
    counts: dict[int, int] = {}
    for channel, _schema, _msg in scanner.messages():
        counts[channel.id] = counts.get(channel.id, 0) + 1
    rep = scanner.report
    return _File(
        path, False, scanner.channels, scanner.schemas, counts, rep.first_ns, rep.last_ns, rep.damage,
        list(rep.damaged_chunks), sum(c.messages or 0 for c in rep.damaged_chunks),
    )


class BagReader:
    """Topics, time range and messages of a bag."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.topics: dict[str, TopicInfo] = {}
        self.custom_data: dict[str, str] = {}  # metadata.yaml's (session id, lost messages...)
        if not self.path.exists():
            raise BagError(f"{self.path} does not exist")
        metadata = None
        if self.path.is_dir():
            if (self.path / METADATA_FILE).exists():
                metadata = load_metadata(self.path)
                paths = [self.path / p for p in metadata["relative_file_paths"]]
                self.custom_data = {str(k): str(v) for k, v in (metadata.get("custom_data") or {}).items()}
            else:
                paths = sorted(self.path.glob("*.mcap"))
                if not paths:
                    raise BagError(
                        f"{self.path} is not a rosbag2 directory (no {METADATA_FILE}, no .mcap file)"
                    )
                self.warnings.append(
                    f"{self.path} has no {METADATA_FILE}: its recorder did not finish; reading what "
                    f"was flushed (run 'recorder --repair {self.path}' to fix the bag for good)"
                )
        elif self.path.suffix == ".mcap":
            paths = [self.path]
        else:
            raise BagError(f"{self.path} is neither a rosbag2 directory nor an .mcap file")
        self._files = [_summary(p) for p in paths]
        damaged = [f for f in self._files if f.damage]
        if damaged and not any(sum(f.counts.values()) for f in self._files):
            f = damaged[0]
            raise BagError(
                f"{f.path} is corrupt or truncated: {f.damage}; not one message could be read from it"
            )
        for f in self._files:
            if not f.complete and (metadata is not None or self.path.is_file()):
                self.warnings.append(
                    f"{f.path.name} has no summary (writer did not finish); reading what was flushed"
                )
            if f.damage:
                self.warnings.append(
                    f"{f.path.name} is truncated or damaged: {f.damage}; reading the "
                    f"{sum(f.counts.values())} message(s) that are intact"
                )
        self._collect_topics(metadata)
        if LOST_KEY in self.custom_data:
            self.warnings.append(
                f"the recorder missed messages while recording this bag ({self.custom_data[LOST_KEY]})"
            )

    def _collect_topics(self, metadata: dict | None) -> None:
        from_meta: dict[str, TopicInfo] = {}
        if metadata is not None:
            for entry in metadata["topics_with_message_count"]:
                tm = entry["topic_metadata"]
                from_meta[tm["name"]] = TopicInfo(
                    tm["name"],
                    tm["type"],
                    list(tm.get("offered_qos_profiles") or []),
                    tm.get("type_description_hash", ""),
                    tm.get("serialization_format", "cdr"),
                    0,
                )
        for f in self._files:
            for cid, channel in f.channels.items():
                info = self.topics.get(channel.topic)
                if info is None:
                    info = from_meta.get(channel.topic) or topic_info_from_channel(
                        channel, f.schemas.get(channel.schema_id)
                    )
                    info.message_count = 0
                    self.topics[channel.topic] = info
                info.message_count += f.counts.get(cid, 0)
        for name, info in self.topics.items():
            if info.serialization_format != "cdr":
                raise BagError(
                    f"topic {name} is stored as {info.serialization_format!r}, only 'cdr' can be played"
                )

    @property
    def complete(self) -> bool:
        """Every file has its summary (its writer finished); says nothing about damage inside."""
        return all(f.complete for f in self._files)

    def damaged_chunks(self) -> list[tuple[Path, DamagedChunk]]:
        """Every chunk that fails its CRC or cannot be decompressed, by file.

        Reads every chunk of a complete file once (a scan of an incomplete one did so already).
        """
        out: list[tuple[Path, DamagedChunk]] = []
        for f in self._files:
            if f.damaged is None:
                check = check_chunks(f.path)
                f.damaged, f.unreadable = check.damaged, check.unreadable_messages
            out.extend((f.path, chunk) for chunk in f.damaged)
        return out

    @property
    def unreadable_messages(self) -> int:
        """Messages lost in damaged chunks (after :meth:`damaged_chunks`; at least, for scanned files)."""
        self.damaged_chunks()
        return sum(f.unreadable for f in self._files)

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())

    @property
    def start_ns(self) -> int | None:
        starts = [f.start_ns for f in self._files if f.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_ns(self) -> int | None:
        ends = [f.end_ns for f in self._files if f.end_ns is not None]
        return max(ends) if ends else None

    def messages(
        self, topics: Iterable[str] | None = None, start_ns: int | None = None
    ) -> Iterator[BagMessage]:
        """Messages of ``topics`` (all if ``None``) at or after ``start_ns``, in time order."""
        wanted = None if topics is None else set(topics)
        for f in self._files:
            try:
                yield from self._file_messages(f, wanted, start_ns)
            except BagError:
                raise
            except Exception as exc:
                raise BagError(f"{f.path} is damaged: {exc}; try 'recorder --repair'") from None

    def _file_messages(self, f: _File, wanted: set[str] | None, start_ns: int | None) -> Iterator[BagMessage]:
        if f.complete:
            with f.path.open("rb") as fh:
                reader = SeekingReader(fh, validate_crcs=True)
                names = None if wanted is None else sorted(wanted)
                for schema, channel, msg in reader.iter_messages(topics=names, starting_at=start_ns):
                    yield BagMessage(channel.topic, schema.name if schema else "", msg.log_time, msg.data)
            return
        for channel, schema, msg in McapScanner(f.path).messages():
            if wanted is not None and channel.topic not in wanted:
                continue
            if start_ns is not None and msg.log_time < start_ns:
                continue
            yield BagMessage(channel.topic, schema.name if schema else "", msg.log_time, msg.data)

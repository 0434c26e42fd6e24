"""Read and repair an MCAP bag whose writer died (no summary, no ``metadata.yaml``).

The scanner walks the file record by record from the start. A record is used only if its
full length lies inside the file, so a chunk cut short by the crash ends the scan cleanly;
a chunk that is complete but damaged (CRC or decompression error) is skipped and counted,
and the scan goes on with the next record. Everything before the damage is recovered:
with :class:`~hri_physio_bridge.bag.writer.BagWriter` that is all but the last
``flush_period`` seconds.

:func:`repair_bag` rewrites the recovered messages into a complete MCAP file (summary,
indexes, ``rosbag2`` metadata record) and writes ``metadata.yaml`` from the channels'
``offered_qos_profiles``/``topic_type_hash`` metadata, so ``ros2 bag info``/``play`` and
every MCAP reader accept it again. The damaged original is kept as ``*.mcap.damaged``
unless asked otherwise.
"""

from __future__ import annotations

import dataclasses
import io
import os
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, MessageIndex, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.integrity import DamagedChunk, known_chunk_offsets
from hri_physio_bridge.bag.metadata import METADATA_FILE, BagInfo, TopicInfo, write_metadata
from hri_physio_bridge.bag.msgdefs import installed_type_hash
from hri_physio_bridge.bag.writer import SESSION_RECORD

MAGIC = b"\x89MCAP0\r\n"


@dataclass
class ScanReport:
    path: Path
    file_bytes: int = 0
    valid_bytes: int = 0  # offset just past the last record that could be used
    complete: bool = False  # footer reached: the writer finished
    messages: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    corrupt_chunks: int = 0
    problem: str = ""  # why the scan stopped before a footer
    first_ns: int | None = None
    last_ns: int | None = None
    # The first damaged or cut-short record ("" / None if none; a file that merely ends
    # without a footer, as a killed writer's does between chunks, is not damaged).
    damage: str = ""
    damage_offset: int | None = None
    #: Every complete but unreadable chunk, with the messages its message index says it held.
    damaged_chunks: list[DamagedChunk] = field(default_factory=list)
    skipped_bytes: int = 0  # broken records skipped mid-file (to a chunk the summary knows of)

    @property
    def lost_bytes(self) -> int:
        return self.file_bytes - self.valid_bytes

    def note_damage(self, offset: int, what: str) -> None:
        """Remember the first damaged record (later ones add nothing a user can act on)."""
        if self.damage_offset is None:
            self.damage_offset, self.damage = offset, what


class McapScanner:
    """Sequential, damage-tolerant reader of one MCAP file.

    ``resume_offsets`` (where chunks start, from an intact summary) let the scan carry on after
    a stretch of broken records instead of ending there.
    """

    def __init__(self, path: Path | str, resume_offsets: Iterable[int] = ()) -> None:
        self.path = Path(path)
        self.resume_offsets = sorted(resume_offsets)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: list[Metadata] = []
        self.report = ScanReport(self.path)

    def messages(self) -> Iterator[tuple[Channel, Schema | None, Message]]:
        """Every recoverable message in file order; :attr:`report` is final when exhausted."""
        try:
            fh = self.path.open("rb")
        except OSError as exc:
            raise BagError(f"cannot open {self.path}: {exc.strerror}") from None
        with fh:
            size = os.fstat(fh.fileno()).st_size
            self.report.file_bytes = size
            if fh.read(len(MAGIC)) != MAGIC:
                raise BagError(f"{self.path} is not an MCAP file (bad magic bytes)")
            self.report.valid_bytes = offset = len(MAGIC)
            yield from self._records(fh, offset, size)

    def _records(
        self, fh: BinaryIO, offset: int, size: int
    ) -> Iterator[tuple[Channel, Schema | None, Message]]:
        rep = self.report
        after_damaged = False  # the records just read are a damaged chunk and its message indexes
        while True:
            head = fh.read(9)
            if len(head) == 0:
                rep.problem = rep.problem or "file ends without a footer (writer did not finish)"
                return
            if len(head) < 9:
                rep.problem = f"truncated record header at byte {offset}"
                rep.note_damage(offset, rep.problem)
                return
            opcode, length = struct.unpack("<BQ", head)
            if offset + 9 + length > size:
                what = (f"{_opname(opcode)} record at byte {offset} is cut short "
                        f"({size - offset - 9} of {length} bytes)")
                resumed = self._resume(fh, offset, what)
                if resumed is None:
                    return
                offset, after_damaged = resumed, False
                continue
            body = fh.read(length)
            start, offset = offset, offset + 9 + length
            if opcode == Opcode.MESSAGE_INDEX:
                self._count_damaged(body, after_damaged)
            after_damaged = after_damaged and opcode == Opcode.MESSAGE_INDEX
            try:
                records = self._parse(opcode, body)
            except Exception as exc:
                if opcode == Opcode.CHUNK:
                    rep.corrupt_chunks += 1
                    rep.note_damage(start, f"damaged chunk record at byte {start}: {exc}")
                    rep.damaged_chunks.append(_damaged_chunk(start, body, exc))
                    after_damaged = True  # its message index records follow it
                    rep.valid_bytes = offset
                    continue
                resumed = self._resume(fh, start, f"damaged {_opname(opcode)} record at byte {start}: {exc}")
                if resumed is None:
                    return
                offset = resumed
                continue
            rep.valid_bytes = offset
            for rec in records:
                if isinstance(rec, Schema):
                    self.schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    self.channels[rec.id] = rec
                    rep.per_topic.setdefault(rec.topic, 0)
                elif isinstance(rec, Metadata):
                    self.metadata.append(rec)
                elif isinstance(rec, Message):
                    channel = self.channels.get(rec.channel_id)
                    if channel is None:
                        continue  # its channel record was lost with a damaged chunk
                    rep.messages += 1
                    rep.per_topic[channel.topic] += 1
                    if rep.first_ns is None or rec.log_time < rep.first_ns:
                        rep.first_ns = rec.log_time
                    if rep.last_ns is None or rec.log_time > rep.last_ns:
                        rep.last_ns = rec.log_time
                    yield channel, self.schemas.get(channel.schema_id), rec
            if opcode == Opcode.FOOTER:
                rep.complete = True
                rep.problem = ""
                return
            if opcode == Opcode.DATA_END:
                # The summary section follows; its records repeat what the data section held.
                rep.complete = True
                return

    def _resume(self, fh: BinaryIO, at: int, what: str) -> int | None:
        """After a broken record at ``at``: the next chunk the summary knows of (seeked to), or
        None (the scan ends there, ``what`` is the problem)."""
        rep = self.report
        rep.note_damage(at, what)
        nxt = next((o for o in self.resume_offsets if o > at), None)
        if nxt is None:
            rep.problem = what
            return None
        rep.skipped_bytes += nxt - at
        fh.seek(nxt)
        return nxt

    def _count_damaged(self, body: bytes, after_damaged: bool) -> None:
        """Add a message index record's entries to the damaged chunk it follows."""
        if not after_damaged:
            return
        try:
            n = len(MessageIndex.read(ReadDataStream(io.BytesIO(body))).records)
        except Exception:
            return
        last = self.report.damaged_chunks[-1]
        self.report.damaged_chunks[-1] = dataclasses.replace(last, messages=(last.messages or 0) + n)

    @staticmethod
    def _parse(opcode: int, body: bytes) -> list[Any]:
        stream = ReadDataStream(io.BytesIO(body))
        if opcode == Opcode.CHUNK:
            return breakup_chunk(Chunk.read(stream), validate_crc=True)
        if opcode == Opcode.SCHEMA:
            return [Schema.read(stream)]
        if opcode == Opcode.CHANNEL:
            return [Channel.read(stream)]
        if opcode == Opcode.MESSAGE:
            return [Message.read(stream, len(body))]
        if opcode == Opcode.METADATA:
            return [Metadata.read(stream)]
        return []


def _damaged_chunk(offset: int, body: bytes, exc: Exception) -> DamagedChunk:
    """A damaged chunk, with its time span if its header can still be read."""
    start_ns = end_ns = None
    try:
        head = Chunk.read(ReadDataStream(io.BytesIO(body)))
        start_ns, end_ns = head.message_start_time, head.message_end_time
    except Exception:
        pass
    return DamagedChunk(offset, start_ns, end_ns, None, str(exc) or type(exc).__name__)


def _opname(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower()
    except ValueError:
        return f"opcode {opcode:#x}"


def topic_info_from_channel(channel: Channel, schema: Schema | None) -> TopicInfo:
    """A topic's metadata as stored in its MCAP channel (rosbag2's conventions)."""
    type_name = schema.name if schema is not None else ""
    qos_text = channel.metadata.get("offered_qos_profiles", "")
    try:
        qos = yaml.safe_load(qos_text) if qos_text else []
    except yaml.YAMLError:
        qos = []
    if not isinstance(qos, list):
        qos = []
    type_hash = channel.metadata.get("topic_type_hash") or ""
    if not type_hash and type_name:
        type_hash = installed_type_hash(type_name) or ""
    return TopicInfo(channel.topic, type_name, qos, type_hash, channel.message_encoding or "cdr")


def find_mcap(path: Path) -> Path:
    """The single MCAP file of a bag directory (or ``path`` itself if it is a file)."""
    if path.is_file():
        return path
    if not path.is_dir():
        raise BagError(f"{path} does not exist")
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise BagError(f"{path} holds no .mcap file")
    if len(files) > 1:
        raise BagError(f"{path} holds {len(files)} .mcap files; repair them one by one")
    return files[0]


@dataclass
class RepairReport:
    scan: ScanReport
    bag_dir: Path
    mcap: Path
    backup: Path | None
    info: BagInfo


def repair_bag(path: Path | str, keep_damaged: bool = True) -> RepairReport:
    """Make the bag at ``path`` (directory or ``.mcap``) complete again, in place."""
    path = Path(path)
    mcap_path = find_mcap(path)
    bag_dir = mcap_path.parent
    tmp = mcap_path.with_suffix(".mcap.repairing")
    scanner = McapScanner(mcap_path, known_chunk_offsets(mcap_path))
    topics: dict[int, TopicInfo] = {}
    new_ids: dict[int, int] = {}
    schema_ids: dict[str, int] = {}
    try:
        out = tmp.open("xb")
    except FileExistsError:
        raise BagError(f"{tmp} exists: another repair is running or was interrupted; remove it") from None
    try:
        with out:
            writer = Writer(out, compression=CompressionType.ZSTD)
            writer.start(profile="ros2", library="hri_physio_bridge recovery")
            for channel, schema, msg in scanner.messages():
                if channel.id not in new_ids:
                    sname = schema.name if schema else ""
                    if sname not in schema_ids:
                        schema_ids[sname] = (
                            writer.register_schema(
                                sname, schema.encoding if schema else "", schema.data if schema else b""
                            )
                            if schema
                            else 0
                        )
                    new_ids[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding, schema_ids[sname], dict(channel.metadata)
                    )
                    topics[channel.id] = topic_info_from_channel(channel, schema)
                topics[channel.id].message_count += 1
                writer.add_message(
                    new_ids[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence
                )
            rep = scanner.report
            info = BagInfo(
                relative_file=mcap_path.name,
                topics=list(topics.values()),
                starting_time_ns=rep.first_ns or 0,
                duration_ns=(rep.last_ns - rep.first_ns)
                if rep.first_ns is not None and rep.last_ns is not None
                else 0,
                custom_data=_custom_data(scanner.metadata),
            )
            writer.add_metadata("rosbag2", {"serialized_metadata": info.to_yaml(root=False)})
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    backup: Path | None = None
    if keep_damaged:
        backup = mcap_path.with_suffix(".mcap.damaged")
        if backup.exists():
            raise BagError(f"{backup} exists already; move it away before repairing again")
        os.link(mcap_path, backup)
    tmp.replace(mcap_path)
    if path.is_dir() or (bag_dir / METADATA_FILE).exists():
        write_metadata(bag_dir, info)  # a bare .mcap elsewhere describes itself (summary)
    return RepairReport(scanner.report, bag_dir, mcap_path, backup, info)


def _custom_data(records: list[Metadata]) -> dict[str, str]:
    """The bag's custom data: from the final ``rosbag2`` record if the writer got that far,
    else from the session record the writer puts at the start of the file."""
    custom: dict[str, str] = {}
    for rec in records:
        if rec.name == SESSION_RECORD:
            custom = dict(rec.metadata)
        elif rec.name == "rosbag2" and "serialized_metadata" in rec.metadata:
            try:
                doc = yaml.safe_load(rec.metadata["serialized_metadata"])
            except yaml.YAMLError:
                continue
            found = doc.get("custom_data") if isinstance(doc, dict) else None
            if isinstance(found, dict):
                custom = {str(k): str(v) for k, v in found.items()}
    custom["repaired"] = "true"
    return custom

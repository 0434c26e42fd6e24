"""Check every chunk of a complete MCAP file against its CRC, and say what damage costs.

A complete file is read through its summary, which never looks inside the chunks: a file
with bytes flipped in the middle reads as complete until playback reaches the damaged
chunk and stops there. :func:`check_chunks` reads each chunk the summary indexes,
decompresses it and checks its ``uncompressed_crc`` (MCAP stores one per chunk); for each
damaged chunk it says where it is, which time span it covers and how many messages it
holds (from the message index records that follow it, which lie outside the chunk).
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Chunk, ChunkIndex, Message, MessageIndex
from mcap.stream_reader import breakup_chunk

from hri_physio_bridge.bag.errors import BagError

_HEADER = struct.Struct("<BQ")  # record opcode and body length


@dataclass(frozen=True)
class DamagedChunk:
    """One chunk that cannot be read back as written."""

    offset: int  # byte offset of the chunk record in its file
    start_ns: int | None  # log time of its first and last message (None: unknown)
    end_ns: int | None
    messages: int | None  # messages it holds (None: its message index is damaged too)
    problem: str

    def describe(self) -> str:
        held = "an unknown number of" if self.messages is None else str(self.messages)
        span = ""
        if self.start_ns is not None and self.end_ns is not None:
            span = f", log time {self.start_ns} .. {self.end_ns} ns"
        return f"chunk at byte {self.offset}{span}: {held} message(s) unreadable ({self.problem})"


def _record(fh: BinaryIO, offset: int, opcode: int) -> bytes:
    """The body of the record of type ``opcode`` at ``offset``; BagError if something else is there."""
    fh.seek(offset)
    head = fh.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise BagError("the file ends before the record")
    found, length = _HEADER.unpack(head)
    if found != opcode:
        raise BagError(f"found a {_opname(found)} record instead of a {_opname(opcode)} record")
    body = fh.read(length)
    if len(body) < length:
        raise BagError(f"the record is cut short ({len(body)} of {length} bytes)")
    return body


def _opname(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower()
    except ValueError:
        return f"opcode {opcode:#x}"


def _read_chunk(fh: BinaryIO, index: ChunkIndex) -> tuple[str, int]:
    """Why the indexed chunk cannot be read ("" if it can: CRC, decompression, record framing),
    and how many messages it holds when it can."""
    try:
        body = _record(fh, index.chunk_start_offset, Opcode.CHUNK)
        if len(body) + _HEADER.size != index.chunk_length:
            return f"its length is {len(body) + _HEADER.size} bytes, the index says {index.chunk_length}", 0
        records = breakup_chunk(Chunk.read(ReadDataStream(io.BytesIO(body))), validate_crc=True)
    except Exception as exc:  # CRC mismatch, zstd/lz4 errors, broken records inside the chunk
        return str(exc) or type(exc).__name__, 0
    return "", sum(isinstance(r, Message) for r in records)


def indexed_messages(fh: BinaryIO, index: ChunkIndex) -> int | None:
    """How many messages the chunk holds, from its message index records (None if unreadable)."""
    total = 0
    for offset in index.message_index_offsets.values():
        try:
            body = _record(fh, offset, Opcode.MESSAGE_INDEX)
            total += len(MessageIndex.read(ReadDataStream(io.BytesIO(body))).records)
        except Exception:
            return None
    return total


@dataclass(frozen=True)
class ChunkCheck:
    """The result of checking every chunk of one complete file."""

    damaged: list[DamagedChunk]
    #: Messages the summary counts minus those in intact chunks: exact even when a damaged
    #: chunk's own message index is damaged too.
    unreadable_messages: int


def open_file(path: Path) -> BinaryIO:
    """``path`` opened for reading; BagError naming the file and why it cannot be opened."""
    try:
        return path.open("rb")
    except OSError as exc:
        raise BagError(f"cannot open {path}: {exc.strerror}") from None


def check_chunks(path: Path) -> ChunkCheck:
    """Every chunk of the complete file ``path`` whose contents do not match its CRC, in file order."""
    with open_file(path) as fh:
        try:
            summary = SeekingReader(fh).get_summary()
        except Exception as exc:
            raise BagError(f"{path}: its summary cannot be read ({exc})") from None
        if summary is None:
            raise BagError(f"{path} has no summary: scan it instead")
        damaged: list[DamagedChunk] = []
        readable = 0
        for index in sorted(summary.chunk_indexes, key=lambda i: i.chunk_start_offset):
            problem, messages = _read_chunk(fh, index)
            if problem:
                damaged.append(DamagedChunk(index.chunk_start_offset, index.message_start_time,
                                            index.message_end_time, indexed_messages(fh, index), problem))
            else:
                readable += messages
        total = summary.statistics.message_count if summary.statistics is not None else readable
        unreadable = max(0, total - readable) if damaged else 0
        unknown = [i for i, c in enumerate(damaged) if c.messages is None]
        if len(unknown) == 1:  # the one chunk whose index is lost holds what is not accounted for
            known = sum(c.messages or 0 for c in damaged)
            i = unknown[0]
            damaged[i] = DamagedChunk(damaged[i].offset, damaged[i].start_ns, damaged[i].end_ns,
                                      max(0, unreadable - known), damaged[i].problem)
        return ChunkCheck(damaged, unreadable)


def known_chunk_offsets(path: Path) -> list[int]:
    """Where the summary says the chunks start ([] without a readable summary): lets a scan
    carry on after a damaged stretch of the file instead of stopping there."""
    try:
        with path.open("rb") as fh:
            summary = SeekingReader(fh).get_summary()
    except Exception:
        return []
    return sorted(i.chunk_start_offset for i in summary.chunk_indexes) if summary is not None else []

"""Reading and repairing bags whose writer died: every truncation point, damaged chunks."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from std_msgs.msg import String

from helpers.bags import check_bag, default_qos, read_with_rosbags, serialize
from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition
from hri_physio_bridge.bag.reader import BagReader
from hri_physio_bridge.bag.recovery import McapScanner, repair_bag
from hri_physio_bridge.bag.writer import BagWriter

T0 = 1_700_000_000_000_000_000
TN = "std_msgs/msg/String"


def _killed_bag(path: Path, n: int = 60, per_chunk: int = 10) -> BagWriter:
    """A bag whose writer flushed a chunk every ``per_chunk`` messages and then 'died'."""
    writer = BagWriter(path, fsync_period=None, custom_data={"session_id": "P007"})
    writer.add_topic("/count", TN, message_definition(TN), installed_type_hash(TN) or "", [default_qos()])
    for i in range(n):
        writer.write("/count", T0 + i * 1_000_000, serialize(String(data=str(i))))
        if (i + 1) % per_chunk == 0:
            writer.flush(fsync=False)
    writer.abort()
    return writer


def _values(path: Path) -> list[int]:
    from rclpy.serialization import deserialize_message

    return [int(deserialize_message(m.data, String).data) for _c, _s, m in McapScanner(path).messages()]


def test_every_truncation_point_recovers_a_prefix(tmp_path: Path) -> None:
    """Cut the file at every 7th byte: the scan never fails, and yields whole chunks in order."""
    writer = _killed_bag(tmp_path / "k", n=40, per_chunk=10)
    data = writer.path.read_bytes()
    assert _values(writer.path) == list(range(40))
    seen_counts = set()
    cut = tmp_path / "cut.mcap"
    for size in range(8, len(data), 7):
        cut.write_bytes(data[:size])
        got = _values(cut)
        assert got == list(range(len(got))), size  # a prefix, in order, no duplicates
        assert len(got) % 10 == 0  # only complete chunks
        seen_counts.add(len(got))
    assert seen_counts == {0, 10, 20, 30, 40}


def test_damaged_chunk_is_skipped_and_the_rest_recovered(tmp_path: Path) -> None:
    writer = _killed_bag(tmp_path / "k", n=30, per_chunk=10)
    data = bytearray(writer.path.read_bytes())
    # find the second chunk record (opcode 0x06) and flip bytes in its compressed payload
    chunk_offsets = [o for _c, _s, o in _record_offsets(bytes(data)) if _c == 0x06]
    assert len(chunk_offsets) == 3
    start = chunk_offsets[1]
    data[start + 80 : start + 90] = b"\xff" * 10
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    scanner = McapScanner(bad)
    got = [int(s) for s in (_values(bad))]
    assert got == list(range(10)) + list(range(20, 30))
    list(scanner.messages())
    assert scanner.report.corrupt_chunks == 1
    assert scanner.report.damage_offset == start and f"chunk record at byte {start}" in scanner.report.damage


def test_reader_names_the_damage_and_refuses_a_bag_without_one_readable_message(tmp_path: Path) -> None:
    writer = _killed_bag(tmp_path / "k", n=30, per_chunk=10)
    data = bytearray(writer.path.read_bytes())
    chunks = [o for op, _n, o in _record_offsets(bytes(data)) if op == 0x06]
    # a damaged second chunk: the other two are read, the warning names the chunk's offset
    damaged = bytearray(data)
    damaged[chunks[1] + 80 : chunks[1] + 90] = b"\xff" * 10
    (tmp_path / "damaged.mcap").write_bytes(bytes(damaged))
    reader = BagReader(tmp_path / "damaged.mcap")
    assert reader.message_count == 20
    assert any(
        f"damaged chunk record at byte {chunks[1]}" in w and "20 message(s)" in w for w in reader.warnings
    )
    # cut inside the first chunk: damage and no message at all -> corrupt or truncated
    (tmp_path / "cut.mcap").write_bytes(bytes(data[: chunks[0] + 40]))
    with pytest.raises(
        BagError, match=rf"cut\.mcap is corrupt or truncated: chunk record at byte {chunks[0]}"
    ):
        BagReader(tmp_path / "cut.mcap")
    # cut inside the second chunk: the first is read, with a warning naming where the file is cut
    (tmp_path / "cut2.mcap").write_bytes(bytes(data[: chunks[1] + 40]))
    reader = BagReader(tmp_path / "cut2.mcap")
    assert reader.message_count == 10
    assert any(f"chunk record at byte {chunks[1]} is cut short" in w for w in reader.warnings)
    # the first chunk damaged, nothing else: refused too
    only = bytearray(data[: chunks[1]])
    only[chunks[0] + 80 : chunks[0] + 90] = b"\xff" * 10
    (tmp_path / "only.mcap").write_bytes(bytes(only))
    with pytest.raises(BagError, match=f"damaged chunk record at byte {chunks[0]}"):
        BagReader(tmp_path / "only.mcap")


def _record_offsets(data: bytes):
    import struct

    off = 8
    while off + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, off)
        yield op, length, off
        off += 9 + length


def test_repair_makes_a_complete_bag(tmp_path: Path) -> None:
    bag = tmp_path / "k"
    writer = _killed_bag(bag, n=55, per_chunk=10)  # the last 5 messages died with the process
    assert not (bag / "metadata.yaml").exists()
    reader = BagReader(bag)
    assert not reader.complete and reader.message_count == 50
    assert "recorder --repair" in reader.warnings[0]

    rep = repair_bag(bag)
    assert not rep.scan.complete and rep.scan.messages == 50
    assert rep.backup is not None and rep.backup.exists()
    meta = check_bag(bag)  # metadata.yaml + summary + hashes, as for a clean bag
    assert meta["message_count"] == 50
    assert meta["custom_data"] == {"session_id": "P007", "repaired": "true"}
    assert [m.data for _, _, m in read_with_rosbags(bag)] == [str(i) for i in range(50)]
    assert BagReader(bag).complete
    assert writer.path.exists()


def test_repair_of_a_complete_bag_keeps_everything(tmp_path: Path) -> None:
    bag = tmp_path / "c"
    writer = BagWriter(bag)
    writer.add_topic("/a", TN, message_definition(TN), installed_type_hash(TN) or "", [default_qos()])
    for i in range(12):
        writer.write("/a", T0 + i, serialize(String(data=str(i))))
    writer.close()
    rep = repair_bag(bag, keep_damaged=False)
    assert rep.scan.complete and rep.backup is None
    assert check_bag(bag)["message_count"] == 12


def test_repair_errors(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="does not exist"):
        repair_bag(tmp_path / "none")
    (tmp_path / "d").mkdir()
    with pytest.raises(BagError, match=r"no \.mcap"):
        repair_bag(tmp_path / "d")
    (tmp_path / "d" / "d_0.mcap").write_bytes(b"garbage!" * 4)
    with pytest.raises(BagError, match="not an MCAP file"):
        repair_bag(tmp_path / "d")
    assert not (tmp_path / "d" / "d_0.mcap.repairing").exists()


def test_header_only_bag_reads_as_empty(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / "h")
    writer.abort()
    copy = tmp_path / "h.mcap"
    shutil.copy(writer.path, copy)
    assert BagReader(copy).message_count == 0


# -- a complete bag with bytes flipped in the middle -----------------------------------------------


def _complete_bag(path: Path, n: int = 1000) -> BagWriter:
    """A finished bag of ``n`` messages in chunks of about 30 (chunk size 4 KiB)."""
    writer = BagWriter(path, chunk_size=4096)
    writer.add_topic("/count", TN, message_definition(TN), installed_type_hash(TN) or "", [default_qos()])
    for i in range(n):
        writer.write("/count", T0 + i * 10_000_000, serialize(String(data=f"{i:05d} " + "x" * 80)))
    writer.close()
    return writer


def _flip(path: Path, start: int, n: int) -> None:
    data = bytearray(path.read_bytes())
    for i in range(start, start + n):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _chunk_spans(data: bytes) -> list[tuple[int, int, list[int]]]:
    """(first byte, end byte, message values) of every chunk of an intact file, via the mcap library."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk
    from rclpy.serialization import deserialize_message

    spans = []
    for index in SeekingReader(io.BytesIO(data)).get_summary().chunk_indexes:
        start, end = index.chunk_start_offset, index.chunk_start_offset + index.chunk_length
        records = breakup_chunk(Chunk.read(ReadDataStream(io.BytesIO(data[start + 9:end]))))
        values = [int(deserialize_message(r.data, String).data.split()[0]) for r in records
                  if isinstance(r, Message)]
        spans.append((start, end, values))
    return sorted(spans)


@pytest.mark.parametrize("where", [0.5, 0.3, 0.8])
def test_flipped_bytes_in_a_complete_bag_are_found_by_chunk_crc(tmp_path: Path, where: float) -> None:
    """400 bytes flipped mid-file: the summary still reads as complete (that is all --info
    looked at); the chunk CRCs say which chunks are damaged and how many messages they hold."""
    from hri_physio_bridge.bag.integrity import check_chunks

    writer = _complete_bag(tmp_path / "b")
    spans = _chunk_spans(writer.path.read_bytes())
    start = int(writer.path.stat().st_size * where)
    _flip(writer.path, start, 400)
    hit = [(s, values) for s, e, values in spans if s < start + 400 and e > start]
    assert hit, "the flipped bytes must hit a chunk for this test to mean anything"

    reader = BagReader(writer.path.parent)
    assert reader.complete and reader.message_count == 1000  # the summary alone sees nothing
    check = check_chunks(writer.path)
    assert [c.offset for c in check.damaged] == [s for s, _ in hit]
    assert check.unreadable_messages == sum(len(v) for _, v in hit)
    assert [c.messages for c in check.damaged] == [len(v) for _, v in hit]
    assert [c.offset for _p, c in reader.damaged_chunks()] == [s for s, _ in hit]
    assert reader.unreadable_messages == check.unreadable_messages

    # Repair keeps every message of every intact chunk, also past the damaged stretch.
    rep = repair_bag(writer.path.parent, keep_damaged=False)
    lost = {v for _, values in hit for v in values}
    assert rep.scan.messages == 1000 - len(lost)
    got = [int(m.data.split()[0]) for _, _, m in read_with_rosbags(writer.path.parent)]
    assert got == [i for i in range(1000) if i not in lost]


def test_an_intact_bag_has_no_damaged_chunk(tmp_path: Path) -> None:
    from hri_physio_bridge.bag.integrity import check_chunks

    writer = _complete_bag(tmp_path / "ok", n=200)
    check = check_chunks(writer.path)
    assert check.damaged == [] and check.unreadable_messages == 0
    assert BagReader(writer.path.parent).damaged_chunks() == []


def test_a_killed_bag_counts_the_messages_of_its_damaged_chunk(tmp_path: Path) -> None:
    writer = _killed_bag(tmp_path / "k", n=30, per_chunk=10)
    data = bytearray(writer.path.read_bytes())
    chunks = [o for op, _n, o in _record_offsets(bytes(data)) if op == 0x06]
    data[chunks[1] + 80: chunks[1] + 90] = b"\xff" * 10
    (tmp_path / "damaged.mcap").write_bytes(bytes(data))
    reader = BagReader(tmp_path / "damaged.mcap")
    assert [(c.offset, c.messages) for _p, c in reader.damaged_chunks()] == [(chunks[1], 10)]
    assert reader.unreadable_messages == 10 and reader.message_count == 20

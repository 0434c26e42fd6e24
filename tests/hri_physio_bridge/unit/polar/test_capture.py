"""Capture files: the shipped synthetic capture, malformed files, replay of the issue's vectors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from helpers import DATA
from helpers.polar import run_session
from hri_physio_bridge.polar.capture import CaptureError, CaptureWriter, read_capture
from hri_physio_bridge.polar.fake import FakeClock, FakePolarDevice
from hri_physio_bridge.polar.gatt import HEART_RATE_MEASUREMENT, PMD_DATA

DATA = DATA / "polar"
CAPTURE = DATA / "synthetic_h10.jsonl"


def test_shipped_capture_is_what_the_script_builds() -> None:
    sys.path.insert(0, str(DATA))
    try:
        import make_synthetic_capture
    finally:
        sys.path.remove(str(DATA))
    assert CAPTURE.read_text(encoding="utf-8").splitlines() == make_synthetic_capture.build_lines()
    header = read_capture(CAPTURE).header
    assert header["synthetic"] is True and "SYNTHETIC" in header["note"]


def test_replaying_the_synthetic_capture_gives_the_vectors() -> None:
    capture = read_capture(CAPTURE)
    clock = FakeClock()
    device = FakePolarDevice.from_capture(capture, clock=clock)
    assert device.name == "Polar H10 0A1B2C3D" and device.battery == 90
    run = run_session([device], clock, device="0A1B2C3D", streams=["ecg", "acc", "hr", "rr"], acc_rate=25)
    ecg = [row[0] for row in run.sink.values("ecg")]
    assert ecg[:8] == [104, 88, 70, 61, 50, 38, 22, 4] and len(ecg) == 10 * 130 // 8 * 8
    assert set(map(tuple, run.sink.values("acc"))) == {(-187, -28, 949), (-187, -28, 952)}
    assert {row[0] for row in run.sink.values("hr")} == {72}
    assert run.sink.values("rr")[:2] == [[987 * 1000 / 1024], [965 * 1000 / 1024]]
    assert run.session.status()["streams"]["ecg"]["gaps"] == 0
    notifications = [
        r for r in capture.records if r.op == "notify" and r.char in (PMD_DATA, HEART_RATE_MEASUREMENT)
    ]
    assert device.delivered == len(notifications)


def test_writer_never_overwrites_and_flushes_each_line(tmp_path: Path) -> None:
    path = tmp_path / "c.jsonl"
    writer = CaptureWriter(path, {"program": "test"})
    writer.record(12.5, "notify", "2a37", bytes.fromhex("1048db03c503"))
    assert json.loads(path.read_text().splitlines()[1]) == {
        "t": 12.5,
        "op": "notify",
        "char": "hr",
        "hex": "1048db03c503",
    }
    writer.close()
    with pytest.raises(CaptureError, match="exists already"):
        CaptureWriter(path)
    assert read_capture(path).records[0].data == bytes.fromhex("1048db03c503")


@pytest.mark.parametrize(
    "body, problem",
    [
        ('{"t": 1, "op": "notify", "char": "hr", "hex": "10"}', "no header"),
        ("HEADER\nnot json\n{}", "c.jsonl:2: not JSON"),
        ('HEADER\n{"t": 1, "op": "notify", "char": "hr"}', "c.jsonl:2: record without 'hex'"),
        ('HEADER\n{"t": "x", "op": "notify", "char": "hr", "hex": ""}', "t must be a number"),
        ('HEADER\n{"t": 1, "op": "push", "char": "hr", "hex": ""}', "op must be one of"),
        ('HEADER\n{"t": 1, "op": "notify", "char": "hr", "hex": "zz"}', "hexadecimal"),
        ('HEADER\n{"t": Infinity, "op": "notify", "char": "hr", "hex": "10"}',
         "c.jsonl:2: t must be a finite"),
        ('HEADER\n{"t": NaN, "op": "notify", "char": "hr", "hex": "10"}', "t must be a finite"),
        ('HEADER\n{"t": 2, "op": "notify", "char": "hr", "hex": "10"}\n'
         '{"t": 1, "op": "notify", "char": "hr", "hex": "10"}',
         "c.jsonl:3: t 1.000000 is before the notification on line 2"),
        ('{"format": "other", "version": 1}', "not a hri_physio.polar.capture"),
    ],
)
def test_malformed_capture_files(tmp_path: Path, body: str, problem: str) -> None:
    header = json.dumps({"format": "hri_physio.polar.capture", "version": 1})
    path = tmp_path / "c.jsonl"
    path.write_text(body.replace("HEADER", header) + "\n", encoding="utf-8")
    with pytest.raises(CaptureError, match=problem):
        read_capture(path)


def test_a_last_line_cut_off_is_left_out_with_a_warning(tmp_path: Path) -> None:
    """A writer stopped in mid-line, or a copy cut short: what came before still replays."""
    header = json.dumps({"format": "hri_physio.polar.capture", "version": 1})
    good = '{"t": 1, "op": "notify", "char": "hr", "hex": "1048"}'
    path = tmp_path / "c.jsonl"
    path.write_text(f"{header}\n{good}\n{good[:20]}", encoding="utf-8")
    capture = read_capture(path)
    assert [r.line for r in capture.records] == [2]
    assert len(capture.warnings) == 1 and "c.jsonl:3: the last line is cut off" in capture.warnings[0]
    path.write_text(f"{header}\n{good}\n{good[:20]}\n", encoding="utf-8")
    assert len(read_capture(path).records) == 1
    path.write_text(f"{header}\n{good[:20]}\n{good}\n", encoding="utf-8")  # cut in the middle: an error
    with pytest.raises(CaptureError, match=r"c\.jsonl:2: not JSON"):
        read_capture(path)


def test_reads_and_writes_may_be_stamped_before_a_notification(tmp_path: Path) -> None:
    """Only notifications are recorded as they arrive; a write's stamp may come before the last one."""
    header = json.dumps({"format": "hri_physio.polar.capture", "version": 1})
    path = tmp_path / "c.jsonl"
    path.write_text(header + "\n" + '{"t": 2, "op": "notify", "char": "hr", "hex": "10"}\n'
                    '{"t": 1, "op": "write", "char": "pmd_cp", "hex": "01"}\n', encoding="utf-8")
    assert [r.op for r in read_capture(path).records] == ["notify", "write"]


def test_a_folder_is_not_a_capture(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match="is a directory, not a capture file"):
        read_capture(tmp_path)


def test_capture_that_is_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "c.jsonl"
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(CaptureError, match="not UTF-8"):
        read_capture(path)
    with pytest.raises(CaptureError, match="does not exist"):
        read_capture(tmp_path / "missing.jsonl")

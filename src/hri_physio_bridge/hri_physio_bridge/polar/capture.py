"""Capture files: every notification (and read/write) of a session as JSON lines, and reading them back.

One object per line::

    {"format": "hri_physio.polar.capture", "version": 1, "device": {...}, "note": "..."}   # header
    {"t": 1234.567891, "op": "notify", "char": "pmd_data", "hex": "00ea1cac..."}

``t`` is the host receive time in seconds (the LSL clock), ``op`` is ``notify``, ``read`` or
``write``, ``char`` the characteristic (short name for the ones the streamer uses, else its UUID),
``hex`` the bytes. Each line is flushed as written, so a crash keeps everything before it. The
fake BLE client replays a capture (:meth:`hri_physio_bridge.polar.fake.FakePolarDevice.from_capture`),
so a field recording of a real strap becomes a regression test without the strap.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from hri_physio_bridge.polar.gatt import SHORT_NAMES, normalise_uuid

FORMAT = "hri_physio.polar.capture"
VERSION = 1
OPS = ("notify", "read", "write")


class CaptureError(ValueError):
    """A capture file that cannot be read; the message names the file and line."""


@dataclass(frozen=True)
class CaptureRecord:
    t: float
    op: str
    char: str  # full UUID
    data: bytes
    line: int = field(default=0, compare=False)  # where it was read from (0: not read from a file)

    def to_json(self) -> str:
        return json.dumps(
            {
                "t": round(self.t, 9),
                "op": self.op,
                "char": SHORT_NAMES.get(self.char, self.char),
                "hex": self.data.hex(),
            }
        )


@dataclass
class Capture:
    header: dict[str, Any] = field(default_factory=dict)
    records: list[CaptureRecord] = field(default_factory=list)
    source: str = ""  # the file it was read from
    warnings: list[str] = field(default_factory=list)  # what reading it let pass, for the caller to say

    def where(self, record: CaptureRecord) -> str:
        """``file:line`` of a record (for messages)."""
        return f"{self.source or 'capture'}:{record.line}"


class CaptureWriter:
    """Appends records to a new capture file (never overwrites one)."""

    def __init__(self, path: str | Path, header: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise CaptureError(f"capture file {self.path} exists already; choose a new name")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] | None = self.path.open("x", encoding="utf-8")
        self.records = 0
        self._write(json.dumps({"format": FORMAT, "version": VERSION, **(header or {})}))

    def _write(self, line: str) -> None:
        if self._file is None:
            return
        self._file.write(line + "\n")
        self._file.flush()

    def record(self, t: float, op: str, char: str, data: bytes) -> None:
        self._write(CaptureRecord(t, op, normalise_uuid(char), bytes(data)).to_json())
        self.records += 1

    def note(self, **fields: Any) -> None:
        """An extra header-like line (e.g. the device found), ignored by replay."""
        self._write(json.dumps({"note": fields}))

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def read_capture(path: str | Path) -> Capture:
    """All records of a capture file, in file order; :class:`CaptureError` on any malformed line.

    A last line that is not JSON (cut off: the writer stopped while writing it, or the copy was cut) is
    left out with a warning in :attr:`Capture.warnings`: everything before it replays.
    Notifications must come in time order, as the writer records them on arrival.
    """
    p = Path(path)
    if not p.is_file():
        what = "is a directory, not a capture file" if p.is_dir() else "does not exist"
        raise CaptureError(f"capture file {p} {what}")
    capture = Capture(source=str(p))
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CaptureError(f"capture file {p} is not UTF-8 text (byte {exc.start})") from None
    lines = text.splitlines()
    last_notify: CaptureRecord | None = None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        where = f"{p}:{number}"
        try:
            item = json.loads(line)
        except json.JSONDecodeError as exc:
            if number == len(lines) and capture.header:
                capture.warnings.append(f"{where}: the last line is cut off ({exc.msg}); replaying the "
                                        f"{len(capture.records)} record(s) before it")
                break
            raise CaptureError(f"{where}: not JSON ({exc.msg})") from None
        if not isinstance(item, dict):
            raise CaptureError(f"{where}: expected a JSON object")
        if "format" in item:
            if item.get("format") != FORMAT or item.get("version") != VERSION:
                raise CaptureError(f"{where}: not a {FORMAT} version {VERSION} file")
            capture.header = item
            continue
        if "note" in item:
            note = item["note"]
            if isinstance(note, dict) and isinstance(note.get("device"), dict):
                capture.header.setdefault("device", note["device"])
            continue
        record = _record_of(item, where, number)
        if record.op == "notify":
            if last_notify is not None and record.t < last_notify.t:
                raise CaptureError(f"{where}: t {record.t:.6f} is before the notification on line "
                                   f"{last_notify.line} (t {last_notify.t:.6f}); notifications are "
                                   "recorded as they arrive, so their times only go forward")
            last_notify = record
        capture.records.append(record)
    if capture.header.get("format") != FORMAT:
        raise CaptureError(f"capture file {p} has no header line (format {FORMAT})")
    return capture


def _record_of(item: dict[str, Any], where: str, number: int) -> CaptureRecord:
    try:
        t, op, char, hex_text = item["t"], item["op"], item["char"], item["hex"]
    except KeyError as exc:
        raise CaptureError(f"{where}: record without {exc.args[0]!r}") from None
    if not isinstance(t, int | float) or isinstance(t, bool):
        raise CaptureError(f"{where}: t must be a number, got {t!r}")
    if not math.isfinite(t):
        raise CaptureError(f"{where}: t must be a finite number of seconds, got {t!r}")
    if op not in OPS:
        raise CaptureError(f"{where}: op must be one of {', '.join(OPS)}, got {op!r}")
    if not isinstance(char, str) or not isinstance(hex_text, str):
        raise CaptureError(f"{where}: char and hex must be text")
    try:
        data = bytes.fromhex(hex_text)
    except ValueError:
        raise CaptureError(f"{where}: hex is not hexadecimal bytes: {hex_text[:40]!r}") from None
    return CaptureRecord(float(t), op, normalise_uuid(char), data, line=number)

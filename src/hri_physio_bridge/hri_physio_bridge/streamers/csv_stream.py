"""CSV streamer: logs as outputs, log replay as inputs.

File layout: one header row ``t,<ch1>,<ch2>...`` then one row per sample, the
source timestamp first. Floats are written with 17 significant digits so a
float64 survives the round trip exactly.

Address: ``<path>[?rate=<x>&dtype=<name>]``. As an input, ``rate`` paces the
replay by the recorded timestamps: 1 = real time (default), 20 = twenty times
faster, 0 = as fast as possible (order kept).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from hri_physio_bridge.frames import TIME_LABEL, Frame
from hri_physio_bridge.streamers.base import (
    Streamer,
    StreamerError,
    StreamMismatchError,
    StreamNotFoundError,
    StreamSpec,
    numpy_dtype,
    split_address,
)

_QUERY_KEYS = {"rate", "dtype"}
#: Splits after a carriage return that ends a line on its own (files written with CR line ends).
_LONE_CR = re.compile(rb"(?<=\r)(?!\n)")


class _Lines:
    """The text lines of a CSV file, decoded one by one as UTF-8, counted.

    A line that is not UTF-8 raises :class:`StreamMismatchError` naming the file and the line;
    every line before it has been handed out.
    """

    def __init__(self, fh: BinaryIO, path: Path) -> None:
        self.path = path
        self.number = 0  # of the last line handed out (1 = the header)
        self._lines = self._decode(fh)

    def _decode(self, fh: BinaryIO) -> Iterator[str]:
        for raw in fh:
            for piece in _LONE_CR.split(raw) if b"\r" in raw[:-2] else (raw,):
                if not piece:
                    continue
                self.number += 1
                try:
                    yield piece.decode("utf-8")
                except UnicodeDecodeError as exc:
                    raise StreamMismatchError(
                        f"{self.path}:{self.number}: not UTF-8 text ({exc.reason} at byte {exc.start + 1} "
                        "of the line); save the file as UTF-8"
                    ) from None

    def __iter__(self) -> Iterator[str]:
        return self._lines


def parse_csv_address(address: str) -> tuple[Path, dict[str, str]]:
    path, params = split_address(address, "CSV", "file path", _QUERY_KEYS)
    return Path(path).expanduser(), params


class CsvWriter:
    """Append frames to a CSV file, flushed after every write.

    Refuses to overwrite an existing file: a lost log is a lost participant.
    """

    def __init__(self, path: str | os.PathLike, channels: tuple[str, ...], dtype: str = "float64") -> None:
        self.path = Path(path)
        if self.path.exists():
            raise StreamerError(f"refusing to overwrite existing file {self.path}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: io.TextIOWrapper | None = open(self.path, "x", newline="", encoding="utf-8")  # noqa: SIM115
        self._writer = csv.writer(self._file)
        self._writer.writerow([TIME_LABEL, *channels])
        self._file.flush()
        self.num_channels = len(channels)
        self._numeric = dtype != "string"
        self.rows_written = 0

    def write(self, frame: Frame) -> None:
        if self._file is None:
            raise StreamerError(f"log {self.path} is closed")
        if frame.num_channels != self.num_channels:
            raise StreamMismatchError(
                f"frame has {frame.num_channels} channels, log {self.path} has {self.num_channels}"
            )
        if self._numeric:
            value_fmt = "%d" if frame.values.dtype.kind in "iu" else "%.17g"
            table = np.column_stack([frame.timestamps, frame.values.astype(np.float64)])
            fmt = ",".join(["%.17g"] + [value_fmt] * self.num_channels)
            np.savetxt(self._file, table, fmt=fmt, delimiter=",")
        else:
            for t, row in zip(frame.timestamps, frame.values, strict=True):
                self._writer.writerow([f"{t:.17g}", *[str(v) for v in row]])
        self._file.flush()
        self.rows_written += frame.num_samples

    def close(self) -> None:
        if self._file is not None:
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            self._file = None


#: Seconds of paced rows sent as one chunk at most (wall time at the replay rate): rows are held back
#: this long at most, as a chunking LSL outlet would.
BATCH_WINDOW = 0.05


class CsvStreamer(Streamer):
    scheme = "csv"

    def __init__(
        self,
        address: str,
        max_chunk: int = 1024,
        monotonic: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(address)
        self.path, self.params = parse_csv_address(address)
        try:
            self.rate = float(self.params.get("rate", "1"))
        except ValueError:
            raise ValueError(f"CSV rate must be a number, got {self.params['rate']!r}") from None
        if self.rate < 0 or not math.isfinite(self.rate):
            raise ValueError(f"CSV rate must be >= 0 (0 = as fast as possible), got {self.rate}")
        self.max_chunk = int(max_chunk)
        self._monotonic = monotonic
        self._sleep = sleep
        self._reader: Iterator[list[str]] | None = None
        self._lines: _Lines | None = None
        self._file: BinaryIO | None = None
        self._writer: CsvWriter | None = None
        self._t0: tuple[float, float] | None = None  # (first source t, wall start)
        self._error: StreamMismatchError | None = None  # found after good rows: raised on the next call
        self._held: tuple[float, list] | None = None  # a row read but not yet due
        self.exhausted = False

    # -- input ---------------------------------------------------------------
    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        # The file is there or not: nothing to wait for, so neither timeout nor stop applies.
        self.close()
        if not self.path.is_file():
            raise StreamNotFoundError(f"CSV file {self.path} does not exist")
        self._file = open(self.path, "rb")  # noqa: SIM115
        self._lines = _Lines(self._file, self.path)
        self._reader = csv.reader(self._lines)
        try:
            header = next(self._reader, None)
        except (StreamMismatchError, csv.Error) as exc:
            self.close()
            raise StreamMismatchError(str(exc) if isinstance(exc, StreamMismatchError)
                                      else f"{self.path}:1: {exc}") from None
        if not header or header[0].strip() != TIME_LABEL:
            self.close()
            raise StreamMismatchError(
                f"{self.path}: first row must be a header starting with '{TIME_LABEL}', got {header}"
            )
        channels = tuple(h.strip() for h in header[1:])
        if not channels:
            self.close()
            raise StreamMismatchError(f"{self.path}: header has no data columns")
        dtype = self.params.get("dtype") or (expected.dtype if expected else "float64")
        spec = StreamSpec(
            name=self.path.stem,
            type=expected.type if expected else "Physio",
            channel_count=len(channels),
            nominal_rate=expected.nominal_rate if expected else 0.0,
            dtype=dtype,
            channels=channels,
        )
        if expected is not None and expected.channel_count != spec.channel_count:
            self.close()
            raise StreamMismatchError(
                f"{self.path} has {spec.channel_count} data column(s) but num_channels is "
                f"{expected.channel_count}"
            )
        self.spec = spec
        self._np_dtype = numpy_dtype(dtype)
        self.exhausted = False
        self._t0 = None
        self._error = None
        self._held = None
        return spec

    def receive(self, timeout: float = 0.1) -> Frame | None:
        """The next rows (up to ``max_chunk``) that are due at the replay ``rate``. A bad row is an
        error naming its line, raised once the good rows before it have been returned.

        A row not yet due is waited for at most ``timeout`` (None: not yet, and the row is kept for
        the next call), so a stop never waits out a long gap in the timestamps, and the rows before a
        gap go out when they are due, not with the first row after it. Rows due within ``BATCH_WINDOW``
        of the first one go out with it.
        """
        if self._reader is None or self._lines is None or self.spec is None:
            raise StreamerError(f"{self.uri} is not open as an input")
        if self._error is not None and self._held is None:
            raise self._error
        deadline = self._monotonic() + max(timeout, 0.0)
        stamps: list[float] = []
        values: list[list[float]] | list[list[str]] = []
        batch_end = deadline  # set when the first row is taken
        while len(stamps) < self.max_chunk:
            row = self._next_row()
            if row is None:
                break
            wait = self._until_due(row[0])
            if wait > 0:
                now = self._monotonic()
                # The first row is waited for up to the timeout; later ones join its chunk if they are
                # due within BATCH_WINDOW of it (a 1 kHz file is not sent a row at a time).
                limit = deadline - now if not stamps else min(deadline, batch_end) - now
                if wait > limit:
                    if not stamps and limit > 0:
                        self._sleep(limit)
                    self._held = row
                    break
                self._sleep(wait)
            if not stamps:
                batch_end = self._monotonic() + BATCH_WINDOW
            stamps.append(row[0])
            values.append(row[1])
        if not stamps:
            if self._held is not None:
                return None  # the next row is not due yet
            if self._error is not None:
                raise self._error
            self.exhausted = True
            return None
        if self.spec.is_string:
            array = np.array(values, dtype=object)
        else:
            array = np.array(values, dtype=np.float64).astype(self._np_dtype)
        return Frame(np.array(stamps, dtype=np.float64), array, self.spec.channels)

    def _next_row(self) -> tuple[float, list] | None:
        """The row held back from the last call, else the next good row; None at the end or at a bad
        row (kept in ``_error`` for after the rows before it)."""
        assert self._reader is not None and self._lines is not None
        if self._held is not None:
            row, self._held = self._held, None
            return row
        if self._error is not None:
            return None
        try:
            for fields in self._reader:
                if fields:
                    return self._parse(fields, self._lines.number)
        except StreamMismatchError as exc:
            self._error = exc
        except csv.Error as exc:
            self._error = StreamMismatchError(f"{self.path}:{self._lines.number}: {exc}")
        return None

    def _parse(self, row: list[str], line: int) -> tuple[float, list]:
        assert self.spec is not None
        if len(row) != self.spec.channel_count + 1:
            raise StreamMismatchError(
                f"{self.path}:{line}: expected {self.spec.channel_count + 1} columns, got {len(row)}"
            )
        try:
            stamp = float(row[0])
            if self.spec.is_string:
                return stamp, row[1:]
            return stamp, [float(v) for v in row[1:]]
        except ValueError as exc:
            raise StreamMismatchError(f"{self.path}:{line}: not a number ({exc})") from None

    def _until_due(self, t_source: float) -> float:
        """Seconds until a row stamped ``t_source`` is due at the replay rate (<= 0: due now). The
        first row sets the start; a row whose stamp is not finite is due at once (the receiver
        drops it)."""
        if self.rate == 0 or not math.isfinite(t_source):
            return 0.0
        now = self._monotonic()
        if self._t0 is None:
            self._t0 = (t_source, now)
            return 0.0
        return self._t0[1] + (t_source - self._t0[0]) / self.rate - now

    # -- output --------------------------------------------------------------
    def open_output(self, spec: StreamSpec) -> None:
        self.close()
        self._writer = CsvWriter(self.path, spec.channels, spec.dtype)
        self.spec = spec

    def publish(self, frame: Frame) -> None:
        if self._writer is None:
            raise StreamerError(f"{self.uri} is not open as an output")
        self._writer.write(frame)

    def abandon(self) -> None:
        unused = self._writer.path if self._writer is not None and self._writer.rows_written == 0 else None
        self.close()
        if unused is not None:
            unused.unlink(missing_ok=True)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None
            self._reader = None
            self._lines = None

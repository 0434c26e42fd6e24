"""Sliding windows over a timestamped sample stream, whatever the chunking of the input.

A :class:`WindowAccumulator` takes chunks of samples with their source timestamps and hands
out windows of ``window`` samples every ``hop`` samples. The windows depend only on the
samples, never on how they were chunked on the way in.

The stream is cut into *segments* at timestamp discontinuities: a step longer than
``gap_factor`` sample periods (lost samples: a :class:`~hri_physio_bridge.ring_buffer.Gap`,
the bridge's one gap type), or a step that does not move forward (duplicated or reordered
timestamps: a :class:`ClockJump`, nothing is missing). Windows never span a cut, because
NeuroKit2 assumes evenly spaced samples. When a segment ends (at a cut, or at :meth:`flush` when the input
ends) and it holds samples no window has covered yet, one *final* window is emitted: the
last ``window`` samples of the segment (or the whole segment when it is shorter), so no
sample is left out.

With ``context > 0`` each window also carries up to ``context`` samples that precede it in
the same segment (``pre_timestamps`` / ``pre_values``): when windows barely overlap, the
processor detects peaks with that lead-in so that a beat at a window's start is not lost to
the filters' edge effects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hri_physio_bridge.ring_buffer import Gap


@dataclass(frozen=True)
class Window:
    """One window of samples and where it sits in its segment."""

    timestamps: np.ndarray  # (n,)
    values: np.ndarray  # (n, channels)
    index: int  # running window number, from 0
    segment: int  # running segment number, from 0
    first_in_segment: bool  # no earlier window of this segment overlaps it
    final: bool  # the segment ends with this window: no later window will overlap it
    next_start: int  # sample offset where the next window of the segment starts (n when final)
    pre_timestamps: np.ndarray = field(default_factory=lambda: np.empty(0))
    pre_values: np.ndarray = field(default_factory=lambda: np.empty((0, 1)))

    @property
    def num_samples(self) -> int:
        return int(self.timestamps.shape[0])

    @property
    def t_start(self) -> float:
        return float(self.timestamps[0])

    @property
    def t_end(self) -> float:
        return float(self.timestamps[-1])


def timestamp_gap(t_before: float, t_after: float, step: float) -> Gap:
    """The hole between two samples ``t_after - t_before`` apart at a nominal ``step``."""
    missing = max(0, round((t_after - t_before) / step) - 1)
    return Gap(t_before + step, t_after - step, missing, "timestamp gap", t_before=t_before, t_after=t_after)


@dataclass(frozen=True)
class ClockJump:
    """A step that does not move forward (duplicated or backward timestamp): the stream is cut
    there, but nothing is missing."""

    t_before: float  # last timestamp before the cut
    t_after: float  # first timestamp after it (<= t_before)


@dataclass(frozen=True)
class Discarded:
    """Samples of a segment too short to make any window of at least ``min_samples``."""

    t_start: float
    t_end: float
    samples: int


Event = Window | Gap | ClockJump | Discarded


class WindowAccumulator:
    """Buffer samples and emit fixed-length, overlapping windows (state across chunks)."""

    def __init__(
        self,
        window: int,
        hop: int,
        sampling_rate: float,
        gap_factor: float = 1.5,
        min_samples: int = 1,
        context: int = 0,
    ) -> None:
        if window < 1:
            raise ValueError(f"window must hold at least one sample, got {window}")
        if not 1 <= hop <= window:
            raise ValueError(f"hop must be between 1 and the window length ({window}) samples, got {hop}")
        if not (math.isfinite(sampling_rate) and sampling_rate > 0):
            raise ValueError(f"sampling rate must be a positive number, got {sampling_rate}")
        if not gap_factor > 1:
            raise ValueError(f"gap_factor must be > 1 (in sample periods), got {gap_factor}")
        self.window = int(window)
        self.hop = int(hop)
        self.step = 1.0 / sampling_rate
        self.max_step = gap_factor * self.step
        self.min_samples = max(1, min(int(min_samples), self.window))
        if context < 0:
            raise ValueError(f"context must be >= 0 samples, got {context}")
        self.context = int(context)
        self._t = np.empty(0)
        self._v: np.ndarray | None = None
        self._next = 0  # buffer offset where the next window starts
        self._covered = 0  # buffer offset up to which emitted windows covered the segment
        self._emitted_in_segment = 0
        self._windows = 0
        self._segment = 0
        self._last_t: float | None = None

    @property
    def buffered(self) -> int:
        return int(self._t.shape[0])

    @property
    def last_timestamp(self) -> float | None:
        """The newest timestamp pushed (None before the first)."""
        return self._last_t

    def push(self, timestamps: np.ndarray, values: np.ndarray) -> list[Event]:
        """Add a chunk; return the windows (and gaps) it completes, in stream order."""
        t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 1:
            v = v.reshape(-1, 1)
        if v.ndim != 2 or v.shape[0] != t.shape[0]:
            raise ValueError(f"{t.shape[0]} timestamps for values shaped {v.shape}")
        if t.shape[0] == 0:
            return []
        if self._v is not None and v.shape[1] != self._v.shape[1]:
            raise ValueError(f"chunk has {v.shape[1]} channel(s), the stream had {self._v.shape[1]}")
        prev = np.concatenate([[self._last_t], t[:-1]]) if self._last_t is not None else None
        if prev is None:
            steps = np.diff(t)
            offset = 1
        else:
            steps = t - prev
            offset = 0
        cuts = np.flatnonzero(~((steps > 0) & (steps <= self.max_step))) + offset
        events: list[Event] = []
        start = 0
        for cut in cuts:
            events.extend(self._append(t[start:cut], v[start:cut]))
            before = float(t[cut - 1]) if cut > 0 else float(self._last_t)
            events.extend(self._end_segment())
            after = float(t[cut])
            events.append(
                timestamp_gap(before, after, self.step) if after > before else ClockJump(before, after))
            start = int(cut)
        events.extend(self._append(t[start:], v[start:]))
        self._last_t = float(t[-1])
        return events

    def flush(self) -> list[Event]:
        """The input ended: close the current segment (emitting its final window, if due)."""
        return self._end_segment()

    # -- internals -------------------------------------------------------------
    def _append(self, t: np.ndarray, v: np.ndarray) -> list[Event]:
        if t.shape[0] == 0:
            return []
        if self._v is None or self._t.shape[0] == 0:
            self._t, self._v = t.copy(), v.copy()
        else:
            self._t = np.concatenate([self._t, t])
            self._v = np.concatenate([self._v, v])
        out: list[Event] = []
        while self._t.shape[0] - self._next >= self.window:
            a, b = self._next, self._next + self.window
            out.append(self._make(a, b, final=False, next_start=self.hop))
            self._covered = b
            self._next += self.hop
        self._trim()
        return out

    def _make(self, a: int, b: int, final: bool, next_start: int) -> Window:
        c = max(0, a - self.context)
        w = Window(
            timestamps=self._t[a:b].copy(),
            values=self._v[a:b].copy(),
            index=self._windows,
            segment=self._segment,
            first_in_segment=self._emitted_in_segment == 0,
            final=final,
            next_start=next_start,
            pre_timestamps=self._t[c:a].copy(),
            pre_values=self._v[c:a].copy(),
        )
        self._windows += 1
        self._emitted_in_segment += 1
        return w

    def _trim(self) -> None:
        """Keep the next window's start (and context), and the last ``window`` samples (for flush)."""
        drop = max(0, min(self._next, self._t.shape[0] - self.window) - self.context)
        if drop > 0:
            self._t = self._t[drop:]
            self._v = self._v[drop:]
            self._next -= drop
            self._covered -= drop

    def _end_segment(self) -> list[Event]:
        out: list[Event] = []
        n = self._t.shape[0]
        if n > self._covered:
            a = max(0, n - self.window)
            if n - a >= self.min_samples:
                out.append(self._make(a, n, final=True, next_start=n - a))
            else:
                first_new = max(self._covered, 0)
                out.append(Discarded(float(self._t[first_new]), float(self._t[-1]), n - first_new))
        self._t = np.empty(0)
        self._v = None if self._v is None else self._v[:0]
        self._next = 0
        self._covered = 0
        self._emitted_in_segment = 0
        if n:
            self._segment += 1
        return out

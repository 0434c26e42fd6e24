"""What a stream's timestamps say: missing samples, clock jumps, and the rate it really has.

Plain numpy, no clock of its own: everything is judged on the stream's timestamps.

* A **gap** is a forward step longer than 1.5 sampling periods: samples that never arrived.
* A **clock jump** is a step back in time, or a repeated timestamp. Nothing is missing then:
  the sender's clock moved. Jumps are counted apart from gaps, never as missing samples.
  The timeline the stream had before a backward jump is remembered for ``jump_memory``
  seconds of stream time: a forward step that lands back on it is the clock returning (a
  second jump, not a gap); only a step beyond it counts as missing samples.
* The **measured rate** is 1 / the median interval between consecutive timestamps over the
  last ``window`` seconds: a gap or a late chunk does not move it, a sender that streams at
  another rate than it declares does.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hri_physio_bridge.ring_buffer import Gap

#: A forward step longer than this many periods is a gap.
GAP_PERIODS = 1.5


@dataclass(frozen=True)
class ClockJump:
    """The stream's clock moved: ``t_after`` follows ``t_before`` but is not one period later."""

    t_before: float
    t_after: float
    kind: str  # "backward", "repeated" or "returned" (forward, back onto the earlier timeline)

    @property
    def size(self) -> float:
        return self.t_after - self.t_before

    def describe(self) -> str:
        if self.kind == "repeated":
            return f"timestamp t={self.t_after:.4f} repeated"
        if self.kind == "returned":
            return (f"timestamps jumped forward {self.size:.3f} s at t={self.t_before:.4f}, back onto "
                    "the timeline they had before an earlier backward jump")
        return f"timestamps jumped back {-self.size:.3f} s at t={self.t_before:.4f} (to t={self.t_after:.4f})"


class TimelineCheck:
    """Finds gaps and clock jumps in consecutive chunks of one stream (``rate`` 0: jumps only)."""

    def __init__(self, rate: float, jump_memory: float = 30.0) -> None:
        self.rate = float(rate)
        self.jump_memory = jump_memory
        self.last: float | None = None  # the last timestamp seen
        self._behind = 0.0  # how far the timeline is behind the one it had before backward jumps
        self._behind_until = -math.inf  # stream time until which that earlier timeline is remembered

    def check(self, timestamps: np.ndarray) -> tuple[list[Gap], list[ClockJump]]:
        """The gaps and jumps before and inside this chunk (timestamps in arrival order)."""
        ts = np.asarray(timestamps, dtype=np.float64)
        if ts.size == 0:
            return [], []
        seq = ts if self.last is None else np.concatenate([[self.last], ts])
        self.last = float(ts[-1])
        steps = np.diff(seq)
        if self.rate <= 0:  # irregular: only time running backwards is suspicious
            return [], [ClockJump(float(seq[i]), float(seq[i + 1]), "backward")
                        for i in np.flatnonzero(steps < 0)]
        period = 1.0 / self.rate
        if steps.size == 0 or (steps.min() > 0 and steps.max() <= GAP_PERIODS * period):
            return [], []  # the usual case: every step about one period
        gaps: list[Gap] = []
        jumps: list[ClockJump] = []
        for i in np.flatnonzero((steps <= 0) | (steps > GAP_PERIODS * period)):
            before, after, step = float(seq[i]), float(seq[i + 1]), float(steps[i])
            if before > self._behind_until:
                self._behind = 0.0  # a backward jump long ago: its timeline is the timeline now
            if step == 0:
                jumps.append(ClockJump(before, after, "repeated"))
            elif step < 0:
                self._behind += before + period - after
                self._behind_until = after + self.jump_memory
                jumps.append(ClockJump(before, after, "backward"))
            elif self._behind > 0:
                self._return(before, after, step, period, gaps, jumps)
            else:
                gaps.append(_gap(before, after, before + period, period, self.rate))
        return gaps, jumps

    def _return(self, before: float, after: float, step: float, period: float,
                gaps: list[Gap], jumps: list[ClockJump]) -> None:
        """A forward step while behind the earlier timeline: the clock returning, maybe past it."""
        jumps.append(ClockJump(before, after, "returned"))
        beyond = step - self._behind  # how far past the earlier timeline's next sample, plus a period
        if beyond > GAP_PERIODS * period:  # back, and samples are missing after that
            gaps.append(_gap(before, after, before + self._behind + period, period, self.rate))
            self._behind = 0.0
            return
        self._behind = max(0.0, self._behind - (step - period))
        if self._behind < 0.5 * period:
            self._behind = 0.0


def _gap(before: float, after: float, first_missing: float, period: float, rate: float) -> Gap:
    missing = round((after - first_missing) * rate)
    return Gap(first_missing, after - period, missing, "no samples received", t_before=before, t_after=after)


class RateMeter:
    """The rate a stream really has: 1 / median interval between its timestamps, last ``window`` s.

    :attr:`rate` is None until ``min_span`` seconds of timestamps are in. Call :meth:`reset`
    when the timeline breaks (a clock jump, a reconnect): intervals across it mean nothing.
    Adding a chunk only keeps it; the intervals are worked out when the rate is asked for.
    """

    def __init__(self, window: float = 10.0, min_span: float = 5.0) -> None:
        if not 0 < min_span <= window:
            raise ValueError(f"need 0 < min_span <= window, got {min_span}, {window}")
        self.window, self.min_span = window, min_span
        np.median(np.ones(3))  # its first call loads numpy code for ~20 ms: at start, not mid-stream
        self._chunks: deque[np.ndarray] = deque()  # consecutive timestamps, oldest first

    def reset(self) -> None:
        self._chunks.clear()

    def add(self, timestamps: np.ndarray) -> None:
        ts = np.asarray(timestamps, dtype=np.float64)
        if ts.size == 0:
            return
        self._chunks.append(ts)
        newest = float(ts[-1])
        while len(self._chunks) > 1 and float(self._chunks[1][0]) <= newest - self.window:
            self._chunks.popleft()

    @property
    def span(self) -> float:
        return float(self._chunks[-1][-1] - self._chunks[0][0]) if self._chunks else 0.0

    @property
    def rate(self) -> float | None:
        if self.span < self.min_span:
            return None
        steps = np.diff(np.concatenate(self._chunks))
        steps = steps[steps > 0]
        if steps.size == 0:
            return None
        return float(1.0 / np.median(steps))


class ClockOffsetTrack:
    """The clock offsets measured for one input (LSL's time correction, s), summed up for a status.

    ``applied``: the input adds them to its timestamps (``sync=1``); otherwise they are measured only,
    to tell how far the sender's clock is from ours. ``span_s`` (largest minus smallest) is how far the
    correction moved during the stream: a move of a sampling period or more between two samples would
    show as a gap or a clock jump of its own.
    """

    def __init__(self, applied: bool) -> None:
        self.applied = applied
        self.count = 0
        self.first = self.last = math.nan
        self.low, self.high = math.inf, -math.inf

    def add(self, offset: float | None) -> None:
        """One measurement (None or non-finite: none this time)."""
        if offset is None or not math.isfinite(offset):
            return
        if self.count == 0:
            self.first = offset
        self.count += 1
        self.last = offset
        self.low, self.high = min(self.low, offset), max(self.high, offset)

    def as_dict(self) -> dict[str, object]:
        def seconds(value: float) -> float | None:
            return round(value, 6) if math.isfinite(value) else None

        return {"applied": self.applied, "measurements": self.count, "offset_s": seconds(self.last),
                "first_s": seconds(self.first), "min_s": seconds(self.low), "max_s": seconds(self.high),
                "span_s": seconds(self.high - self.low) if self.count else None}

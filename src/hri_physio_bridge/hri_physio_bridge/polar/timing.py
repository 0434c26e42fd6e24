"""Per-sample times, in integer nanoseconds: PMD frames on device time, beats on host arrival.

A PMD frame carries the device time ``T`` of its LAST sample only. :class:`FrameTimer` gives every
sample a time:

- first frame (and after a reset or a clock jump): samples 1/fs apart, back from ``T``;
- later frames: ``T - T_prev`` spread over the frame's ``n`` samples, the last one getting ``T``
  exactly (the device's clock, not the nominal rate, decides the spacing);
- a span longer than ``n`` samples by at least half a sample = frames were lost (BLE has no
  counter): nominal spacing back from ``T`` and a gap report (how many samples, from when to when);
- ``T`` equal to, just before or (by less than 1 ns a sample) after ``T_prev``: a duplicate or
  reordered frame, dropped and counted;
- a device time that jumps by more than the host's own elapsed time allows (a reset clock, a
  clock set by another app): a clock jump, timing restarts from this frame.

Heart-rate RR intervals (and OH1 PPI) have no device time: :class:`BeatTimer` chains the intervals
and keeps the last beat no later than the notification's host arrival (it cannot have happened
after it), re-anchoring at the arrival when the chain runs ahead of it or falls far behind.

A float64 near 6e17 ns has ~128 ns resolution, so everything here is ``int``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

NS = 1_000_000_000


def _div_round(numerator: int, denominator: int) -> int:
    """``round(numerator / denominator)`` for integers (halves up), without floats."""
    if denominator < 0:
        numerator, denominator = -numerator, -denominator
    q, _r = divmod(2 * numerator + denominator, 2 * denominator)
    return q


@dataclass(frozen=True)
class FramePlacement:
    """Where a frame's samples go on the device clock, and what the timer concluded."""

    #: first | ok | gap | short | duplicate | backward | clock_jump
    kind: str
    #: Device time of each sample (empty when the frame is dropped).
    device_ns: list[int] = field(default_factory=list)
    #: Samples estimated missing before this frame (``gap``).
    missing: int = 0
    #: Device times of the first and last missing sample (``gap``).
    gap_from_ns: int = 0
    gap_to_ns: int = 0

    @property
    def dropped(self) -> bool:
        return self.kind in ("duplicate", "backward")


@dataclass
class TimingCounts:
    """What a stream's timers found and corrected; one per stream, kept across reconnects."""

    gaps: int = 0  # frames that came after lost ones
    missing_samples: int = 0  # samples estimated lost in those gaps
    duplicates: int = 0  # frames dropped: the previous frame's device time again
    backward: int = 0  # frames dropped: before the previous one, or too close after it
    short_frames: int = 0  # frames closer than their samples' span (times spread evenly)
    clock_jumps: int = 0  # timing restarted: the device time jumped
    invalid_intervals: int = 0  # beat intervals <= 0, skipped
    reanchored_beats: int = 0  # beat chains re-anchored at the notification's arrival
    clamped_beats: int = 0  # beats moved later to keep beat times increasing

    @property
    def dropped_frames(self) -> int:
        return self.duplicates + self.backward


class FrameTimer:
    """Per-sample device times for one PMD stream of nominal rate ``rate_hz``."""

    def __init__(self, rate_hz: float, *, jump_tolerance_ns: int = 2 * NS,
                 counts: TimingCounts | None = None) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate must be > 0 Hz, got {rate_hz}")
        self.rate_hz = rate_hz
        #: Numerator/denominator of the sample period in ns, so 1/fs stays exact for whole rates.
        self._period_num, self._period_den = (
            (NS, int(rate_hz))
            if float(rate_hz).is_integer()
            else (round(NS * 1_000_000 / rate_hz), 1_000_000)
        )
        self.jump_tolerance_ns = jump_tolerance_ns
        self.counts = counts if counts is not None else TimingCounts()
        self._last_t: int | None = None
        self._last_arrival: int | None = None

    def reset(self) -> None:
        """Forget the previous frame (a reconnect): the next frame is placed like a first one."""
        self._last_t = None
        self._last_arrival = None

    def _span(self, samples: int) -> int:
        """``samples`` sample periods in ns, rounded."""
        return _div_round(samples * self._period_num, self._period_den)

    def _nominal(self, t: int, n: int) -> list[int]:
        return [t - self._span(n - 1 - i) for i in range(n)]

    def place(self, timestamp_ns: int, n: int, arrival_ns: int) -> FramePlacement:
        """Times for a frame of ``n`` samples whose last sample is at device time ``timestamp_ns``."""
        if n < 1:
            raise ValueError(f"a frame needs at least one sample, got {n}")
        c = self.counts
        last, last_arrival = self._last_t, self._last_arrival
        if last is None or last_arrival is None:
            return self._accept(
                FramePlacement("first", self._nominal(timestamp_ns, n)), timestamp_ns, arrival_ns
            )
        span = timestamp_ns - last
        host_span = arrival_ns - last_arrival
        if span < n and -span <= self.jump_tolerance_ns:
            if span == 0:
                c.duplicates += 1
                return FramePlacement("duplicate")
            c.backward += 1  # before the previous frame, or too close after it to hold n samples
            return FramePlacement("backward")
        if span < 0 or span - max(host_span, 0) > self.jump_tolerance_ns:
            c.clock_jumps += 1
            return self._accept(
                FramePlacement("clock_jump", self._nominal(timestamp_ns, n)), timestamp_ns, arrival_ns
            )
        half = self._span(1) // 2
        if span > self._span(n) + half:
            missing = max(1, _div_round(span * self._period_den, self._period_num) - n)
            times = self._nominal(timestamp_ns, n)
            c.gaps += 1
            c.missing_samples += missing
            placement = FramePlacement("gap", times, missing, last + self._span(1), times[0] - self._span(1))
            return self._accept(placement, timestamp_ns, arrival_ns)
        kind = "short" if span < self._span(n) - half else "ok"
        if kind == "short":
            c.short_frames += 1
        times = [last + _div_round((i + 1) * span, n) for i in range(n)]
        return self._accept(FramePlacement(kind, times), timestamp_ns, arrival_ns)

    def _accept(self, placement: FramePlacement, timestamp_ns: int, arrival_ns: int) -> FramePlacement:
        self._last_t = timestamp_ns
        self._last_arrival = arrival_ns
        return placement


class BeatTimer:
    """End times (host ns) of intervals reported without device time (RR, PPI).

    ``max_lag_ns``: how far the last chained beat may fall behind the arrival before the chain is
    thought broken (beats not reported) and re-anchored at the arrival.
    """

    def __init__(self, *, max_lag_ns: int = 3 * NS, min_step_ns: int = 1_000_000,
                 counts: TimingCounts | None = None) -> None:
        self.max_lag_ns = max_lag_ns
        self.min_step_ns = min_step_ns
        self.counts = counts if counts is not None else TimingCounts()
        self._last: int | None = None

    def reset(self) -> None:
        self._last = None

    def place(self, intervals_ns: list[int], arrival_ns: int) -> list[int]:
        """One end time per interval (oldest first); intervals <= 0 are skipped and counted."""
        valid = [i for i in intervals_ns if i > 0]
        self.counts.invalid_intervals += len(intervals_ns) - len(valid)
        if not valid:
            return []
        anchored = [arrival_ns - sum(valid[k + 1 :]) for k in range(len(valid))]
        if self._last is None:
            times = anchored
        else:
            chained, t = [], self._last
            for interval in valid:
                t += interval
                chained.append(t)
            if chained[-1] > arrival_ns or chained[-1] < arrival_ns - self.max_lag_ns:
                self.counts.reanchored_beats += 1
                times = anchored
            else:
                times = chained
        out, previous = [], self._last
        for t in times:
            if previous is not None and t < previous + self.min_step_ns:
                t = previous + self.min_step_ns
                self.counts.clamped_beats += 1
            out.append(t)
            previous = t
        self._last = out[-1]
        return out

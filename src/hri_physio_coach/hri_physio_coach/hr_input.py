"""Heart-rate input of the coach: validity, the rule-update window, recent values, timeouts.

Two clocks meet here. Windows such as "the last 30 s" and the data timeout are measured on the
coach's clock (the clock the scenario runs on). A rule update's window holds the samples *taken*
in it: each sample's source stamp (another clock, e.g. LSL) is mapped onto the coach's clock with
the offset of the fastest-delivered sample (a sample never arrives before it was taken, so
``source - receipt`` is at most the offset and its largest value is the best estimate). So a
window has the same samples however late the transport delivers them, and
:meth:`HeartRateMonitor.window_complete` tells a rule update whether the last of them has come.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass

from hri_physio_coach.gates import NO_HR_DATA, SIGNAL_FLAGGED, TOO_FEW_SAMPLES, Gate


@dataclass(frozen=True)
class BufferStats:
    """What a rule update sees: the mean of the valid samples and how many were (in)valid."""

    mean: float | None
    n_valid: int
    n_invalid: int  # non-finite or outside the plausible range
    n_flagged: int  # marked unreliable by the source

    @property
    def n_total(self) -> int:
        return self.n_valid + self.n_invalid + self.n_flagged

    @property
    def bad_fraction(self) -> float:
        return (self.n_invalid + self.n_flagged) / self.n_total if self.n_total else 0.0

    def as_dict(self) -> dict[str, object]:
        return {"hr_mean": self.mean, "n_valid": self.n_valid, "n_invalid": self.n_invalid,
                "n_flagged": self.n_flagged}


#: Kinds of samples in the rule-update window.
VALID, INVALID, FLAGGED = "valid", "invalid", "flagged"
#: A source clock that falls back by more than this (s) against the arrivals was restarted (a strap
#: reconnected, a replay looped): the mapping onto the coach's clock starts again. Samples whose own
#: stamps carry on from the last one (at most this far after it) are the same timeline delivered late
#: (a stalled transport catching up), not a restart, unless they come more than
#: :data:`MAX_DELIVERY_DELAY` late: then the coach's own clock jumped (sim time started, a replay
#: restarted).
CLOCK_RESET = 5.0
MAX_DELIVERY_DELAY = 60.0
#: Sample intervals remembered to know when the next sample is due.
INTERVALS_KEPT = 9


class HeartRateMonitor:
    """Collects HR samples; tells a rule update whether the signal can be trusted."""

    def __init__(self, valid_min: float = 30.0, valid_max: float = 230.0, timeout: float = 10.0,
                 min_valid: int = 10, max_bad_fraction: float = 0.5, maxlen: int = 1000,
                 recent_window: float = 30.0) -> None:
        self.valid_min, self.valid_max = valid_min, valid_max
        self.timeout = timeout
        self.min_valid = min_valid
        self.max_bad_fraction = max_bad_fraction
        self.recent_window = recent_window
        self._window: deque[tuple[float, str, float]] = deque(maxlen=maxlen)  # (taken, kind, bpm)
        self._recent: deque[tuple[float, float]] = deque()
        self._calibration: list[tuple[float, float]] | None = None  # (taken, bpm) of valid samples
        self.clock_offset: float | None = None  # source clock minus coach clock (fastest sample)
        self._last_source: float | None = None  # the last sample's own stamp
        self.newest_sample: float | None = None  # when the newest sample was taken (coach clock)
        self._intervals: deque[float] = deque(maxlen=INTERVALS_KEPT)
        self.last_receipt: float | None = None
        self.last_hr: float | None = None
        self.lost = False
        self.silent_since: float | None = None  # while lost: time of the last sample (or start)

    def is_valid(self, hr: float) -> bool:
        return math.isfinite(hr) and self.valid_min <= hr <= self.valid_max

    def sample_time(self, receipt_time: float, source_t: float | None) -> float:
        """When a sample received at ``receipt_time`` was taken, on the coach's clock."""
        if source_t is None or not math.isfinite(source_t):
            return receipt_time
        lead = source_t - receipt_time
        last, self._last_source = self._last_source, source_t
        carries_on = last is not None and 0.0 < source_t - last <= CLOCK_RESET
        late = math.inf if self.clock_offset is None else self.clock_offset - lead  # vs the fastest
        restarted = CLOCK_RESET < late < math.inf and (not carries_on or late > MAX_DELIVERY_DELAY)
        if restarted:
            self.newest_sample = None  # another timeline: intervals and order start again
            self._intervals.clear()
        if self.clock_offset is None or restarted or lead > self.clock_offset:
            self.clock_offset = lead
        return source_t - self.clock_offset

    def add(self, receipt_time: float, hr: float, flagged: bool = False,
            source_t: float | None = None) -> bool:
        """Add one sample (``source_t``: its own stamp); True when it is valid (counted in the mean)."""
        self.last_receipt = receipt_time
        taken = self.sample_time(receipt_time, source_t)
        if self.newest_sample is None or taken > self.newest_sample:
            if self.newest_sample is not None:
                self._intervals.append(taken - self.newest_sample)
            self.newest_sample = taken
        if flagged:
            self._window.append((taken, FLAGGED, hr))
            return False
        if not self.is_valid(hr):
            self._window.append((taken, INVALID, hr))
            return False
        self._window.append((taken, VALID, hr))
        self.last_hr = hr
        self._recent.append((receipt_time, hr))
        if self._calibration is not None:
            self._calibration.append((taken, hr))
        return True

    @property
    def sample_interval(self) -> float | None:
        """The source's usual time between samples (median of the last few), None before two."""
        return statistics.median(self._intervals) if self._intervals else None

    def window_complete(self, end: float) -> bool:
        """Whether every sample taken before ``end`` has arrived (as far as the source's rhythm tells).

        True when a sample taken at or after ``end`` arrived, when the next one is due at or after
        ``end``, or when there is nothing to wait for (no samples yet, data lost).
        """
        if self.lost or self.newest_sample is None:
            return True
        interval = self.sample_interval
        return self.newest_sample >= end or (interval is not None and self.newest_sample + interval >= end)

    def stats(self, start: float = -math.inf, end: float = math.inf) -> BufferStats:
        """The window's samples taken in ``[start, end)``."""
        counts = {VALID: 0, INVALID: 0, FLAGGED: 0}
        total = 0.0
        for taken, kind, hr in self._window:
            if start <= taken < end:
                counts[kind] += 1
                if kind == VALID:
                    total += hr
        n = counts[VALID]
        return BufferStats(total / n if n else None, n, counts[INVALID], counts[FLAGGED])

    def clear(self, before: float = math.inf) -> None:
        """Forget the samples taken before ``before`` (default: all)."""
        kept = [entry for entry in self._window if entry[0] >= before]
        self._window.clear()
        self._window.extend(kept)

    def take(self, start: float = -math.inf, end: float = math.inf) -> BufferStats:
        """The statistics of the samples taken in ``[start, end)``; every sample before ``end`` is dropped."""
        stats = self.stats(start, end)
        self.clear(end)
        return stats

    def gate(self, stats: BufferStats, now: float) -> Gate | None:
        """Why a rule update must not adapt on ``stats`` (None: it may)."""
        if self.lost:
            since = self.silent_since if self.silent_since is not None else now
            return Gate(NO_HR_DATA, f"no heart-rate data for {now - since:.0f} s: adaptation paused")
        if stats.n_valid < self.min_valid or stats.mean is None:
            return Gate(TOO_FEW_SAMPLES, f"too few valid HR samples: {stats.n_valid} < {self.min_valid}")
        if stats.bad_fraction > self.max_bad_fraction:
            return Gate(SIGNAL_FLAGGED,
                        f"signal flagged: {stats.n_invalid + stats.n_flagged} of {stats.n_total} samples "
                        f"invalid or flagged (> {self.max_bad_fraction:.0%})")
        return None

    def recent_mean(self, now: float, window: float | None = None) -> float | None:
        """Mean of the valid samples received in the last ``window`` seconds."""
        window = self.recent_window if window is None else window
        while self._recent and self._recent[0][0] < now - max(window, self.recent_window):
            self._recent.popleft()
        values = [hr for t, hr in self._recent if t >= now - window]
        return sum(values) / len(values) if values else None

    def check_timeout(self, now: float, started_at: float) -> str | None:
        """``"lost"`` when data stopped for longer than the timeout, ``"resumed"`` when it is back."""
        last = self.last_receipt if self.last_receipt is not None else started_at
        if not self.lost and now - last > self.timeout:
            self.lost, self.silent_since = True, last
            return "lost"
        if self.lost and self.last_receipt is not None and now - self.last_receipt <= self.timeout:
            self.lost, self.silent_since = False, None
            return "resumed"
        return None

    # --- calibration ---------------------------------------------------------------------------
    def start_calibration(self) -> None:
        self._calibration = []

    def finish_calibration(self, start: float = -math.inf, end: float = math.inf) -> list[float]:
        """The valid samples taken in ``[start, end)`` since :meth:`start_calibration` (by when taken,
        as a rule update's window: a sample that arrives late still counts, one taken before does not)."""
        samples, self._calibration = self._calibration or [], None
        return [hr for taken, hr in samples if start <= taken < end]

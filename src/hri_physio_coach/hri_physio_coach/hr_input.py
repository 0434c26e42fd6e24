"""Heart-rate input of the coach: validity, the rule-update buffer, recent values, timeouts.

Samples are kept with their *receipt* time on the coach's clock (the clock the scenario runs
on) next to their source time: windows such as "the last 30 s" and the data timeout are
measured on the coach's clock, because source timestamps come from another clock (LSL).
"""

from __future__ import annotations

import math
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
        self._valid: deque[float] = deque(maxlen=maxlen)
        self._invalid = 0
        self._flagged = 0
        self._recent: deque[tuple[float, float]] = deque()
        self._calibration: list[float] | None = None
        self.last_receipt: float | None = None
        self.last_hr: float | None = None
        self.lost = False
        self.silent_since: float | None = None  # while lost: time of the last sample (or start)

    def is_valid(self, hr: float) -> bool:
        return math.isfinite(hr) and self.valid_min <= hr <= self.valid_max

    def add(self, receipt_time: float, hr: float, flagged: bool = False) -> bool:
        """Add one sample; True when it is valid (counted in the mean)."""
        self.last_receipt = receipt_time
        if flagged:
            self._flagged += 1
            return False
        if not self.is_valid(hr):
            self._invalid += 1
            return False
        self._valid.append(hr)
        self.last_hr = hr
        self._recent.append((receipt_time, hr))
        if self._calibration is not None:
            self._calibration.append(hr)
        return True

    def stats(self) -> BufferStats:
        mean = sum(self._valid) / len(self._valid) if self._valid else None
        return BufferStats(mean, len(self._valid), self._invalid, self._flagged)

    def clear(self) -> None:
        self._valid.clear()
        self._invalid = self._flagged = 0

    def take(self) -> BufferStats:
        """The buffer's statistics, then an empty buffer (every rule update clears it)."""
        stats = self.stats()
        self.clear()
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

    def finish_calibration(self) -> list[float]:
        samples, self._calibration = self._calibration or [], None
        return samples

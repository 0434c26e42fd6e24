"""The sample rate a PMD stream really has, measured from its frames' device times and sample counts.

Some firmware announces one rate and samples at another (a Verity Sense before 2.1.0 announces
PPG at 135 Hz and sends 55 Hz: 42 samples per 762 ms; an OH1 announces 130 Hz for 135 Hz). Timed
at the announced rate, every frame would look like a gap and every timestamp would be wrong.

Each pair of consecutive frames gives one measurement: the later frame's sample count over the
device time between the two frames' last samples. A lost frame makes one pair's rate low (about
half), a duplicate or reordered frame gives no pair; a wrong announced rate moves every pair the
same way. So :class:`RateCheck` takes the median of the first ``pairs`` pairs. The announced
rate stands when a frame timed at it would be off by less than a quarter of a sample (the timer
calls half a sample a gap): ``|median / announced - 1| * samples per frame < 1/4`` (0.34 % for an
H10's 73-sample ECG frames, which measure 130.05 Hz: 0.035 %). Otherwise the effective rate is
the total of samples over the total of device time of the pairs within ``tolerance`` of the
median, given as the nearest rate Polar sensors are known to sample at when that one passes the
same quarter-sample test, else as measured (to 0.01 Hz).
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass

NS = 1_000_000_000


@dataclass(frozen=True)
class RateVerdict:
    announced: float  # Hz, what the device said (after known quirks)
    measured: float  # Hz, from the device times and sample counts (the announced rate if no pair)
    rate: float  # Hz, what the stream uses from now on
    pairs: int  # frame pairs measured

    @property
    def corrected(self) -> bool:
        return self.rate != self.announced


class RateCheck:
    """Collects a stream's first frames; :meth:`add` gives the verdict once enough pairs are seen."""

    def __init__(
        self,
        announced: float,
        *,
        pairs: int = 4,
        tolerance: float = 0.01,  # pairs this far from the median are not losses
        known_rates: Sequence[float] = (),
    ) -> None:
        if not announced > 0:
            raise ValueError(f"announced rate must be > 0 Hz, got {announced}")
        self.announced = float(announced)
        self.pairs_needed = pairs
        self.tolerance = tolerance
        self.known_rates = tuple(float(r) for r in known_rates)
        self._last_ns: int | None = None
        self._pairs: list[tuple[int, int]] = []  # (samples, device ns) of each measured pair

    def add(self, timestamp_ns: int, samples: int) -> RateVerdict | None:
        """One frame (device time of its last sample, its sample count); the verdict when due."""
        last = self._last_ns
        if last is not None and timestamp_ns > last:
            self._pairs.append((samples, timestamp_ns - last))
        if last is None or timestamp_ns > last:
            self._last_ns = timestamp_ns
        if len(self._pairs) >= self.pairs_needed:
            return self.verdict()
        return None

    def verdict(self) -> RateVerdict:
        """The verdict on what has been seen so far (fewer pairs than asked: the rate stands)."""
        if not self._pairs:
            return RateVerdict(self.announced, self.announced, self.announced, 0)
        rates = [n * NS / span for n, span in self._pairs]
        median = statistics.median(rates)
        samples = statistics.median(n for n, _ in self._pairs)
        if len(self._pairs) < min(3, self.pairs_needed) or self._fits(self.announced, median, samples):
            return RateVerdict(self.announced, median, self.announced, len(self._pairs))
        pairs = zip(self._pairs, rates, strict=True)
        agreeing = [(n, span) for (n, span), r in pairs if abs(r / median - 1.0) <= self.tolerance]
        measured = sum(n for n, _ in agreeing) * NS / sum(span for _, span in agreeing)
        known = [r for r in self.known_rates if self._fits(r, measured, samples)]
        rate = min(known, key=lambda r: abs(r - measured)) if known else round(measured, 2)
        return RateVerdict(self.announced, measured, rate, len(self._pairs))

    @staticmethod
    def _fits(rate: float, measured: float, samples: float) -> bool:
        """Frames of ``samples`` timed at ``rate`` are off by less than a quarter sample."""
        return abs(measured / rate - 1.0) * samples < 0.25

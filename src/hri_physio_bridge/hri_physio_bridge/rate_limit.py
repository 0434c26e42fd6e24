"""Rate-limited reports: count every occurrence, log at most one line per kind per period.

A stream that goes bad sends bad messages (or overflows) many times a second;
one log line per occurrence buries everything else. :class:`RateLimitedLog`
counts each occurrence and writes the first one at once, then at most one line
per kind every ``period`` seconds, saying how many occurrences it stands for.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable

#: Seconds between two lines of the same kind.
DEFAULT_PERIOD = 5.0


class RateLimitedLog:
    """At most one line per kind every ``period`` seconds, each with the count it summarises."""

    def __init__(
        self,
        emit: Callable[[str], None],
        period: float = DEFAULT_PERIOD,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.emit = emit
        self.period = float(period)
        self._monotonic = monotonic
        self.totals: Counter[str] = Counter()
        self._pending: Counter[str] = Counter()
        self._last: dict[str, float] = {}
        self._lock = threading.Lock()

    def report(self, kind: str, text: str, unit: str, count: int = 1) -> bool:
        """Count ``count`` occurrences of ``kind``; log ``text`` if the kind has been quiet long enough.

        ``unit`` names what is counted, e.g. "message(s) rejected". Returns whether a line was written.
        """
        with self._lock:
            self.totals[kind] += count
            self._pending[kind] += count
            now = self._monotonic()
            if now - self._last.get(kind, -math.inf) < self.period:
                return False
            first = kind not in self._last
            self._last[kind] = now
            pending = self._pending.pop(kind)
            total = self.totals[kind]
        if first:
            suffix = f"{total} {unit} so far; repeats are summarised at most every {self.period:g} s"
        else:
            suffix = f"{pending} {unit} since the last report, {total} so far"
        self.emit(f"{text} ({suffix})")
        return True

"""Noticing that the coach is not alone on its topics (no rclpy: the node feeds these).

Two sessions started on one ROS domain share topics: two coaches send robot commands and
events, two launchers publish ``/clock``. The coach must notice and stop (issue 16), and it
must not mistake a publisher that is gone but still listed in the ROS graph (a crashed
process stays there for the DDS lease time) for a live one. So both checks here look at
*messages*, not at the graph:

- :class:`EchoFilter`: the coach hears its own events back on the topic it publishes them
  on; a message it did not send comes from someone else.
- :class:`SourceWatch`: on ``/clock`` one publisher may replace another (a launcher or a
  replay restarted), but two that take turns are two clocks.
"""

from __future__ import annotations

import contextlib
import threading
from collections import Counter, deque
from collections.abc import Hashable

#: Conflict kinds in the coach's ``conflict`` event.
SECOND_COACH = "second_coach"
SECOND_CLOCK = "second_clock"


class EchoFilter:
    """Tells our own messages, heard back on a topic we publish on, from anybody else's.

    :meth:`sent` before publishing, :meth:`is_foreign` for every message received. At most
    ``capacity`` payloads wait for their echo (an echo lost to a full queue is forgotten in
    time, so it can only ever hide a foreign message, never invent one).
    """

    def __init__(self, capacity: int = 10_000) -> None:
        self.capacity = capacity
        self._pending: Counter[str] = Counter()
        self._order: deque[str] = deque()
        self._lock = threading.Lock()
        self.foreign = 0

    def sent(self, payload: str) -> None:
        with self._lock:
            self._pending[payload] += 1
            self._order.append(payload)
            while len(self._order) > self.capacity:
                self._forget(self._order.popleft())

    def is_foreign(self, payload: str) -> bool:
        """True when ``payload`` is not one we sent and have not heard back yet."""
        with self._lock:
            if self._pending[payload] > 0:
                self._forget(payload)
                with contextlib.suppress(ValueError):  # already dropped from the order by capacity
                    self._order.remove(payload)
                return False
            del self._pending[payload]
            self.foreign += 1
            return True

    def _forget(self, payload: str) -> None:
        self._pending[payload] -= 1
        if self._pending[payload] <= 0:
            del self._pending[payload]


class SourceWatch:
    """Notices two publishers taking turns on one topic.

    Feed it the publisher of every message (its endpoint id). One source replacing another
    is fine; a source that publishes again after another one took over means both are alive.
    """

    def __init__(self) -> None:
        self.current: Hashable | None = None
        self._earlier: set[Hashable] = set()
        self.sources = 0

    def seen(self, source: Hashable) -> bool:
        """Record one message from ``source``; True when two sources are taking turns."""
        if source == self.current:
            return False
        if self.current is not None:
            self._earlier.add(self.current)
        back = source in self._earlier
        if not back:
            self.sources += 1
        self.current = source
        return back

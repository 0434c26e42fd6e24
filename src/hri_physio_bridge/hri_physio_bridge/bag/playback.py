"""Playback scheduling: when each message (and each ``/clock`` tick) goes out.

Pure logic on an injected clock: ``now()`` returns wall seconds (monotonic), ``sleep(s)``
waits. Message ``k`` of a pass is due at ``wall_start + (t_k - t_origin) / rate``;
``rate == 0`` means no waiting at all (as fast as possible, order kept). Late messages are
sent at once, never dropped or reordered, so a slow publisher stretches the replay instead
of changing it.

``/clock``: ticks every ``clock_step`` of *bag* time from the first played message up to
each message's time, so a node on sim time sees its clock advance in steps no larger
than ``clock_step`` (rclpy timers skip periods when time jumps by more than their period).
On ``loop``, clock time keeps increasing (each pass continues the previous pass's tick grid,
one step after its last tick) so sim-time nodes never see time run backwards; the messages
themselves are sent unchanged.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from hri_physio_bridge.bag.reader import BagMessage

NS = 1_000_000_000


@dataclass
class PlaybackOptions:
    rate: float = 1.0
    loop: bool = False
    clock_step_ns: int | None = None  # None: no /clock
    max_sleep: float = 0.05  # wake up this often to notice a stop request

    def __post_init__(self) -> None:
        if self.rate < 0:
            raise ValueError(f"rate must be >= 0 (0 = as fast as possible), got {self.rate}")
        if self.clock_step_ns is not None and self.clock_step_ns <= 0:
            raise ValueError(f"clock step must be positive, got {self.clock_step_ns} ns")


@dataclass
class PlaybackStats:
    passes: int = 0
    messages: int = 0
    clock_ticks: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    max_lateness: float = 0.0  # seconds a message went out after its due time
    stopped: bool = False


class Player:
    """Send ``messages()`` (called once per pass) through ``publish`` on schedule."""

    def __init__(
        self,
        messages: Callable[[], Iterable[BagMessage]],
        publish: Callable[[BagMessage], None],
        options: PlaybackOptions,
        *,
        publish_clock: Callable[[int], None] | None = None,
        now: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        stop: threading.Event | None = None,
    ) -> None:
        if options.clock_step_ns is not None and publish_clock is None:
            raise ValueError("a clock step needs a publish_clock callback")
        self._messages = messages
        self._publish = publish
        self._publish_clock = publish_clock
        self.options = options
        self._now = now
        self._sleep = sleep
        self._stop = stop or threading.Event()
        self.stats = PlaybackStats()

    def _wait_until(self, deadline: float) -> bool:
        """Sleep until ``deadline``; False if stopped meanwhile."""
        while not self._stop.is_set():
            remaining = deadline - self._now()
            if remaining <= 0:
                return True
            self._sleep(min(remaining, self.options.max_sleep))
        return False

    def _due(self, wall0: float, t_ns: int, origin_ns: int) -> float | None:
        if self.options.rate == 0:
            return None
        return wall0 + (t_ns - origin_ns) / NS / self.options.rate

    def run(self) -> PlaybackStats:
        opts = self.options
        step = opts.clock_step_ns
        clock_offset = 0
        while not self._stop.is_set():
            origin: int | None = None
            last_t: int | None = None
            next_tick = 0
            wall0 = self._now()
            sent = 0
            for msg in self._messages():
                if self._stop.is_set():
                    break
                t = msg.log_time_ns
                if origin is None:
                    origin, next_tick = t, t
                if step is not None:
                    while next_tick <= t and not self._stop.is_set():
                        due = self._due(wall0, next_tick, origin)
                        if due is not None and not self._wait_until(due):
                            break
                        assert self._publish_clock is not None
                        self._publish_clock(next_tick + clock_offset)
                        self.stats.clock_ticks += 1
                        next_tick += step
                due = self._due(wall0, t, origin)
                if due is not None:
                    if not self._wait_until(due):
                        break
                    self.stats.max_lateness = max(self.stats.max_lateness, self._now() - due)
                self._publish(msg)
                sent += 1
                last_t = t if last_t is None else max(last_t, t)
                self.stats.messages += 1
                self.stats.per_topic[msg.topic] = self.stats.per_topic.get(msg.topic, 0) + 1
            if self._stop.is_set():
                break
            self.stats.passes += 1
            if not opts.loop or sent == 0:
                break
            assert origin is not None and last_t is not None
            # Continue the tick grid: the next pass's first tick is one step after this one's last.
            clock_offset += (next_tick if step is not None else last_t) - origin
        self.stats.stopped = self._stop.is_set()
        return self.stats

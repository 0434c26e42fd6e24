"""Pacing on an injected clock: wall time, or ROS time (which follows /clock under use_sim_time).

A streamer produces media "due" at clock times and waits for them here. The clock may run at
any speed, stand still (a paused simulation, or no /clock yet) or jump; waits sleep in short
wall-time steps so a faster clock is followed and a stop ends the wait at once.

A clock that moves only in steps (ROS time under sim time: one step per /clock message) comes
with :class:`ClockTicks`, told of each step: a pacer then sleeps until the next step instead of
polling a clock that stands still (which, with a due time just past the current step, meant
sleeping a fraction of a millisecond over and over until the next /clock).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

Clock = Callable[[], float]
#: Sleeps up to the given (wall) seconds; returns True when the wait should end (a stop).
Sleeper = Callable[[float, threading.Event], bool]


def wait_on_event(seconds: float, stop: threading.Event) -> bool:
    return stop.wait(seconds)


#: Longest wait for a clock step (wall s): a stop is seen within it, and so is a clock whose steps
#: were not told (a bound only: steps end the wait).
TICK_WAIT = 0.1


class ClockTicks:
    """Told each time a stepping clock moved (:meth:`tick`, from any thread); a pacer waits for it."""

    def __init__(self) -> None:
        self._moved = threading.Event()
        self.count = 0

    def tick(self) -> None:
        self.count += 1
        self._moved.set()

    def clear(self) -> None:
        self._moved.clear()

    def wait(self, seconds: float) -> bool:
        """Until the next tick since :meth:`clear`, at most ``seconds``; True when it came."""
        return self._moved.wait(seconds)


class Pacer:
    """Waits until an injected clock reaches a time (``sleep``: how to pass time, injectable for tests).

    With ``ticks`` the clock moves only when they tick (sim time), and a wait sleeps until the tick.
    """

    def __init__(self, clock: Clock = time.monotonic, *, poll: float = 0.02,
                 sleep: Sleeper = wait_on_event, ticks: ClockTicks | None = None) -> None:
        self.clock, self.poll, self.sleep, self.ticks = clock, poll, sleep, ticks

    def wait_until(self, due: float, stop: threading.Event) -> bool:
        """Sleep until ``clock() >= due``; False when ``stop`` was set first."""
        while not stop.is_set():
            if self.ticks is not None:
                self.ticks.clear()  # before reading the clock: a step from now on ends the wait below
            remaining = due - self.clock()
            if remaining <= 0:
                return True
            if self.ticks is not None:
                self.ticks.wait(TICK_WAIT)
            elif self.sleep(min(remaining, self.poll), stop):
                return False
        return False


class Schedule:
    """A steady stream of items, each due when the previous ones' durations have passed on the clock.

    When the clock jumps back (a replay restarted) or the producer is more than ``max_lag`` s
    late (no /clock until now, a stalled machine, a slow frame), the schedule restarts from the
    present instead of rushing to catch up; :attr:`resyncs` counts those restarts.
    """

    def __init__(self, pacer: Pacer, *, lead: float = 0.0, max_lag: float = 1.0) -> None:
        self.pacer, self.lead, self.max_lag = pacer, lead, max_lag
        self.resyncs = 0
        self._start: float | None = None
        self._done = 0.0  # clock seconds of items handed out since the start

    def wait_next(self, duration: float, stop: threading.Event) -> bool:
        """Wait until an item of ``duration`` s may be handed out (``lead`` s ahead of its time)."""
        now = self.pacer.clock()
        if self._start is None or now < self._start:
            self._start, self._done = now, 0.0
        due = self._start + self._done - self.lead
        if now - due > self.max_lag:
            self.resyncs += 1
            self._start, self._done = now, 0.0
            due = now - self.lead
        self._done += duration
        return self.pacer.wait_until(due, stop)

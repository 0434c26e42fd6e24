"""Waiting, written once: deadlines on an injected clock, backoff, waiting for consumers.

Every node that opens a stream (receiver, processor, simulator, Polar streamer) and every loop
that polls until a deadline uses these, so a wait is always bounded or stoppable, idle between
polls (no busy loop), and logged at a bounded rate. Opening an input that may not be there yet is
:class:`hri_physio_bridge.streamers.opener.StreamOpener`, built on these. Nothing here imports
rclpy, and nothing here knows streamers (they use this module, not the other way round).
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections.abc import Callable

Clock = Callable[[], float]
#: Sleeps up to the given seconds; returns True when the wait should end early (a stop).
Sleeper = Callable[[float], bool]

DEFAULT_POLL = 0.05


def sleeper_for(stop: threading.Event | None) -> Sleeper:
    """Sleeps on ``stop`` (ended early by a stop) or, without one, plain ``time.sleep``."""
    if stop is not None:
        return stop.wait
    return lambda seconds: (time.sleep(seconds), False)[1]


def wait_until(
    condition: Callable[[], bool],
    timeout: float | None,
    *,
    clock: Clock = time.monotonic,
    stop: threading.Event | None = None,
    poll: float = DEFAULT_POLL,
    sleep: Sleeper | None = None,
) -> bool:
    """Poll ``condition`` every ``poll`` s: True once it holds, False after ``timeout`` or a stop.

    ``timeout`` None waits until the condition holds or the stop. Time comes from ``clock``;
    between polls the thread sleeps on ``stop`` (or ``sleep``), so the wait is idle and a stop
    ends it at once.
    """
    sleep = sleep or sleeper_for(stop)
    deadline = None if timeout is None else clock() + timeout
    while True:
        if condition():
            return True
        if stop is not None and stop.is_set():
            return False
        if deadline is not None:
            remaining = deadline - clock()
            if remaining <= 0:
                return False
            step = min(poll, remaining)
        else:
            step = poll
        if sleep(step):
            return condition()


class Backoff:
    """Delays that grow from ``initial`` to ``maximum`` (x ``factor`` each time) with +-``jitter`` share.

    Jitter keeps several clients that lost the same device from retrying in lockstep.
    """

    def __init__(self, initial: float = 1.0, maximum: float = 30.0, factor: float = 2.0,
                 jitter: float = 0.2, rng: random.Random | None = None) -> None:
        if not 0 < initial <= maximum:
            raise ValueError(f"need 0 < initial <= maximum, got {initial}, {maximum}")
        self.initial, self.maximum, self.factor, self.jitter = initial, maximum, factor, jitter
        self._rng = rng or random.Random()
        self._next = initial
        self.attempts = 0

    def next_delay(self) -> float:
        base = self._next
        self._next = min(self.maximum, self._next * self.factor)
        self.attempts += 1
        spread = base * self.jitter
        return min(self.maximum, max(0.0, base + self._rng.uniform(-spread, spread)))

    def reset(self) -> None:
        self._next = self.initial
        self.attempts = 0


def wait_for_consumers(
    count: Callable[[], int],
    want: int,
    timeout: float,
    *,
    what: str,
    log: logging.Logger,
    clock: Clock = time.monotonic,
    stop: threading.Event | None = None,
    sleep: Sleeper | None = None,
) -> bool:
    """Hold until ``count()`` reaches ``want`` listeners on ``what``; at most ``timeout`` s (0 = no wait).

    Returns True when they are there. On timeout it logs how many of how many listened and
    returns False (the caller starts anyway); a stop returns False quietly.
    """
    if timeout <= 0:
        return count() >= want
    label = "a consumer" if want == 1 else f"{want} consumers"
    log.info(f"waiting up to {timeout:g} s for {label} on {what}")
    if wait_until(lambda: count() >= want, timeout, clock=clock, stop=stop, poll=0.02, sleep=sleep):
        log.info(f"{what} has {label}")
        return True
    if stop is not None and stop.is_set():
        log.info(f"stopped while waiting for {label} on {what}")
        return False
    have = f"only {count()} of {want} consumers" if want > 1 else "no consumer"
    log.warning(f"{have} on {what} after {timeout:g} s; starting anyway")
    return False

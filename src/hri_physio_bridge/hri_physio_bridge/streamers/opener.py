"""Opening an input streamer that may not be there yet: one bounded attempt, or attempts until it appears.

Used by the receiver and the processor; built on :mod:`hri_physio_bridge.waiting` (which knows no
streamer). Nothing here imports rclpy.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.streamers.base import (
    OpenCancelled,
    Streamer,
    StreamLostError,
    StreamNotFoundError,
    StreamSpec,
)
from hri_physio_bridge.waiting import Backoff, Clock, Sleeper, sleeper_for


class StreamOpener:
    """Opens an input streamer: one bounded attempt, or (``retry``) attempts until it appears or a stop.

    Each attempt waits up to ``timeout`` s inside the streamer. With ``retry``, attempts are
    separated by a :class:`Backoff` delay and "still waiting" is logged at most every
    ``log_period`` s (``on_attempt`` hears of every attempt, for a status a node publishes). Only
    :class:`StreamNotFoundError` and :class:`StreamLostError` are retried:
    a source that cannot exist (a missing file, a bad address) is raised at once. A stop raises
    :class:`OpenCancelled`.
    """

    def __init__(
        self,
        streamer: Streamer,
        expected: StreamSpec | None,
        *,
        timeout: float,
        retry: bool,
        log: logging.Logger,
        stop: threading.Event | None = None,
        clock: Clock = time.monotonic,
        backoff: Backoff | None = None,
        log_period: float = 30.0,
        sleep: Sleeper | None = None,
        on_attempt: Callable[[int, str], None] | None = None,
    ) -> None:
        self.streamer, self.expected, self.timeout, self.retry = streamer, expected, timeout, retry
        self.log, self.stop = log, stop
        self.backoff = backoff or Backoff(initial=0.5, maximum=5.0)
        self._sleep = sleep or sleeper_for(stop)
        self._waiting = RateLimitedLog(log.warning, period=log_period, monotonic=clock)
        self.attempts = 0
        #: Called after each attempt that found no stream (attempts so far, why): a node reports it.
        self.on_attempt = on_attempt

    def open(self) -> StreamSpec:
        self.backoff.reset()
        while True:
            if self.stop is not None and self.stop.is_set():
                raise OpenCancelled(f"stopped while waiting for {self.streamer.uri}")
            self.attempts += 1
            try:
                return self.streamer.open_input(self.expected, timeout=self.timeout, stop=self.stop)
            except OpenCancelled:
                raise
            except (StreamNotFoundError, StreamLostError) as exc:
                # Absent, or gone again while opening (LSL may list an outlet for a moment after it
                # closed): both can change, so a retrying opener tries again.
                if not self.retry:
                    raise
                self._waiting.report("absent", f"{exc}; still waiting", "attempt(s)")
                if self.on_attempt is not None:
                    self.on_attempt(self.attempts, str(exc))
            if self._sleep(self.backoff.next_delay()):
                raise OpenCancelled(f"stopped while waiting for {self.streamer.uri}")

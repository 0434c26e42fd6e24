"""Virtual time for the fake device: an asyncio loop whose clock jumps ahead whenever it is idle.

Every wait in the streamer is an asyncio wait (a sleep, a timeout on an answer, the watchdog's
tick, the fake device's next notification). :class:`VirtualTimeLoop` runs them on a
:class:`FakeClock`: when no callback is ready, instead of blocking until the earliest timer is
due, it moves the clock to that timer. Hours of streaming, silences, timeouts and backoffs run
in milliseconds, and in the order they would happen in real time, because time only moves when
everything due so far has run. I/O still counts (a thread's ``call_soon_threadsafe`` wakes the
loop at once).
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine, Mapping
from typing import Any, TypeVar

T = TypeVar("T")


class FakeClock:
    """Virtual seconds: only the loop (when idle), :meth:`advance` and :meth:`set` move it."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = float(start)

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += max(0.0, seconds)

    def set(self, t: float) -> None:
        self.now = max(self.now, t)

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of virtual time (inside :func:`run_virtual` only)."""
        loop = asyncio.get_running_loop()
        if not isinstance(loop, VirtualTimeLoop) or loop.clock is not self:
            raise RuntimeError("FakeClock.sleep needs a VirtualTimeLoop on this clock (run_virtual)")
        await asyncio.sleep(seconds)


class _FastForwardSelector(selectors.BaseSelector):
    """A real selector that, instead of blocking for ``timeout``, adds it to the virtual clock."""

    def __init__(self, clock: FakeClock) -> None:
        self._real = selectors.DefaultSelector()
        self._clock = clock

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = self._real.select(0)
        if ready:
            return ready
        if timeout is None:  # nothing scheduled: only I/O (another thread) can wake the loop
            return self._real.select(None)
        self._clock.advance(timeout)
        return []

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._real.get_map()

    def close(self) -> None:
        self._real.close()


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An event loop on a :class:`FakeClock` that skips idle time."""

    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        super().__init__(_FastForwardSelector(clock))

    def time(self) -> float:
        return self.clock.now


def run_virtual(main: Coroutine[Any, Any, T], clock: FakeClock) -> T:
    """Run ``main`` to completion on a :class:`VirtualTimeLoop` of ``clock`` (like ``asyncio.run``)."""
    with asyncio.Runner(loop_factory=lambda: VirtualTimeLoop(clock)) as runner:
        return runner.run(main)

"""Periodic tasks run from one loop, on an injected clock (no executor, no threads).

A loop that already wakes often (the recorder takes its messages every few milliseconds)
calls :meth:`Periodic.run_due` on each pass instead of paying an executor's wait-set pass for
its timers. A task that falls behind runs once, not once per missed period.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass
class _Task:
    period: float
    fn: Callable[[], None]
    due: float


class Periodic:
    def __init__(self, monotonic: Callable[[], float] = time.monotonic) -> None:
        self._monotonic = monotonic
        self._tasks: list[_Task] = []

    def every(self, period: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` every ``period`` seconds, the first time one period from now."""
        if not period > 0:
            raise ValueError(f"period must be > 0 s, got {period}")
        self._tasks.append(_Task(period, fn, self._monotonic() + period))

    def next_due_in(self) -> float | None:
        """Seconds until the next task is due (0: one is due now; None: no tasks)."""
        if not self._tasks:
            return None
        return max(0.0, min(task.due for task in self._tasks) - self._monotonic())

    def run_due(self) -> int:
        """Run the tasks that are due (in the order they were added); returns how many ran."""
        ran = 0
        for task in self._tasks:
            now = self._monotonic()
            if now < task.due:
                continue
            task.due += task.period
            if task.due <= now:  # fell behind by a period or more: skip ahead, do not catch up
                task.due = now + task.period
            task.fn()
            ran += 1
        return ran

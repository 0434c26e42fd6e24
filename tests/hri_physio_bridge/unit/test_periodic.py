"""Periodic: tasks on an injected clock, run from a loop."""

from __future__ import annotations

import pytest

from hri_physio_bridge.periodic import Periodic


def test_tasks_run_on_their_periods_and_do_not_catch_up() -> None:
    now = [0.0]
    calls: list[tuple[str, float]] = []
    tasks = Periodic(monotonic=lambda: now[0])
    tasks.every(0.25, lambda: calls.append(("tick", now[0])))
    tasks.every(1.0, lambda: calls.append(("status", now[0])))
    for t in (0.1, 0.25, 0.3, 0.5, 0.74, 1.0):
        now[0] = t
        tasks.run_due()
    assert calls == [("tick", 0.25), ("tick", 0.5), ("tick", 1.0), ("status", 1.0)]
    calls.clear()
    now[0] = 3.6  # the loop stalled: each task runs once, then keeps its period from now
    assert tasks.run_due() == 2
    now[0] = 3.8
    assert tasks.run_due() == 0
    now[0] = 3.85
    tasks.run_due()
    assert calls == [("tick", 3.6), ("status", 3.6), ("tick", 3.85)]


def test_period_must_be_positive() -> None:
    with pytest.raises(ValueError, match="period must be > 0 s"):
        Periodic().every(0.0, lambda: None)


def test_next_due_in_is_the_time_to_the_earliest_task() -> None:
    now = [0.0]
    tasks = Periodic(monotonic=lambda: now[0])
    assert tasks.next_due_in() is None
    tasks.every(0.25, lambda: None)
    tasks.every(0.2, lambda: None)
    assert tasks.next_due_in() == 0.2
    now[0] = 0.15
    assert abs(tasks.next_due_in() - 0.05) < 1e-12
    now[0] = 0.3  # both overdue: due now, never negative
    assert tasks.next_due_in() == 0.0
    tasks.run_due()
    assert abs(tasks.next_due_in() - 0.1) < 1e-12  # the 0.2-s task, next at 0.4

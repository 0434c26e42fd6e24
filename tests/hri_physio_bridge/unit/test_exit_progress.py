"""Judging a stopping process: more time while it works, none once it has idled for the grace; the
line a node says its work's status in."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from hri_physio_bridge.exit_progress import Activity, ExitProgress, done_line, read_activity, said_status


def looks(progress: ExitProgress, samples: list[tuple[float, Activity | None]]) -> list[bool]:
    return [progress.more_time(t, a) for t, a in samples]


def test_a_process_that_computes_gets_time_past_the_grace_until_the_limit() -> None:
    p = ExitProgress(started=0.0, idle_grace=2.0, limit=10.0)
    working = [(t, Activity(cpu_seconds=0.5 * t, runnable=False)) for t in range(0, 12)]
    assert looks(p, working) == [True] * 10 + [False, False]


def test_a_process_waiting_for_a_cpu_is_working() -> None:
    """On a busy machine a draining node may get no CPU for a while: runnable still counts."""
    p = ExitProgress(started=0.0, idle_grace=2.0, limit=60.0)
    starved = [(float(t), Activity(cpu_seconds=1.0, runnable=True)) for t in range(0, 6)]
    assert all(looks(p, starved))


def test_an_idle_process_is_given_up_after_the_grace() -> None:
    """A hung node's middleware threads use a little CPU: below the working share it is idle."""
    p = ExitProgress(started=0.0, idle_grace=2.0, limit=60.0)
    idle = [(t * 0.5, Activity(cpu_seconds=0.001 * t, runnable=False)) for t in range(0, 8)]
    assert looks(p, idle) == [True, True, True, True, False, False, False, False]


def test_work_then_idle_counts_the_grace_from_the_last_work() -> None:
    p = ExitProgress(started=0.0, idle_grace=2.0, limit=60.0)
    samples = [(0.0, Activity(0.0, False)), (1.0, Activity(0.9, False)), (2.0, Activity(1.8, False)),
               (3.0, Activity(1.8, False)), (3.9, Activity(1.8, False)), (4.1, Activity(1.8, False))]
    assert looks(p, samples) == [True, True, True, True, True, False]


def test_without_proc_only_the_grace_counts() -> None:
    p = ExitProgress(started=5.0, idle_grace=1.0, limit=60.0)
    assert looks(p, [(5.5, None), (5.99, None), (6.0, None)]) == [True, True, False]


def write_task(root: Path, pid: int, tid: int, comm: str, state: str, utime: int, stime: int) -> None:
    task = root / str(pid) / "task" / str(tid)
    task.mkdir(parents=True)
    rest = [state, *["0"] * 10, str(utime), str(stime), *["0"] * 30]
    (task / "stat").write_text(f"{tid} ({comm}) {' '.join(rest)}\n")


def test_read_activity_sums_every_thread_and_sees_a_runnable_one(tmp_path: Path) -> None:
    ticks = os.sysconf("SC_CLK_TCK")
    write_task(tmp_path, 42, 42, "python x (main)", "S", 100, 50)
    write_task(tmp_path, 42, 43, "dds) thread", "R", 7, 3)
    activity = read_activity(42, proc=tmp_path)
    assert activity == Activity(cpu_seconds=pytest.approx(160 / ticks), runnable=True)
    assert read_activity(43, proc=tmp_path) is None  # no such process


def test_read_activity_of_this_process() -> None:
    before = read_activity(os.getpid())
    assert before is not None and before.runnable  # this thread is running
    sum(i * i for i in range(2_000_000))
    after = read_activity(os.getpid())
    assert after is not None and after.cpu_seconds > before.cpu_seconds


@pytest.mark.parametrize("code", [0, 1, 2, 4, 130, -6])
def test_the_done_line_gives_back_its_status(code: int) -> None:
    assert said_status(done_line("physio_receiver", code)) == code
    assert said_status(done_line("physio_receiver", code) + "\n") == code


@pytest.mark.parametrize("line", [
    "", "physio_receiver: finished", "finished with exit status 0",
    "physio_receiver: finished with exit status x; shutting down ROS 2",
    "physio_receiver: finished with exit status 0; shutting down ROS 2 (and more)",
    "[INFO] [1.0] [rx]: 3 samples",
])
def test_other_lines_give_no_status(line: str) -> None:
    assert said_status(line) is None

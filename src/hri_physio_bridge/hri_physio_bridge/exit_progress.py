"""Is a process that was asked to stop still working on its way out, or stuck? (no rclpy here)

A node that drains at a stop (the processor's last frames, the recorder's last messages) needs
more than a fixed grace period on a busy machine, where it waits for a CPU as long as it computes.
A node stuck on its way out (a deadlock, a hang in a library's shutdown) uses no CPU at all. So the
launcher gives a stopping process more time for as long as it works, and escalates once it has
been idle for the grace period (or after a hard limit).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

#: A process using at least this share of one core since the last look is working.
WORKING_SHARE = 0.05
_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


@dataclass(frozen=True)
class Activity:
    """What a process did, as /proc shows it: CPU seconds so far, and whether a thread waits for a CPU."""

    cpu_seconds: float
    runnable: bool


def read_activity(pid: int, proc: Path = Path("/proc")) -> Activity | None:
    """The CPU time of all of ``pid``'s threads and whether any is runnable; None without /proc or pid."""
    total, runnable = 0, False
    try:
        tasks = list((proc / str(pid) / "task").iterdir())
    except OSError:
        return None
    for task in tasks:
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue  # a thread that ended meanwhile
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) "; comm may hold spaces
        runnable |= fields[0] == "R"
        total += int(fields[11]) + int(fields[12])  # utime, stime
    return Activity(total / _TICKS, runnable)


@dataclass
class ExitProgress:
    """Fed :class:`Activity` looks at wall times; says whether the process deserves more time.

    It does while it worked (``WORKING_SHARE`` of a core, or a thread waiting for a CPU) within the
    last ``idle_grace`` seconds and ``limit`` seconds have not passed since the stop. Without /proc
    (``None``) it only counts the grace from the stop.
    """

    started: float
    idle_grace: float
    limit: float
    last_work: float = field(init=False)
    _last: tuple[float, Activity] | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        self.last_work = self.started

    def more_time(self, now: float, activity: Activity | None) -> bool:
        if activity is not None:
            if self._last is not None:
                t, before = self._last
                share = (activity.cpu_seconds - before.cpu_seconds) / max(now - t, 1e-9)
                if share >= WORKING_SHARE or activity.runnable:
                    self.last_work = now
            self._last = (now, activity)
        return now - self.last_work < self.idle_grace and now - self.started < self.limit

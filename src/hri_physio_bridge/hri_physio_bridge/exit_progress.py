"""Is a process that was asked to stop still working on its way out, or stuck? (no rclpy here)

A node that drains at a stop (the processor's last frames, the recorder's last messages) needs
more than a fixed grace period on a busy machine, where it waits for a CPU as long as it computes.
A node stuck on its way out (a deadlock, a hang in a library's shutdown) uses no CPU at all. So the
launcher gives a stopping process more time for as long as it works, and escalates once it has
been idle for the grace period (or after a hard limit).

A node's work can be over while its process is not: the ROS 2 middleware's teardown comes after it,
and can hang (Fast DDS), be cut off or crash. So a node says how its work ended in one line first
(:func:`done_line`), and the launcher takes the node's outcome from that line (:func:`said_status`).
"""

from __future__ import annotations

import os
import re
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


_DONE = re.compile(r": finished with exit status (-?\d+); shutting down ROS 2$")


def done_line(prog: str, code: int) -> str:
    """The line a node prints once its work is over, before the middleware's teardown."""
    return f"{prog}: finished with exit status {code}; shutting down ROS 2"


def said_status(line: str) -> int | None:
    """The exit status a :func:`done_line` gives; None for any other line."""
    found = _DONE.search(line.rstrip())
    return int(found.group(1)) if found else None

"""Which node the session launcher restarts when it dies, when, how often, and the record of it (no rclpy).

A node that dies mid-session (a crash, ``kill -9``) is either *restartable* - the robot side, the
media streamers, the receivers, the processor: the session carries on without it for a moment,
and it is started again with the same command line after a backoff (``first`` seconds, doubling
up to ``cap``) - or *essential* - the coach, the recorder, the strap: without them the session
means nothing, so their loss ends it. A restartable node that dies more than ``max_restarts``
times also ends it. Every restart and every loss is a :class:`Restart` / :class:`Loss` record
that becomes an event on ``/session/events`` (sim time ``t``), a line of ``summary.json`` and of
the report.

A new LSL inlet gets no history: what a receiver's source sent while the receiver was down is
lost. The launcher watches each receiver's output, so a receiver's restart record also says which
samples are missing (:attr:`Restart.gap`: the last source timestamp before the restart and the
first after it, on the source's clock), found once the restarted receiver publishes again.
Wall time (the backoff) comes from an injected clock.
"""

from __future__ import annotations

import math
import signal
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from hri_physio_bringup.plan import (
    AUDIO,
    CONTROLLER,
    ECG_RECEIVER,
    HR_RECEIVER,
    LIVE,
    MOCK,
    PROCESSOR,
    VIDEO,
)

#: Nodes the session can lose for a moment; any other node is essential.
RESTARTABLE = frozenset({CONTROLLER, MOCK, AUDIO, VIDEO, HR_RECEIVER, ECG_RECEIVER, PROCESSOR, LIVE})
#: Events on /session/events (the ``event`` field).
NODE_RESTARTED, NODE_DIED, RECEIVER_GAP = "node_restarted", "node_died", "receiver_gap"
DEFAULT_MAX_RESTARTS = 3


def status_text(code: int) -> str:
    """An exit status in words: ``-9 (SIGKILL)`` for a signal, the number otherwise."""
    if code < 0:
        try:
            return f"{code} ({signal.Signals(-code).name})"
        except ValueError:
            return str(code)
    return str(code)


@dataclass(frozen=True)
class Backoff:
    """Wall seconds before restart ``n`` (1, 2, ...): ``first``, doubling, at most ``cap``."""

    first: float = 0.5
    cap: float = 8.0

    def delay(self, n: int) -> float:
        return min(self.cap, self.first * 2.0 ** (n - 1))


@dataclass
class Restart:
    """One restart of a node: why, when (sim time), how long it was down."""

    node: str
    restart: int  # 1 for the first restart of this node
    exit_status: int
    died_t: float  # sim time the launcher found it gone
    t: float | None = None  # sim time it was started again (None: still waiting for its backoff)
    #: A receiver's missing samples: (last source timestamp before, first after) its restart.
    gap: tuple[float, float] | None = None
    missing: int | None = None  # how many samples that gap held (its gap_event's count, once published)

    @property
    def down_s(self) -> float | None:
        """Session seconds from the death seen to the new process started."""
        return None if self.t is None else round(self.t - self.died_t, 3)

    def event(self) -> dict[str, Any]:
        return {"t": self.t, "event": NODE_RESTARTED, "node": self.node, "exit_status": self.exit_status,
                "down_s": self.down_s, "restart": self.restart}

    def gap_event(self, rate: float | None) -> dict[str, Any]:
        """The receiver's outage on its source's clock, and the samples a ``rate`` Hz source lost in it."""
        assert self.gap is not None
        before, after = self.gap
        missing = None if not rate else max(0, round((after - before) * rate) - 1)
        return {"t": self.t, "event": RECEIVER_GAP, "node": self.node, "restart": self.restart,
                "last_before": before, "first_after": after, "missing": missing}

    def record(self) -> dict[str, Any]:
        """The entry of summary.json's ``restarts``."""
        return {"node": self.node, "restart": self.restart, "exit_status": self.exit_status,
                "died_t": self.died_t, "restarted_t": self.t, "down_s": self.down_s,
                "gap": None if self.gap is None else {"last_before": self.gap[0], "first_after": self.gap[1],
                                                      "missing": self.missing}}

    def line(self, max_restarts: int) -> str:
        return (f"[session] restarted {self.node} ({self.restart} of {max_restarts}): it died with exit "
                f"status {status_text(self.exit_status)}, down {self.down_s:g} s of session time")


def gap_line(event: dict[str, Any]) -> str:
    """The console line of a ``receiver_gap`` event: what the restarted receiver's source sent meanwhile."""
    lost = "an unknown number of" if event["missing"] is None else str(event["missing"])
    return (f"[session] {event['node']} publishes again: {lost} sample(s) of its source were lost while it "
            f"was down (source time {event['last_before']:.3f} .. {event['first_after']:.3f})")


def restarts_text(restarts: list[dict[str, Any]]) -> str:
    """The closing line about restarts: which node, how often, how long it was down."""
    parts = []
    for r in restarts:
        down = "not restarted before the end" if r["down_s"] is None else f"down {r['down_s']:g} s"
        lost = r["gap"]["missing"] if r["gap"] else None
        parts.append(f"{r['node']} after exit status {status_text(r['exit_status'])} ({down}"
                     + ("" if lost is None else f", {lost} sample(s) of its source lost") + ")")
    return f"[session] nodes that died and their restarts ({len(restarts)}): {', '.join(parts)}"


@dataclass(frozen=True)
class Loss:
    """A node whose death ends the session: essential, or past its restart limit."""

    node: str
    exit_status: int
    t: float
    restarts: int  # how often it had been restarted before
    essential: bool
    last_words: str = ""  # its error line, when it said one

    @property
    def reason(self) -> str:
        return "essential" if self.essential else "restart limit"

    def event(self) -> dict[str, Any]:
        return {"t": self.t, "event": NODE_DIED, "node": self.node, "exit_status": self.exit_status,
                "restart": self.restarts, "reason": self.reason}

    def problem(self, max_restarts: int) -> str:
        """The session's one error line."""
        why = ("an essential node: the session cannot go on without it" if self.essential else
               f"after {self.restarts} restart(s), the limit (--max-restarts {max_restarts})")
        words = f" ({self.last_words})" if self.last_words else ""
        return f"{self.node} died with exit status {status_text(self.exit_status)}, {why}{words}"


@dataclass
class Supervisor:
    """The restart policy of one session; the launcher reports deaths and applies the decisions."""

    max_restarts: int = DEFAULT_MAX_RESTARTS
    backoff: Backoff = field(default_factory=Backoff)
    restartable: frozenset[str] = RESTARTABLE
    monotonic: Callable[[], float] = field(default=time.monotonic, repr=False)
    records: list[Restart] = field(default_factory=list)
    loss: Loss | None = None
    _due: dict[str, tuple[Restart, float]] = field(default_factory=dict)  # node -> (record, wall time due)
    _watching: dict[str, Restart] = field(default_factory=dict)  # receiver -> restart waiting for its gap
    _last_t: dict[str, float] = field(default_factory=dict)  # receiver -> newest source timestamp seen
    _gap_since: dict[str, float] = field(default_factory=dict)  # receiver -> last timestamp before restart

    def __post_init__(self) -> None:
        if self.max_restarts < 0:
            raise ValueError(f"max_restarts must be >= 0, got {self.max_restarts}")

    def restarts_of(self, node: str) -> int:
        return sum(r.node == node for r in self.records)

    def pending(self, node: str) -> bool:
        """Dead and waiting for its restart (its old process is expected to have exited)."""
        return node in self._due

    def awaiting_restart(self) -> list[str]:
        """The nodes that died and wait for their restart (at the session's end: never restarted)."""
        return sorted(self._due)

    def died(self, node: str, exit_status: int, sim_t: float, last_words: str = "") -> Restart | Loss:
        """``node`` found gone at sim time ``sim_t``: a restart planned, or the loss ending the session."""
        done = self.restarts_of(node)
        if node not in self.restartable or done >= self.max_restarts:
            loss = Loss(node, exit_status, sim_t, done, node not in self.restartable, last_words)
            self.loss = self.loss or loss
            return loss
        record = Restart(node, done + 1, exit_status, sim_t)
        self.records.append(record)
        self._due[node] = (record, self.monotonic() + self.backoff.delay(record.restart))
        return record

    def due(self) -> list[Restart]:
        """The restarts whose backoff is over (each returned once: the caller starts the node)."""
        now = self.monotonic()
        ready = [record for record, at in self._due.values() if now >= at]
        for record in ready:
            del self._due[record.node]
        return ready

    def started(self, record: Restart, sim_t: float) -> None:
        """The node of ``record`` runs again (a new process) since sim time ``sim_t``."""
        record.t = sim_t
        if record.node in self._last_t or record.node in self._watching:
            self.watch_gap(record)

    # --- receivers: the samples their restart lost ------------------------------------------------
    def watch_gap(self, record: Restart) -> None:
        """From now on, the first sample on the receiver's output closes its gap."""
        if record.node not in self._watching:  # else: restarted again before it published: one gap
            self._gap_since[record.node] = self._last_t.get(record.node, math.nan)
        self._watching[record.node] = record

    def output(self, node: str, timestamps: Iterable[float]) -> Restart | None:
        """A frame the receiver ``node`` published; the restart whose gap it closes, if any."""
        stamps = [float(t) for t in timestamps]
        if not stamps:
            return None
        closed = None
        record = self._watching.pop(node, None)
        if record is not None:
            since = self._gap_since.pop(node, math.nan)
            if math.isfinite(since):
                record.gap = (since, stamps[0])
                closed = record
        last = self._last_t.get(node, math.nan)
        self._last_t[node] = stamps[-1] if not math.isfinite(last) else max(last, stamps[-1])
        return closed

    def tracks(self, node: str) -> bool:
        """Whether ``node``'s output is watched for gaps (:meth:`track`)."""
        return node in self._last_t

    def watching(self) -> list[str]:
        """The restarted receivers whose gap is still open (waiting for their first new frame)."""
        return list(self._watching)

    def track(self, node: str) -> None:
        """Watch ``node``'s output for gaps (a receiver)."""
        self._last_t.setdefault(node, math.nan)

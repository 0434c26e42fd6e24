"""A per-stream watchdog: data must start, and must not stop, without anyone saying so.

Owners report notifications that stop without a disconnect (after 30-150 s on Raspberry Pi /
BlueZ) and an H10's ECG that starts 20-30 s after its start was accepted. Only a disconnect
ended the wait before. Every started source is watched on the session's clock:

- its first data must come within ``start_timeout`` of its start;
- after that, no silence may last longer than ``stall_timeout``.

A silence past its limit is an :class:`Alarm`. The first alarm of a silence asks for a restart
of that source (stop and start it); the watch then waits ``start_timeout`` again for data. If
the source stays silent, the next alarm asks for a reconnection. Data clears it all.

A source is a PMD measurement (``ecg``, ``acc``, ``ppg``, ``ppi``) or ``hr``, the Heart Rate
Measurement notifications that carry both the HR and the RR streams.
"""

from __future__ import annotations

from dataclasses import dataclass

RESTART, RECONNECT = "restart", "reconnect"
START, STREAMING = "start", "streaming"


@dataclass(frozen=True)
class Alarm:
    source: str
    #: ``start``: no first data since the (re)start; ``streaming``: silent after data.
    phase: str
    #: Seconds of silence when the alarm was raised, counted from ``since``.
    silent_s: float
    #: Clock time the silence began: the (re)start, or the last data.
    since: float
    #: ``restart`` the source, or ``reconnect`` (a restart did not bring data back).
    action: str


@dataclass
class _Watch:
    start_timeout: float
    stall_timeout: float
    since: float
    started: float
    has_data: bool = False
    restarted: bool = False

    @property
    def limit(self) -> float:
        return self.stall_timeout if self.has_data else self.start_timeout


class StreamWatchdog:
    """Watches each started source; :meth:`check` raises the alarms that are due."""

    def __init__(self) -> None:
        self._watches: dict[str, _Watch] = {}

    def watch(self, source: str, now: float, start_timeout: float, stall_timeout: float) -> None:
        """``source`` was (re)started at ``now``: its first data is due within ``start_timeout``."""
        if not (start_timeout > 0 and stall_timeout > 0):
            raise ValueError(f"timeouts must be > 0 s, got {start_timeout} and {stall_timeout}")
        previous = self._watches.get(source)
        self._watches[source] = _Watch(
            start_timeout, stall_timeout, since=now, started=now,
            restarted=previous.restarted if previous is not None else False,
        )

    def forget(self, source: str) -> None:
        self._watches.pop(source, None)

    def clear(self) -> None:
        """Forget every source (the connection ended)."""
        self._watches.clear()

    def data(self, source: str, now: float) -> float | None:
        """Data of ``source`` arrived at ``now``; the seconds since its (re)start if it is the first."""
        watch = self._watches.get(source)
        if watch is None:
            return None
        first = None if watch.has_data else now - watch.started
        watch.since, watch.has_data, watch.restarted = now, True, False
        return first

    def next_due(self) -> float | None:
        """The clock time of the next possible alarm (None: nothing watched)."""
        if not self._watches:
            return None
        return min(w.since + w.limit for w in self._watches.values())

    def check(self, now: float) -> list[Alarm]:
        """The alarms due at ``now``. A restart alarm re-arms the watch for the restarted source's
        first data; a reconnect alarm ends the watch (the next connection watches anew)."""
        alarms = []
        for source, watch in list(self._watches.items()):
            silent = now - watch.since
            if silent < watch.limit:
                continue
            phase = STREAMING if watch.has_data else START
            if watch.restarted:
                alarms.append(Alarm(source, phase, silent, watch.since, RECONNECT))
                del self._watches[source]
            else:
                alarms.append(Alarm(source, phase, silent, watch.since, RESTART))
                watch.since, watch.started, watch.has_data, watch.restarted = now, now, False, True
        return alarms

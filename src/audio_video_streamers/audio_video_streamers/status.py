"""The streamers' status model: what ``/audio_streamer/status`` and ``/video_streamer/status`` carry.

One JSON object per message (std_msgs/String), published on every change and at ``status_rate``.
The package README documents every field; :meth:`MediaStatus.as_dict` is the JSON.
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass, field, replace
from enum import StrEnum
from typing import Any, Literal

Outcome = Literal["started", "failed", "superseded"]


class State(StrEnum):
    PLAYING = "playing"  # one source at full level
    FADING = "fading"  # a cross-fade (or a fade to silence) is under way
    STOPPED = "stopped"  # nothing plays
    ERROR = "error"  # this message reports a request that failed; what played goes on


@dataclass(frozen=True)
class RequestCounts:
    """Every request received ends in exactly one of started, failed or superseded (or is pending)."""

    received: int = 0
    started: int = 0
    failed: int = 0
    superseded: int = 0


class RequestLedger:
    """Counts every request from receipt to its outcome (thread-safe): the status proves none was lost."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts = RequestCounts()
        self._pending: list[str] = []
        self._last_key: tuple[Any, ...] | None = None  # what the last status showed (see changed)

    def received(self, text: str) -> None:
        with self._lock:
            self._counts = replace(self._counts, received=self._counts.received + 1)
            self._pending.append(text)

    def settle(self, text: str, outcome: Outcome) -> None:
        with self._lock:
            self._counts = replace(self._counts, **{outcome: getattr(self._counts, outcome) + 1})
            if text in self._pending:
                self._pending.remove(text)

    def snapshot(self) -> tuple[RequestCounts, tuple[str, ...]]:
        with self._lock:
            return self._counts, tuple(self._pending)

    def status(self, t: float, state: State, error: tuple[str, str] | None, extra: dict[str, Any],
               **fields: Any) -> MediaStatus:
        """A status with these counts; with ``error`` (request, message) it reports that failure."""
        counts, pending = self.snapshot()
        return MediaStatus(t=t, state=State.ERROR if error else state, requests=counts, pending=pending,
                           error=error[1] if error else None, request=error[0] if error else None,
                           extra=extra, **fields)

    def changed(self, key: tuple[Any, ...]) -> bool:
        """True when ``key`` (what a status shows) together with the counts differs from the last call's."""
        key = (*key, self.snapshot())
        if key == self._last_key:
            return False
        self._last_key = key
        return True


@dataclass(frozen=True)
class MediaStatus:
    """Fields shared by both streamers; ``None`` fields are left out of the JSON."""

    t: float
    state: State
    source: str | None = None  # the request now playing (the incoming one while fading)
    kind: str | None = None  # beat | relaxing | file | stretch (audio); splash | relaxing | activity | file
    tempo: float | None = None  # BPM, when known
    position: float = 0.0  # s into the current loop of the source
    elapsed: float = 0.0  # s since the source started (does not wrap)
    loops: int = 0  # completed passes through the source
    duration: float | None = None  # s of one loop, when known
    requests: RequestCounts = field(default_factory=RequestCounts)
    pending: tuple[str, ...] = ()  # received, still being prepared
    error: str | None = None  # only with state ``error``
    request: str | None = None  # the failed request, only with state ``error``
    extra: dict[str, Any] = field(default_factory=dict)  # streamer-specific fields, merged in

    def as_dict(self) -> dict[str, Any]:
        data = asdict(self)
        extra = data.pop("extra")
        data["state"] = str(self.state)
        data["pending"] = list(self.pending)
        out = {k: v for k, v in data.items() if v is not None}
        out.update(extra)
        return out

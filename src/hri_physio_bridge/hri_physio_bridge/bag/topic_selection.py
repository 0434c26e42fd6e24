"""Which topics to record or play, remapping, and bag names."""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime

from hri_physio_bridge.bag.errors import BagError

_SESSION_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def is_hidden(topic: str) -> bool:
    """ROS 2 hidden topics have a name part starting with ``_`` (e.g. ``/_action/...``)."""
    return any(part.startswith("_") for part in topic.split("/") if part)


def _compile(pattern: str | None, what: str) -> re.Pattern[str] | None:
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise BagError(f"{what} {pattern!r} is not a valid regular expression: {exc}") from None


@dataclass
class TopicSelector:
    """All topics (default), or an explicit list and/or a regular expression (full match),
    minus an exclusion expression; hidden topics only on request."""

    topics: Iterable[str] = ()
    regex: str | None = None
    exclude: str | None = None
    include_hidden: bool = False
    _names: frozenset[str] = field(init=False)
    _re: re.Pattern[str] | None = field(init=False)
    _ex: re.Pattern[str] | None = field(init=False)

    def __post_init__(self) -> None:
        names = []
        for t in self.topics:
            if not t.startswith("/"):
                raise BagError(f"topic {t!r} must be absolute (start with '/')")
            names.append(t)
        self._names = frozenset(names)
        self._re = _compile(self.regex, "--regex")
        self._ex = _compile(self.exclude, "--exclude")

    @property
    def records_all(self) -> bool:
        return not self._names and self._re is None

    def selects(self, topic: str) -> bool:
        if self._ex is not None and self._ex.fullmatch(topic):
            return False
        if topic in self._names:
            return True  # named explicitly: hidden or not
        if is_hidden(topic) and not self.include_hidden:
            return False
        if self.records_all:
            return True
        return self._re is not None and self._re.fullmatch(topic) is not None


def parse_remaps(items: Iterable[str]) -> dict[str, str]:
    """``/from:=/to`` pairs (as ``ros2 bag play --remap`` takes them)."""
    out: dict[str, str] = {}
    for item in items:
        src, sep, dst = item.partition(":=")
        if not sep or not src.startswith("/") or not dst.startswith("/"):
            raise BagError(f"remapping {item!r} must look like /from:=/to")
        out[src] = dst
    return out


def bag_name(session_id: str, start: datetime) -> str:
    """``<session>_<YYYY-mm-dd-HH-MM-SS>`` (rosbag2's default date format, our session first)."""
    if not _SESSION_RE.match(session_id):
        raise BagError(
            f"session id {session_id!r} may hold letters, digits, '_', '-' and '.' only "
            "(no participant names: use a pseudonymous id)"
        )
    return f"{session_id}_{start.strftime('%Y_%m_%d-%H_%M_%S')}"

"""What the recorder does, without rclpy: choose topics, register them, count, report.

The node shell polls the ROS graph and hands this class ``(topic, [types])`` lists and the
publishers' offered QoS/type hashes; it creates the raw subscriptions this class asks for
and passes every received buffer to :meth:`RecordingSession.on_message`.

Messages that never reach the bag are found from each publisher's sequence numbers (in the
middleware's message info): a gap means the subscription's queue overflowed (``--qos-depth``)
or a best-effort link dropped them. They are reported, counted per topic and written to the
bag's ``custom_data``, never silently lost. A publisher's first message taken is the start of
its count: what it sent before that cannot be told apart from what it sent before the
recorder subscribed.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.metadata import HASH_RE, LOST_KEY, BagInfo
from hri_physio_bridge.bag.msgdefs import (
    UnknownTypeError,
    import_message_type,
    installed_type_hash,
    message_definition,
)
from hri_physio_bridge.bag.topic_selection import TopicSelector
from hri_physio_bridge.bag.writer import BagWriter
from hri_physio_bridge.rate_limit import RateLimitedLog

#: Warn when the bag's disk has less free space than this many seconds of recording ...
LOW_DISK_SECONDS = 600.0
#: ... or than this many bytes, whatever the rate.
LOW_DISK_BYTES = 500_000_000


@dataclass(frozen=True)
class Candidate:
    """A topic to subscribe to: its name, type name and generated Python class."""

    topic: str
    type_name: str
    msg_class: Any


class RecordingSession:
    def __init__(
        self,
        writer: BagWriter,
        selector: TopicSelector,
        log: logging.Logger,
        *,
        import_type: Callable[[str], Any] = import_message_type,
        definition: Callable[[str], str] = message_definition,
        wall_ns: Callable[[], int] = time.time_ns,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.writer = writer
        self.selector = selector
        self.log = log
        self._import = import_type
        self._definition = definition
        self._wall_ns = wall_ns
        self.recording: dict[str, str] = {}
        self.skipped: dict[str, str] = {}
        self._last_report = (0, 0)
        self.lost: dict[str, int] = {}  # messages missed per topic (publisher sequence gaps)
        self._last_seq: dict[tuple[str, bytes], int] = {}
        self._last_log_ns: dict[str, int] = {}
        self._loss_log = RateLimitedLog(lambda text: self.log.warning(text), monotonic=monotonic)
        self._file_bytes_seen = 0
        self._monotonic = monotonic
        self._last_disk_warning = -math.inf

    # -- discovery -----------------------------------------------------------
    def _skip(self, topic: str, reason: str) -> None:
        if self.skipped.get(topic) != reason:
            self.skipped[topic] = reason
            self.log.warning(f"not recording {topic}: {reason}")

    def candidates(self, graph: Iterable[tuple[str, list[str]]]) -> list[Candidate]:
        """Selected topics not yet recorded that can be (each skip is reported once)."""
        out = []
        for topic, types in graph:
            if topic in self.recording or not self.selector.selects(topic):
                continue
            if len(types) != 1:
                self._skip(topic, f"it carries {len(types)} types ({', '.join(types)}); a bag topic has one")
                continue
            try:
                cls = self._import(types[0])
            except UnknownTypeError as exc:
                self._skip(topic, f"{exc}; install its interface package to record it")
                continue
            out.append(Candidate(topic, types[0], cls))
        return out

    def start_topic(
        self, cand: Candidate, offered_qos: list[dict[str, Any]], graph_hashes: Iterable[str]
    ) -> bool:
        """Register ``cand`` in the bag; False (and a logged reason) if it cannot be."""
        try:
            definition = self._definition(cand.type_name)
        except UnknownTypeError as exc:
            self._skip(cand.topic, str(exc))
            return False
        installed = installed_type_hash(cand.type_name)
        offered = sorted({h for h in graph_hashes if HASH_RE.match(h)})
        if len(offered) > 1:
            self._skip(cand.topic, f"publishers offer different type hashes {offered}")
            return False
        type_hash = offered[0] if offered else (installed or "")
        if offered and installed and offered[0] != installed:
            self.log.warning(
                f"{cand.topic}: publishers' {cand.type_name} hash {offered[0]} differs from the installed "
                f"definition's {installed}; recording the publishers' hash"
            )
        if not type_hash:
            self.log.warning(f"{cand.topic}: no type description hash known for {cand.type_name}")
        try:
            self.writer.add_topic(cand.topic, cand.type_name, definition, type_hash, offered_qos)
        except BagError as exc:
            self._skip(cand.topic, str(exc))
            return False
        self.recording[cand.topic] = cand.type_name
        self.skipped.pop(cand.topic, None)
        qos = offered_qos[0] if offered_qos else {}
        self.log.info(
            f"recording {cand.topic} [{cand.type_name}] from {len(offered_qos)} publisher(s), "
            f"{qos.get('reliability', '?')}/{qos.get('durability', '?')}"
        )
        return True

    # -- messages ------------------------------------------------------------
    def on_message(self, topic: str, data: bytes, info: dict[str, Any] | None = None) -> None:
        """One raw message, stamped with the middleware's receive time (ns) when known, but always
        after the topic's previous message.

        A reliable topic is delivered in order, yet not always received in order: a writer that sent
        before this reader had matched it (a node just restarted) repairs those first messages after
        the reader has already received later ones. Readers of a bag go by log time, so a repaired
        message's receive time would put it after messages delivered after it.
        """
        received = int(info.get("received_timestamp") or 0) if info else 0
        source = int(info.get("source_timestamp") or 0) if info else 0
        seq = int(info.get("publication_sequence_number") or 0) if info else 0
        gid = info.get("publisher_gid") if seq and info else None
        if gid:
            self._check_sequence(topic, bytes(gid["data"]), seq)
        stamp = max(received or self._wall_ns(), self._last_log_ns.get(topic, -1) + 1)
        self._last_log_ns[topic] = stamp
        self.writer.write(topic, stamp, data, source, seq)

    def _check_sequence(self, topic: str, publisher: bytes, seq: int) -> None:
        key = (topic, publisher)
        last = self._last_seq.get(key)
        self._last_seq[key] = seq
        if last is None or seq <= last + 1:
            return  # a publisher's first message here, the next one, or a restart
        missed = seq - last - 1
        self.lost[topic] = self.lost.get(topic, 0) + missed
        self._loss_log.report(
            topic,
            f"{topic}: {missed} message(s) from one publisher never reached the recorder (its queue "
            "overflowed: raise --qos-depth; or a best-effort link dropped them)",
            "message(s) lost",
            missed,
        )

    def finish(self) -> None:
        """Before closing the bag: note the lost messages in its metadata."""
        if self.lost:
            self.writer.custom_data[LOST_KEY] = ", ".join(f"{t}: {n}" for t, n in sorted(self.lost.items()))

    # -- reporting -----------------------------------------------------------
    def check_disk(self, free_bytes: int, interval: float) -> bool:
        """Warn when the disk will be full within LOW_DISK_SECONDS at the file growth of the
        last ``interval`` seconds, or has less than LOW_DISK_BYTES free (a full disk stops the
        recording: better to know ten minutes before). At most one warning a minute; returns
        whether space is low."""
        grown = self.writer.stats.file_bytes - self._file_bytes_seen
        self._file_bytes_seen = self.writer.stats.file_bytes
        rate = grown / interval if interval > 0 else 0.0
        if free_bytes >= max(LOW_DISK_BYTES, rate * LOW_DISK_SECONDS):
            return False
        now = self._monotonic()
        if now - self._last_disk_warning >= 60.0:
            self._last_disk_warning = now
            left = f", about {free_bytes / rate / 60:.0f} min at {rate / 1e6:.2f} MB/s" if rate > 0 else ""
            self.log.warning(
                f"low disk space for {self.writer.bag_dir}: {free_bytes / 1e9:.2f} GB free{left}; "
                "free some space or the recording stops when the disk is full"
            )
        return True

    def status(self, interval: float | None = None) -> str:
        st = self.writer.stats
        text = (
            f"{len(self.recording)} topic(s) recorded, {len(self.skipped)} skipped; "
            f"{st.messages} messages, {st.bytes / 1e6:.2f} MB payload, file {st.file_bytes / 1e6:.2f} MB, "
            f"{st.chunks_flushed} chunks flushed"
        )
        if self.lost:
            text += f", {sum(self.lost.values())} lost"
        if interval:
            dm = st.messages - self._last_report[0]
            db = st.bytes - self._last_report[1]
            text += f"; {dm / interval:.0f} msg/s, {db / interval / 1e6:.2f} MB/s"
        self._last_report = (st.messages, st.bytes)
        return text

    def summary_lines(self, info: BagInfo) -> list[str]:
        lines = [
            f"{t.name} [{t.type}]: {t.message_count} messages"
            + (f", {self.lost[t.name]} LOST (sequence gaps)" if t.name in self.lost else "")
            for t in info.topics
        ]
        lines += [f"{topic}: skipped ({why})" for topic, why in sorted(self.skipped.items())]
        return lines

"""physio_recorder (alias recorder): every ROS 2 topic (or a chosen set) into a rosbag2 directory (MCAP).

Examples::

    physio_recorder --session-id P012                      # all topics -> bags/P012_<date-time>/
    physio_recorder /physio/polar_h10/ecg /coach/state -o bags/run1
    physio_recorder --regex '/physio/.*' --exclude '.*/status'
    physio_recorder --repair bags/P012_2025_01_01-10_00_00   # fix a bag whose recorder was killed

Topics that appear later are picked up (the graph is polled). Messages are stored as
received (raw CDR), stamped with their receive time. Completed chunks reach the disk at
least every --flush-period seconds, so a crash loses at most that much. Messages that never
reach the recorder (a full queue, a best-effort drop) are found from the publishers' sequence
numbers, reported, and listed in the bag's metadata (lost_messages); low disk space is warned
about before it stops the recording.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import threading
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

from rclpy.node import Node

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.options import RecorderConfig
from hri_physio_bridge.bag.topic_selection import TopicSelector, bag_name
from hri_physio_bridge.node_runner import ManagedNode, logic_logger, run_node
from hri_physio_bridge.periodic import Periodic
from hri_physio_bridge.ros_tools import MessageArrivals

PROG = "physio_recorder"
#: The older, shorter name of the same command (kept: users and scripts type it).
ALIAS = "recorder"
#: Messages taken per topic per pass before the timers run again.
DRAIN_BUDGET = 2000


def _arguments(p: argparse.ArgumentParser) -> None:
    """The topic list, the modes that need no ROS, and the short flags of some options."""
    p.add_argument("topics", nargs="*", help="topics to record (default: all topics)")
    short_flags = (("-o", "output", "DIR"), ("-e", "regex", "REGEX"), ("-x", "exclude", "REGEX"))
    for short, name, metavar in short_flags:
        p.add_argument(short, "--" + name.replace("_", "-"), dest=name, default=None, metavar=metavar,
                       help=RecorderConfig.describe(name) + "; also a --conf key and ROS parameter")
    p.add_argument("--repair", metavar="BAG",
                   help="do not record: repair BAG (directory or .mcap) whose recorder was killed, then exit")
    p.add_argument("--no-backup", action="store_true", help="with --repair: do not keep the damaged file")


def run_repair(prog: str, target: str, keep: bool) -> int:
    from hri_physio_bridge.bag.recovery import repair_bag

    try:
        rep = repair_bag(Path(target), keep_damaged=keep)
    except BagError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr, flush=True)
        return 1
    scan = rep.scan
    state = "was complete" if scan.complete else f"was incomplete ({scan.problem})"
    print(
        f"{prog}: {rep.mcap} {state}; recovered {scan.messages} messages on {len(rep.info.topics)} topic(s), "
        f"dropped {scan.lost_bytes} trailing bytes, {scan.corrupt_chunks} damaged chunk(s)"
        f"{f', skipped {scan.skipped_bytes} damaged bytes' if scan.skipped_bytes else ''}"
    )
    for t in rep.info.topics:
        print(f"  {t.name} [{t.type}]: {t.message_count}")
    if rep.backup is not None:
        print(f"{prog}: original kept as {rep.backup}")
    return 0


def _qos_profile(values: dict[str, Any]) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=values["depth"],
        reliability=ReliabilityPolicy.RELIABLE
        if values["reliability"] == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL
            if values["durability"] == "transient_local"
            else DurabilityPolicy.VOLATILE
        ),
    )


def _taken_by_drain(_data: bytes) -> None:
    """The subscriptions' callback, never called: nothing spins them, drain_subscriptions
    takes their messages."""


def drain_subscriptions(
    subs: dict[str, Any], on_message: Callable[[str, bytes, dict[str, Any]], None], budget: int = DRAIN_BUDGET
) -> tuple[int, bool]:
    """Take the messages waiting in raw subscriptions ``{topic: subscription}`` straight from
    their handles, without an executor. Returns how many were taken and whether a topic still
    has more: at most ``budget`` per topic, so a flooding topic cannot starve the others. Call
    it from one thread only: each topic's order is then kept."""
    taken, more = 0, False
    for topic, sub in list(subs.items()):
        with sub.handle:
            for _ in range(budget):
                item = sub.handle.take_message(sub.msg_type, True)
                if item is None:
                    break
                on_message(topic, item[0], item[1])
                taken += 1
            else:
                more = True
    return taken, more


def drain_within(step: Callable[[], tuple[int, bool]], timeout: float,
                 clock: Callable[[], float] = time.monotonic) -> tuple[int, bool]:
    """Repeat ``step`` (a pass of :func:`drain_subscriptions`) while it leaves more, for at most
    ``timeout`` s after the first pass. Returns how many were taken and whether more was left."""
    deadline = clock() + timeout
    taken, more = step()
    while more and clock() < deadline:
        step_taken, more = step()
        taken += step_taken
    return taken, more


class RecorderNode(ManagedNode):
    """Records the selected topics into a new bag until stopped.

    Its subscriptions live on a second node that no executor spins: the recording loop takes
    their messages straight from the middleware (:func:`drain_subscriptions`). An executor's
    wait-set pass over every subscription cost about a millisecond per message with 40 topics.
    Between passes the loop sleeps in one wait on all of them (:class:`MessageArrivals`) and then
    takes from those that hold messages, rather than trying every queue 50 times a second.
    """

    def __init__(self, config: RecorderConfig, topics: list[str], **kwargs: Any) -> None:
        from hri_physio_bridge.bag.recording import RecordingSession
        from hri_physio_bridge.bag.writer import BagWriter

        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self.capture = Node(f"{self.get_name()}_capture", context=self.context,
                            start_parameter_services=False, enable_rosout=False)
        self.subs: dict[str, Any] = {}
        self.arrivals = MessageArrivals(self.capture)
        started = datetime.now()
        self.selector = TopicSelector(topics, cfg.regex or None, cfg.exclude or None, cfg.include_hidden)
        bag_dir = Path(cfg.output) if cfg.output else Path(cfg.output_dir) / bag_name(cfg.session_id, started)
        self.writer = BagWriter(
            bag_dir,
            chunk_size=cfg.chunk_size,
            flush_period=cfg.flush_period,
            fsync_period=cfg.fsync_period or None,
            compression=cfg.compression,
            custom_data={
                "session_id": cfg.session_id,
                "recorder": "hri_physio_bridge",
                "started": started.isoformat(timespec="seconds"),
            },
        )
        self.session = RecordingSession(self.writer, self.selector, logic_logger(PROG, self.get_logger()))

    def on_stop(self, signal_name: str) -> None:
        self.get_logger().info(f"{signal_name} received: closing the bag")
        self.arrivals.wake()

    def discover(self) -> None:
        from hri_physio_bridge.bag.recorded_qos import adapted_qos, qos_to_dict

        for cand in self.session.candidates(self.capture.get_topic_names_and_types()):
            infos = self.capture.get_publishers_info_by_topic(cand.topic)
            if not infos:
                continue  # no publisher yet: its offered QoS is unknown; try again later
            offered = [qos_to_dict(i.qos_profile) for i in infos]
            if self.session.start_topic(cand, offered, [str(i.topic_type_hash) for i in infos]):
                qos = _qos_profile(adapted_qos(offered, self.config.qos_depth))
                self.subs[cand.topic] = self.capture.create_subscription(
                    cand.msg_class, cand.topic, _taken_by_drain, qos, raw=True
                )

    def run(self, stop: threading.Event) -> int:
        cfg, writer, session, log = self.config, self.writer, self.session, self.get_logger()
        code = 0
        try:
            log.info(
                f"recording to {writer.bag_dir} ("
                f"{'all topics' if self.selector.records_all else 'selected topics'}; chunks flushed every "
                f"{writer.flush_period:g} s or {writer.chunk_size} bytes)"
            )
            session.check_disk(shutil.disk_usage(writer.bag_dir).free, 0.0)
            self.discover()
            tasks = Periodic()
            tasks.every(cfg.discovery_period, self.discover)
            tasks.every(min(writer.flush_period / 4, 0.25), writer.tick)
            last_status = time.monotonic()

            def report() -> None:
                nonlocal last_status
                now = time.monotonic()
                log.info(session.status(now - last_status))
                session.check_disk(shutil.disk_usage(writer.bag_dir).free, now - last_status)
                last_status = now

            tasks.every(cfg.status_period, report)
            ready: list[str] | None = None  # topics that hold messages (None: try every topic)
            while not stop.is_set() and self.context.ok():
                # Messages wait in the subscriptions' queues (stamped on arrival by the middleware)
                # and are taken in batches, at most one pass per poll_period, from the topics that hold
                # some; between passes the loop sleeps until a message arrives or a task is due (it
                # runs the timers itself).
                subs = self.subs if ready is None else {t: self.subs[t] for t in ready}
                _taken, more = drain_subscriptions(subs, session.on_message)
                tasks.run_due()
                if more:
                    ready = None
                    continue
                if stop.wait(cfg.poll_period):
                    break
                due = tasks.next_due_in()  # None: no task to wake for
                ready = self.arrivals.wait(self.subs, 1.0 if due is None else min(due, 1.0))
            code = self._drain_at_stop()
        except (BagError, OSError) as exc:
            log.error(f"recording failed: {exc}; nothing after this is recorded ({writer.bag_dir})")
            code = 1
        return self._close_bag() or code

    def _drain_at_stop(self) -> int:
        """Stopping: what arrived since the last pass goes into the bag too, within ``drain_timeout``.

        A topic still delivering after that (a publisher that did not stop) is left, said as an error.
        """
        timeout = self.config.drain_timeout
        taken, more = drain_within(lambda: drain_subscriptions(self.subs, self.session.on_message), timeout)
        if more:
            self.get_logger().error(
                f"stopping: messages still arrived after drain_timeout ({timeout:g} s; {taken} written "
                f"since the stop); what came after is not in the bag")
            return 1
        if taken:
            self.get_logger().info(f"stopping: wrote the {taken} message(s) that arrived before the stop")
        return 0

    def _close_bag(self) -> int:
        if self.writer.closed:
            return 0
        log = self.get_logger()
        try:
            self.session.finish()
            info = self.writer.close()
        except (BagError, OSError) as exc:
            # A full disk refuses the summary too: leave the file as a crash would (said once, not again
            # at the node's close), for --repair to recover what reached the disk.
            self.writer.abort()
            log.error(f"could not close the bag: {exc}; run '{PROG} --repair {self.writer.bag_dir}'")
            return 1
        log.info(
            f"bag closed: {self.writer.bag_dir} ({info.message_count} messages, "
            f"{self.writer.stats.file_bytes / 1e6:.2f} MB)"
        )
        for line in self.session.summary_lines(info):
            log.info("  " + line)
        return 0

    def close(self) -> None:
        self._close_bag()  # a bag is never left open, whatever ended the run
        for sub in self.subs.values():
            self.capture.destroy_subscription(sub)
        self.subs.clear()
        self.capture.destroy_node()


def _make_node(config: RecorderConfig, args: argparse.Namespace) -> RecorderNode:
    return RecorderNode(config, args.topics)


def _prog() -> str:
    return ALIAS if Path(sys.argv[0]).name == ALIAS else PROG


def main(argv: list[str] | None = None) -> int:
    prog = _prog()
    return run_node(
        prog, RecorderConfig, _make_node, argv=argv, description=__doc__, extra_arguments=_arguments,
        startup_errors=(BagError,),
        offline=lambda _cfg, args: run_repair(prog, args.repair, not args.no_backup) if args.repair else None,
    )


if __name__ == "__main__":
    sys.exit(main())

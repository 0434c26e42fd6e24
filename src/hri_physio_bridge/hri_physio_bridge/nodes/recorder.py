"""recorder: every ROS 2 topic (or a chosen set) into a rosbag2 directory with MCAP storage.

Examples::

    recorder --session-id P012                      # all topics -> bags/P012_<date-time>/
    recorder /physio/polar_h10/ecg /coach/state -o bags/run1
    recorder --regex '/physio/.*' --exclude '.*/status'
    recorder --repair bags/P012_2025_01_01-10_00_00   # fix a bag whose recorder was killed

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
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.topics import TopicSelector, bag_name
from hri_physio_bridge.bag.writer import DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_PERIOD, DEFAULT_FSYNC_PERIOD
from hri_physio_bridge.nodes.common import fail, install_stop_handlers, logic_logger, split_ros_args
from hri_physio_bridge.periodic import Periodic

PROG = "recorder"
DEFAULT_POLL_PERIOD = 0.02
#: Messages taken per topic per pass before the timers run again.
DRAIN_BUDGET = 2000


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("topics", nargs="*", help="topics to record (default: all topics)")
    p.add_argument("-e", "--regex", help="also record topics whose full name matches this expression")
    p.add_argument("-x", "--exclude", help="never record topics whose full name matches this expression")
    p.add_argument(
        "--include-hidden", action="store_true", help="record hidden topics (a part starting with '_')"
    )
    p.add_argument(
        "-o", "--output", help="bag directory to create (default: OUTPUT_DIR/SESSION_ID_<date-time>)"
    )
    p.add_argument("--output-dir", default="bags", help="where bags are created (default: bags)")
    p.add_argument(
        "--session-id", default="session", help="pseudonymous session id in the bag name (default: session)"
    )
    p.add_argument(
        "--discovery-period", type=_positive, default=0.5, help="seconds between graph polls (default 0.5)"
    )
    p.add_argument(
        "--status-period", type=_positive, default=5.0, help="seconds between progress reports (default 5)"
    )
    p.add_argument(
        "--chunk-size",
        type=int,
        default=DEFAULT_CHUNK_SIZE,
        help=f"MCAP chunk size in bytes before compression (default {DEFAULT_CHUNK_SIZE})",
    )
    p.add_argument(
        "--flush-period",
        type=_positive,
        default=DEFAULT_FLUSH_PERIOD,
        help=f"close and write out a chunk at least this often, seconds: the most a crash "
        f"loses (default {DEFAULT_FLUSH_PERIOD:g})",
    )
    p.add_argument(
        "--fsync-period",
        type=_non_negative,
        default=DEFAULT_FSYNC_PERIOD,
        help=f"fsync at most this often, seconds; 0 = only at the end (default {DEFAULT_FSYNC_PERIOD:g})",
    )
    p.add_argument(
        "--compression", choices=("zstd", "none"), default="zstd", help="chunk compression (default zstd)"
    )
    p.add_argument(
        "--qos-depth",
        type=int,
        default=10000,
        help="subscription queue depth (default 10000); must hold what a topic sends in one poll period",
    )
    p.add_argument(
        "--poll-period",
        type=_positive,
        default=DEFAULT_POLL_PERIOD,
        help=f"seconds between takes of queued messages while they flow (default {DEFAULT_POLL_PERIOD:g}); "
        "receive stamps come from the middleware, so this only delays the disk",
    )
    p.add_argument(
        "--repair",
        metavar="BAG",
        help="do not record: repair BAG (directory or .mcap) whose recorder was killed, then exit",
    )
    p.add_argument("--no-backup", action="store_true", help="with --repair: do not keep the damaged file")
    return p


def run_repair(target: str, keep: bool) -> int:
    from hri_physio_bridge.bag.recovery import repair_bag

    try:
        rep = repair_bag(Path(target), keep_damaged=keep)
    except BagError as exc:
        fail(PROG, str(exc), 1)
    scan = rep.scan
    state = "was complete" if scan.complete else f"was incomplete ({scan.problem})"
    print(
        f"{PROG}: {rep.mcap} {state}; recovered {scan.messages} messages on {len(rep.info.topics)} topic(s), "
        f"dropped {scan.lost_bytes} trailing bytes, {scan.corrupt_chunks} damaged chunk(s)"
    )
    for t in rep.info.topics:
        print(f"  {t.name} [{t.type}]: {t.message_count}")
    if rep.backup is not None:
        print(f"{PROG}: original kept as {rep.backup}")
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


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    if args.repair:
        return run_repair(args.repair, not args.no_backup)
    if args.qos_depth < 1:
        fail(PROG, f"--qos-depth must be >= 1, got {args.qos_depth}")

    from hri_physio_bridge.bag.writer import BagWriter

    started = datetime.now()
    try:
        selector = TopicSelector(args.topics, args.regex, args.exclude, args.include_hidden)
        default_name = bag_name(args.session_id, started)  # validates the session id too
        bag_dir = Path(args.output) if args.output else Path(args.output_dir) / default_name
        writer = BagWriter(
            bag_dir,
            chunk_size=args.chunk_size,
            flush_period=args.flush_period,
            fsync_period=args.fsync_period or None,
            compression=args.compression,
            custom_data={
                "session_id": args.session_id,
                "recorder": "hri_physio_bridge",
                "started": started.isoformat(timespec="seconds"),
            },
        )
    except BagError as exc:
        fail(PROG, str(exc))
    return _record(args, ros_args, selector, writer)


def _record(args: argparse.Namespace, ros_args: list[str], selector: TopicSelector, writer: Any) -> int:
    import rclpy
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    from hri_physio_bridge.bag.qos import adapted_qos, qos_to_dict
    from hri_physio_bridge.bag.recording import RecordingSession

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = Node(PROG, start_parameter_services=False)
    log = node.get_logger()
    session = RecordingSession(writer, selector, logic_logger(PROG, log))
    stop = install_stop_handlers(lambda name: log.info(f"{name} received: closing the bag"))
    subs: dict[str, Any] = {}

    def discover() -> None:
        for cand in session.candidates(node.get_topic_names_and_types()):
            infos = node.get_publishers_info_by_topic(cand.topic)
            if not infos:
                continue  # no publisher yet: its offered QoS is unknown; try again later
            offered = [qos_to_dict(i.qos_profile) for i in infos]
            if session.start_topic(cand, offered, [str(i.topic_type_hash) for i in infos]):
                qos = _qos_profile(adapted_qos(offered, args.qos_depth))
                subs[cand.topic] = node.create_subscription(
                    cand.msg_class, cand.topic, _taken_by_drain, qos, raw=True
                )

    code = 0
    try:
        log.info(
            f"recording to {writer.bag_dir} ("
            f"{'all topics' if selector.records_all else 'selected topics'}; chunks flushed every "
            f"{writer.flush_period:g} s or {writer.chunk_size} bytes)"
        )
        session.check_disk(shutil.disk_usage(writer.bag_dir).free, 0.0)
        discover()
        tasks = Periodic()
        tasks.every(args.discovery_period, discover)
        tasks.every(min(writer.flush_period / 4, 0.25), writer.tick)
        last_status = time.monotonic()

        def report() -> None:
            nonlocal last_status
            now = time.monotonic()
            log.info(session.status(now - last_status))
            session.check_disk(shutil.disk_usage(writer.bag_dir).free, now - last_status)
            last_status = now

        tasks.every(args.status_period, report)
        while not stop.is_set() and rclpy.ok():
            # Messages wait in the subscriptions' queues (stamped on arrival by the middleware)
            # and are taken in batches every --poll-period. No executor: its wait-set pass,
            # over every subscription's QoS event handlers too, cost about a millisecond per
            # message with 40 topics; this loop runs the timers itself.
            _taken, more = drain_subscriptions(subs, session.on_message)
            tasks.run_due()
            if not more:
                stop.wait(args.poll_period)
        while drain_subscriptions(subs, session.on_message)[1]:
            pass  # stopping: what arrived since the last pass goes into the bag too
    except (BagError, OSError) as exc:
        log.error(f"recording failed: {exc}")
        code = 1
    finally:
        for sub in subs.values():
            node.destroy_subscription(sub)
        if not writer.closed:
            try:
                session.finish()
                info = writer.close()
                log.info(
                    f"bag closed: {writer.bag_dir} ({info.message_count} messages, "
                    f"{writer.stats.file_bytes / 1e6:.2f} MB)"
                )
                for line in session.summary_lines(info):
                    log.info("  " + line)
            except (BagError, OSError) as exc:
                log.error(f"could not close the bag: {exc}; run '{PROG} --repair {writer.bag_dir}'")
                code = 1
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())

"""replayer: play a rosbag2 directory (MCAP) or a bare .mcap file back onto ROS 2.

Examples::

    replayer bags/P012_2025_01_01-10_00_00                  # original timing
    replayer run.mcap --rate 20 --loop                       # 20x faster, forever
    replayer BAG --rate 0 --topics /physio/polar_h10/ecg      # as fast as possible, in order
    replayer BAG --clock --clock-step 0.01 --start-offset 30  # drive use_sim_time nodes
    replayer BAG --remap /physio/polar_h10/ecg:=/replay/ecg
    replayer BAG --info

Messages are published as stored (raw CDR), with each topic's recorded QoS (reliable /
transient-local only if every recorded publisher offered it).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.playback import NS, PlaybackOptions, Player
from hri_physio_bridge.bag.reader import BagMessage, BagReader
from hri_physio_bridge.bag.topics import TopicSelector, parse_remaps
from hri_physio_bridge.nodes.common import fail, install_stop_handlers, split_ros_args

PROG = "replayer"


def _number(low: float, strict: bool) -> Any:
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if value < low or (strict and value == low):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {low:g}, got {text}")
        return value

    return parse


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("bag", help="rosbag2 directory or .mcap file")
    p.add_argument(
        "-r",
        "--rate",
        type=_number(0, False),
        default=1.0,
        help="speed factor (default 1; 0 = as fast as possible, order kept)",
    )
    p.add_argument("-l", "--loop", action="store_true", help="start again at the end, until stopped")
    p.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="play only these topics")
    p.add_argument("-e", "--regex", help="play only topics whose full name matches (with --topics: either)")
    p.add_argument("-x", "--exclude", help="never play topics whose full name matches")
    p.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO", help="publish topic FROM as TO")
    p.add_argument(
        "--start-offset",
        type=_number(0, False),
        default=0.0,
        help="skip the first SECONDS of the bag (default 0)",
    )
    p.add_argument(
        "--clock", action="store_true", help="publish /clock from the bag's time (for use_sim_time)"
    )
    p.add_argument(
        "--clock-step",
        type=_number(0, True),
        default=0.01,
        help="bag seconds between /clock messages; keep it <= the shortest timer period of "
        "the nodes on sim time (default 0.01)",
    )
    p.add_argument(
        "--skip-unknown",
        action="store_true",
        help="leave out topics whose message type is not installed (default: refuse to play)",
    )
    p.add_argument(
        "--wait-for-subscribers",
        type=_number(0, False),
        default=0.0,
        metavar="SECONDS",
        help="wait up to SECONDS for a subscriber on every played topic before starting",
    )
    p.add_argument("--delay", type=_number(0, False), default=0.0, help="seconds to sleep before playing")
    p.add_argument("--qos-depth", type=int, default=1000, help="publisher queue depth (default 1000)")
    p.add_argument("--info", action="store_true", help="print what the bag holds and exit")
    return p


def print_info(bag: BagReader) -> None:
    start, end = bag.start_ns, bag.end_ns
    duration = (end - start) / NS if start is not None and end is not None else 0.0
    print(f"bag:       {bag.path}")
    print(f"complete:  {'yes' if bag.complete else 'no (recorder did not finish)'}")
    print(f"duration:  {duration:.3f} s")
    print(f"start:     {start} ns" if start is not None else "start:     -")
    print(f"messages:  {bag.message_count}")
    for t in bag.topics.values():
        print(f"  {t.name} [{t.type}] {t.message_count} msgs, hash {t.type_description_hash or '-'}")
    for key, value in bag.custom_data.items():
        print(f"custom:    {key}: {value}")


def select(bag: BagReader, args: argparse.Namespace) -> dict[str, Any]:
    """Topics to play and their Python classes; unknown types fail unless --skip-unknown."""
    from hri_physio_bridge.bag.msgdefs import UnknownTypeError, import_message_type

    if bag.message_count == 0:
        raise BagError(f"{bag.path}: the bag holds no messages (empty bag)")
    selector = TopicSelector(args.topics, args.regex, args.exclude, include_hidden=True)
    missing = [t for t in args.topics if t not in bag.topics]
    if missing:
        raise BagError(f"topic(s) {missing} not in the bag; it holds {sorted(bag.topics)}")
    chosen = {name: info for name, info in bag.topics.items() if selector.selects(name)}
    if not chosen:
        raise BagError(f"no topic of the bag is selected; it holds {sorted(bag.topics)}")
    classes: dict[str, Any] = {}
    unknown = []
    for name, info in chosen.items():
        try:
            classes[name] = import_message_type(info.type)
        except UnknownTypeError:
            unknown.append(f"{name} [{info.type}]")
    if unknown and not args.skip_unknown:
        raise BagError(
            f"message type(s) not installed for {', '.join(unknown)}; install them, leave the "
            "topics out (--exclude) or pass --skip-unknown"
        )
    for item in unknown:
        print(f"{PROG}: warning: skipping {item}: message type not installed", file=sys.stderr)
    if not classes or sum(bag.topics[t].message_count for t in classes) == 0:
        raise BagError(f"{bag.path}: the bag has no messages on the selected topics (empty bag)")
    return classes


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    if args.qos_depth < 1:
        fail(PROG, f"--qos-depth must be >= 1, got {args.qos_depth}")
    try:
        bag = BagReader(args.bag)
        for warning in bag.warnings:
            print(f"{PROG}: warning: {warning}", file=sys.stderr)
        if args.info:
            print_info(bag)
            return 0
        remaps = parse_remaps(args.remap)
        classes = select(bag, args)
        assert bag.start_ns is not None and bag.end_ns is not None
        start_ns = bag.start_ns + round(args.start_offset * NS)
        if start_ns > bag.end_ns:
            raise BagError(
                f"--start-offset {args.start_offset:g} s is past the bag's end "
                f"({(bag.end_ns - bag.start_ns) / NS:.3f} s)"
            )
        options = PlaybackOptions(
            rate=args.rate, loop=args.loop, clock_step_ns=round(args.clock_step * NS) if args.clock else None
        )
    except BagError as exc:
        fail(PROG, str(exc))
    return _play(args, ros_args, bag, classes, remaps, start_ns, options)


def _play(
    args: argparse.Namespace,
    ros_args: list[str],
    bag: BagReader,
    classes: dict[str, Any],
    remaps: dict[str, str],
    start_ns: int,
    options: PlaybackOptions,
) -> int:
    import time

    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.duration import Duration
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from rosgraph_msgs.msg import Clock

    from hri_physio_bridge.bag.qos import adapted_qos

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = Node(PROG, start_parameter_services=False)
    log = node.get_logger()
    stop = install_stop_handlers(lambda name: log.info(f"{name} received: stopping playback"))
    code = 0
    try:
        pubs: dict[str, Any] = {}
        for topic, cls in classes.items():
            q = adapted_qos(bag.topics[topic].offered_qos_profiles, args.qos_depth)
            qos = QoSProfile(
                depth=q["depth"],
                reliability=ReliabilityPolicy.RELIABLE
                if q["reliability"] == "reliable"
                else ReliabilityPolicy.BEST_EFFORT,
                durability=DurabilityPolicy.TRANSIENT_LOCAL
                if q["durability"] == "transient_local"
                else DurabilityPolicy.VOLATILE,
            )
            pubs[topic] = node.create_publisher(cls, remaps.get(topic, topic), qos)
        clock_pub = node.create_publisher(Clock, "/clock", 100) if options.clock_step_ns else None

        def publish(msg: BagMessage) -> None:
            pubs[msg.topic].publish(msg.data)

        def publish_clock(t_ns: int) -> None:
            assert clock_pub is not None
            clock_pub.publish(Clock(clock=Time(sec=t_ns // NS, nanosec=t_ns % NS)))

        if args.wait_for_subscribers > 0:
            deadline = time.monotonic() + args.wait_for_subscribers
            while not stop.is_set() and time.monotonic() < deadline:
                if all(p.get_subscription_count() > 0 for p in pubs.values()):
                    break
                time.sleep(0.05)
            else:
                lonely = [p.topic_name for p in pubs.values() if p.get_subscription_count() == 0]
                if lonely:
                    log.warning(
                        f"no subscriber after {args.wait_for_subscribers:g} s on {lonely}; playing anyway"
                    )
        if args.delay and stop.wait(args.delay):
            return 0
        total = sum(bag.topics[t].message_count for t in classes)
        log.info(
            f"playing {bag.path}: {len(pubs)} topic(s), {total} messages, rate "
            f"{'max' if options.rate == 0 else f'{options.rate:g}x'}{', loop' if options.loop else ''}"
            f"{', /clock' if clock_pub else ''}"
        )
        player = Player(
            lambda: bag.messages(classes.keys(), start_ns),
            publish,
            options,
            publish_clock=publish_clock if clock_pub else None,
            stop=stop,
        )
        try:
            stats = player.run()
        except BagError as exc:
            log.error(str(exc))
            return 1
        for pub in pubs.values():
            pub.wait_for_all_acked(Duration(seconds=2.0))
        log.info(
            f"played {stats.messages} messages in {stats.passes} pass(es)"
            f"{f', {stats.clock_ticks} clock ticks' if clock_pub else ''}"
            f"{' (stopped)' if stats.stopped else ''}; max lateness {stats.max_lateness * 1e3:.1f} ms"
        )
        for topic, n in sorted(stats.per_topic.items()):
            log.info(f"  {topic}{' -> ' + remaps[topic] if topic in remaps else ''}: {n}")
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())

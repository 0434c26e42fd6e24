"""physio_replayer (alias replayer): play a rosbag2 directory (MCAP) or a bare .mcap file back onto ROS 2.

Examples::

    physio_replayer bags/P012_2025_01_01-10_00_00                  # original timing
    physio_replayer run.mcap --rate 20 --loop                       # 20x faster, forever
    physio_replayer BAG --rate 0 --topics /physio/polar_h10/ecg      # as fast as possible, in order
    physio_replayer BAG --clock --clock-step 0.01 --start-offset 30  # drive use_sim_time nodes
    physio_replayer BAG --remap /physio/polar_h10/ecg:=/replay/ecg
    physio_replayer BAG --info

Messages are published as stored (raw CDR), with each topic's recorded QoS (reliable /
transient-local only if every recorded publisher offered it).
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.options import ReplayerConfig
from hri_physio_bridge.bag.playback import NS, PlaybackOptions, Player
from hri_physio_bridge.bag.reader import BagMessage, BagReader
from hri_physio_bridge.bag.topic_selection import TopicSelector
from hri_physio_bridge.node_runner import ManagedNode, run_node
from hri_physio_bridge.ros_tools import wait_all_acked
from hri_physio_bridge.waiting import wait_until

PROG = "physio_replayer"
#: The older, shorter name of the same command (kept: users and scripts type it).
ALIAS = "replayer"
#: rcl takes any ``a:=b`` outside ``--ros-args`` for a (deprecated) remapping of its own. The
#: values of --remap are ours: they reach the option parser spelled ``a=>b`` and are turned back.
_REMAP_IN_TRANSIT = "=>"


def _keep_remaps_from_rcl(argv: list[str]) -> list[str]:
    out, in_remap = list(argv), False
    for i, token in enumerate(out):
        if token == "--ros-args":
            break
        if token.startswith("-"):
            in_remap = token == "--remap"
        elif in_remap:
            out[i] = token.replace(":=", _REMAP_IN_TRANSIT)
    return out


def _arguments(p: argparse.ArgumentParser) -> None:
    """The bag, the --info mode (no ROS), and the options written their own way on the command line."""
    p.add_argument("bag", help="rosbag2 directory or .mcap file")
    p.add_argument("--info", action="store_true",
                   help="print what the bag holds (checking every chunk's CRC) and exit")
    also = "; also a --conf key and ROS parameter"
    p.add_argument("-r", "--rate", dest="rate", default=None, metavar="NUM",
                   help=ReplayerConfig.describe("rate") + also)
    p.add_argument("-l", "--loop", dest="loop", action="store_const", const=True, default=None,
                   help=ReplayerConfig.describe("loop") + also)
    p.add_argument("-e", "--regex", dest="regex", default=None, metavar="REGEX",
                   help=ReplayerConfig.describe("regex") + also)
    p.add_argument("-x", "--exclude", dest="exclude", default=None, metavar="REGEX",
                   help=ReplayerConfig.describe("exclude") + also)
    p.add_argument("--topics", dest="topics", nargs="+", default=None, metavar="TOPIC",
                   help=ReplayerConfig.describe("topics") + also)
    p.add_argument("--remap", dest="remap", nargs="+", default=None, metavar="FROM:=TO",
                   type=lambda text: text.replace(_REMAP_IN_TRANSIT, ":="),
                   help=ReplayerConfig.describe("remap") + also)


def print_info(bag: BagReader, prog: str = PROG) -> None:
    """What the bag holds, and whether all of it can be read back: every chunk's CRC is checked."""
    start, end = bag.start_ns, bag.end_ns
    duration = (end - start) / NS if start is not None and end is not None else 0.0
    damaged = bag.damaged_chunks()
    problems = [] if bag.complete else ["recorder did not finish"]
    if damaged:
        at_least = "at least " if any(c.messages is None for _, c in damaged) and not bag.complete else ""
        problems.append(f"{len(damaged)} damaged chunk(s) holding {at_least}{bag.unreadable_messages} "
                        f"message(s); playback {'stops at the first' if bag.complete else 'skips them'}, "
                        "'physio_recorder --repair' keeps the rest")
    print(f"bag:       {bag.path}")
    print(f"complete:  {'no (' + '; '.join(problems) + ')' if problems else 'yes'}")
    print(f"duration:  {duration:.3f} s")
    print(f"start:     {start} ns" if start is not None else "start:     -")
    print(f"messages:  {bag.message_count}")
    for t in bag.topics.values():
        print(f"  {t.name} [{t.type}] {t.message_count} msgs, hash {t.type_description_hash or '-'}")
    for path, chunk in damaged:
        print(f"damaged:   {path.name}: {chunk.describe()}")
    for key, value in bag.custom_data.items():
        print(f"custom:    {key}: {value}")


def select(bag: BagReader, cfg: ReplayerConfig, warn: Callable[[str], None]) -> dict[str, Any]:
    """Topics to play and their Python classes; unknown types fail unless --skip-unknown."""
    from hri_physio_bridge.bag.msgdefs import UnknownTypeError, import_message_type

    if bag.message_count == 0:
        raise BagError(f"{bag.path}: the bag holds no messages (empty bag)")
    selector = TopicSelector(cfg.topics, cfg.regex or None, cfg.exclude or None, include_hidden=True)
    missing = [t for t in cfg.topics if t not in bag.topics]
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
    if unknown and not cfg.skip_unknown:
        raise BagError(
            f"message type(s) not installed for {', '.join(unknown)}; install them, leave the "
            "topics out (--exclude) or pass --skip-unknown"
        )
    for item in unknown:
        warn(f"skipping {item}: message type not installed")
    if not classes or sum(bag.topics[t].message_count for t in classes) == 0:
        raise BagError(f"{bag.path}: the bag has no messages on the selected topics (empty bag)")
    return classes


class ReplayerNode(ManagedNode):
    """Publishes a bag's messages on their recorded topics (or remapped), on schedule."""

    def __init__(self, config: ReplayerConfig, bag: BagReader, **kwargs: Any) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        from hri_physio_bridge.bag.recorded_qos import adapted_qos

        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self.bag = bag
        self.remaps = cfg.remaps()
        self.classes = select(bag, cfg, self.get_logger().warning)
        assert bag.start_ns is not None and bag.end_ns is not None
        self.start_ns = bag.start_ns + round(cfg.start_offset * NS)
        if self.start_ns > bag.end_ns:
            raise BagError(
                f"start_offset {cfg.start_offset:g} s is past the bag's end "
                f"({(bag.end_ns - bag.start_ns) / NS:.3f} s)"
            )
        self.options = PlaybackOptions(
            rate=cfg.rate, loop=cfg.loop, clock_step_ns=round(cfg.clock_step * NS) if cfg.clock else None
        )
        self.pubs: dict[str, Any] = {}
        for topic, cls in self.classes.items():
            q = adapted_qos(bag.topics[topic].offered_qos_profiles, cfg.qos_depth)
            qos = QoSProfile(
                depth=q["depth"],
                reliability=ReliabilityPolicy.RELIABLE
                if q["reliability"] == "reliable"
                else ReliabilityPolicy.BEST_EFFORT,
                durability=DurabilityPolicy.TRANSIENT_LOCAL
                if q["durability"] == "transient_local"
                else DurabilityPolicy.VOLATILE,
            )
            self.pubs[topic] = self.create_publisher(cls, self.remaps.get(topic, topic), qos)
        self.clock_pub = self.create_publisher(Clock, "/clock", 100) if self.options.clock_step_ns else None

    def on_stop(self, signal_name: str) -> None:
        self.get_logger().info(f"{signal_name} received: stopping playback")

    def _publish(self, msg: BagMessage) -> None:
        self.pubs[msg.topic].publish(msg.data)

    def _publish_clock(self, t_ns: int) -> None:
        from builtin_interfaces.msg import Time
        from rosgraph_msgs.msg import Clock

        assert self.clock_pub is not None
        self.clock_pub.publish(Clock(clock=Time(sec=t_ns // NS, nanosec=t_ns % NS)))

    def run(self, stop: threading.Event) -> int:

        cfg, bag, log, pubs = self.config, self.bag, self.get_logger(), self.pubs
        if cfg.wait_for_subscribers > 0:
            everyone = wait_until(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()),
                                  cfg.wait_for_subscribers, stop=stop)
            lonely = [p.topic_name for p in pubs.values() if p.get_subscription_count() == 0]
            if not everyone and not stop.is_set() and lonely:
                log.warning(f"no subscriber after {cfg.wait_for_subscribers:g} s on {lonely}; playing anyway")
        if stop.is_set() or (cfg.delay and stop.wait(cfg.delay)):
            return 0
        options = self.options
        total = sum(bag.topics[t].message_count for t in self.classes)
        log.info(
            f"playing {bag.path}: {len(pubs)} topic(s), {total} messages, rate "
            f"{'max' if options.rate == 0 else f'{options.rate:g}x'}{', loop' if options.loop else ''}"
            f"{', /clock' if self.clock_pub else ''}"
        )
        player = Player(
            lambda: bag.messages(self.classes.keys(), self.start_ns),
            self._publish,
            options,
            publish_clock=self._publish_clock if self.clock_pub else None,
            stop=stop,
        )
        try:
            stats = player.run()
        except BagError as exc:
            log.error(str(exc))
            return 1
        wait_all_acked(pubs.values(), 2.0)
        log.info(
            f"played {stats.messages} messages in {stats.passes} pass(es)"
            f"{f', {stats.clock_ticks} clock ticks' if self.clock_pub else ''}"
            f"{' (stopped)' if stats.stopped else ''}; max lateness {stats.max_lateness * 1e3:.1f} ms"
        )
        for topic, n in sorted(stats.per_topic.items()):
            log.info(f"  {topic}{' -> ' + self.remaps[topic] if topic in self.remaps else ''}: {n}")
        return 0


def _prog() -> str:
    return ALIAS if Path(sys.argv[0]).name == ALIAS else PROG


def main(argv: list[str] | None = None) -> int:
    prog = _prog()

    def open_bag(_config: ReplayerConfig, args: argparse.Namespace) -> int | None:
        """Before ROS starts: open the bag (errors are one line), and answer --info."""
        args.reader = BagReader(args.bag)
        for warning in args.reader.warnings:
            print(f"{prog}: warning: {warning}", file=sys.stderr)
        if args.info:
            print_info(args.reader, prog)
            return 0
        return None

    argv = _keep_remaps_from_rcl(sys.argv[1:] if argv is None else argv)
    return run_node(
        prog, ReplayerConfig, lambda config, args: ReplayerNode(config, args.reader), argv=argv,
        description=__doc__, extra_arguments=_arguments, startup_errors=(BagError,), offline=open_bag,
    )


if __name__ == "__main__":
    sys.exit(main())

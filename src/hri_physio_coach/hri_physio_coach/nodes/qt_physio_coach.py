"""qt_physio_coach: the QT cardio-aware exercise coach as a ROS 2 node.

A thin shell around :class:`hri_physio_coach.coach.ExerciseCoach`: heart-rate frames in
(one-sample frames ``[t, bpm]``, std_msgs/Float64MultiArray), robot commands out on
/QtController/input, replies from /QtController/output, every decision as a JSON event on
/coach/events and a state snapshot on /coach/state. The session runs on the node's ROS
clock, so with ``use_sim_time`` it follows /clock and can run many times faster than real
time. The node exits (status 0) when the session ends, and on SIGINT/SIGTERM.

Examples::

    qt_physio_coach                                   # starts at once, packaged coach.yaml
    qt_physio_coach --interactive                     # waits for 'start' on stdin or /coach/control
    qt_physio_coach --conf my_coach.yaml --policy fuzzy --ros-args -p part_age:=45.0
    qt_physio_coach --ros-args -p use_sim_time:=true -p hr_topic:=/physio/polar_h10/ecg/hr
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge.frames import FrameFormatError
from hri_physio_bridge.nodes.common import install_stop_handlers, split_ros_args
from hri_physio_bridge.qos import frame_qos
from hri_physio_bridge.ros_frames import msg_to_frame
from hri_physio_coach.coach import CoachError, ExerciseCoach
from hri_physio_coach.config import (
    SCALAR_KEYS,
    CoachConfig,
    ConfigError,
    config_from_mapping,
    read_config_file,
)
from hri_physio_coach.paths import default_config_file
from hri_physio_coach.policies import POLICY_NAMES
from hri_physio_coach.routine import RoutineError

PROG = "qt_physio_coach"
NODE_OPTIONS: dict[str, Any] = {
    "hr_topic": "/physio/polar_h10/hr",
    "command_topic": "/QtController/input",
    "reply_topic": "/QtController/output",
    "events_topic": "/coach/events",
    "state_topic": "/coach/state",
    "control_topic": "/coach/control",
    "interactive": False,
    "tick_period": 0.1,
}
HR_CHANNELS = ("hr", "bpm", "heart_rate")
FLAG_CHANNEL = "flag"
# Events worth a line in the ROS log (all of them go to /coach/events).
_LOGGED = {"session_start", "phase", "activity", "calibration", "zone", "rule_update", "hr_lost",
           "hr_resumed", "command_failed", "session_end", "session_stopped"}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Precedence: defaults < --conf file < command-line options < --ros-args parameters. "
        "Node parameters: " + ", ".join(f"{k} (default {v!r})" for k, v in NODE_OPTIONS.items())
        + "; every scalar key of coach.yaml is a parameter too (" + ", ".join(SCALAR_KEYS) + ").",
    )
    parser.add_argument("--conf",
                        help=f"coach YAML file (default: the packaged {default_config_file().name})")
    parser.add_argument("--interactive", action="store_true", default=None,
                        help="wait for 'start' on stdin or on the control topic before starting")
    parser.add_argument("--policy", choices=POLICY_NAMES, default=None, help="adaptation policy")
    parser.add_argument("--hr-topic", default=None,
                        help=f"heart-rate frames (default {NODE_OPTIONS['hr_topic']})")
    return parser


def hr_samples(msg: Float64MultiArray) -> list[tuple[float, float, bool]]:
    """(source time, bpm, flagged) of every sample of an HR frame (DESIGN.md layout)."""
    frame = msg_to_frame(msg)
    names = [c.lower() for c in frame.channels]
    column = next((names.index(n) for n in HR_CHANNELS if n in names), 0)
    flag = names.index(FLAG_CHANNEL) if FLAG_CHANNEL in names else None
    out = []
    for i in range(frame.num_samples):
        flagged = flag is not None and float(frame.values[i, flag]) != 0.0
        out.append((float(frame.timestamps[i]), float(frame.values[i, column]), flagged))
    return out


class QtPhysioCoachNode(Node):
    """Parameters, topics and the tick timer around an :class:`ExerciseCoach`."""

    def __init__(self, file_values: dict[str, Any], cli: dict[str, Any], **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        dynamic = ParameterDescriptor(dynamic_typing=True)
        opts = {}
        for key, default in NODE_OPTIONS.items():
            self.declare_parameter(key, cli.get(key, default), dynamic)
            opts[key] = self.get_parameter(key).value
        defaults = CoachConfig().as_dict()
        values = dict(file_values)
        for key in SCALAR_KEYS:
            if key in cli:
                values[key] = cli[key]
            self.declare_parameter(key, values.get(key, defaults[key]), dynamic)
            values[key] = self.get_parameter(key).value
        self.config = config_from_mapping(values, "configuration")
        self.opts = opts
        period = opts["tick_period"]
        if isinstance(period, bool) or not isinstance(period, int | float) or not period > 0:
            raise ConfigError(f"tick_period must be > 0 s, got {period!r}")
        self.interactive = bool(opts["interactive"])
        self.coach = ExerciseCoach(self.config, self._now, self._send, self._on_event)
        reliable = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
        self.commands = self.create_publisher(String, opts["command_topic"], reliable)
        self.events = self.create_publisher(String, opts["events_topic"], QoSProfile(depth=2000))
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.state_pub = self.create_publisher(String, opts["state_topic"], latched)
        self.create_subscription(Float64MultiArray, opts["hr_topic"], self._on_hr, frame_qos())
        self.create_subscription(String, opts["reply_topic"], self._on_reply, 200)
        self.create_subscription(String, opts["control_topic"], self._on_control, 10)
        self._start_requested = threading.Event()
        self._stop_reason: str | None = None
        self._state_dirty = False
        self.create_timer(float(period), self._tick)
        self.get_logger().info(
            f"participant {self.coach.participant}, policy {self.config.policy}, routine "
            f"{self.coach.routine.name} ({self.coach.routine.duration / 60:.1f} min), "
            f"HR from {opts['hr_topic']}"
            + (": waiting for 'start'" if self.interactive else "")
        )

    # --- plumbing ----------------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _send(self, line: str) -> None:
        self.commands.publish(String(data=line))

    def _on_event(self, event: dict[str, Any]) -> None:
        self.events.publish(String(data=to_json(event)))
        self._state_dirty = True
        kind = event.get("event")
        if kind in _LOGGED:
            text = _summary(event)
            if kind in ("command_failed", "hr_lost"):
                self.get_logger().warning(text)
            else:
                self.get_logger().info(text)

    def _on_hr(self, msg: Float64MultiArray) -> None:
        try:
            samples = hr_samples(msg)
        except FrameFormatError as exc:
            self.get_logger().warning(f"ignoring a malformed HR frame: {exc}")
            return
        now = self._now()
        for source_t, bpm, flagged in samples:
            self.coach.on_hr(bpm, now=now, flagged=flagged, source_t=source_t)

    def _on_reply(self, msg: String) -> None:
        try:
            reply = json.loads(msg.data)
        except ValueError:
            self.get_logger().warning(f"ignoring a reply that is not JSON: {msg.data[:80]!r}")
            return
        if isinstance(reply, dict):
            self.coach.on_reply(reply)

    def _on_control(self, msg: String) -> None:
        self.request(msg.data)

    def request(self, word: str) -> None:
        """``start`` or ``stop``/``exit`` from the control topic or stdin."""
        word = word.strip().lower()
        if word == "start":
            self._start_requested.set()
        elif word in ("stop", "exit"):
            self._stop_reason = f"{word} requested"
        elif word:
            self.get_logger().warning(f"unknown control word {word!r} (start, stop)")

    def _tick(self) -> None:
        now = self._now()
        if now <= 0.0:
            return  # sim time without /clock yet
        if self._stop_reason and not self.coach.finished:
            self.coach.stop(self._stop_reason)
        if not self.coach.started and not self.coach.finished:
            if self.interactive and not self._start_requested.is_set():
                return
            self.coach.start(now)
        self.coach.tick(now)
        if self._state_dirty:
            self._state_dirty = False
            self.state_pub.publish(String(data=to_json(self.coach.state())))

    @property
    def done(self) -> bool:
        return self.coach.finished

    def flush(self, timeout: float = 2.0) -> None:
        for pub in (self.commands, self.events):
            pub.wait_for_all_acked(Duration(seconds=timeout))


def _finite(value: Any) -> Any:
    """JSON has no NaN/inf: they become null (recursively)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def to_json(event: dict[str, Any]) -> str:
    """One event as strict JSON (anything not JSON-native is written as text)."""
    return json.dumps(_finite(event), allow_nan=False, default=str)


def _summary(event: dict[str, Any]) -> str:
    kind = event["event"]
    t = event.get("t", 0.0)
    if kind == "rule_update":
        d = event["decision"]
        hr = event["inputs"]["hr_mean"]
        hr_text = "-" if hr is None else f"{hr:.1f}"
        return (f"[{t:.1f}] rule update: HR {hr_text} -> {d['action']} ({d['reason']}), "
                f"step {d['index_after']}")
    detail = {k: v for k, v in event.items() if k not in ("t", "event", "participant")}
    return f"[{t:.1f}] {kind}: {to_json(detail)[:200]}"


def _stdin_reader(node: QtPhysioCoachNode) -> None:
    print("type 'start' to begin the session ('stop' ends it)", flush=True)
    for line in sys.stdin:
        node.request(line)


def _cli_values(args: argparse.Namespace) -> dict[str, Any]:
    cli: dict[str, Any] = {}
    if args.interactive:
        cli["interactive"] = True
    if args.policy:
        cli["policy"] = args.policy
    if args.hr_topic:
        cli["hr_topic"] = args.hr_topic
    return cli


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    try:
        file_values = read_config_file(args.conf or default_config_file(), PROG)
    except ConfigError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node: QtPhysioCoachNode | None = None
    executor = SingleThreadedExecutor()
    try:
        try:
            node = QtPhysioCoachNode(file_values, _cli_values(args))
        except (ConfigError, CoachError, RoutineError, ParameterException, ValueError) as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
        log = node.get_logger()
        stop = install_stop_handlers(lambda name: log.info(f"{name} received: stopping the session"))
        executor.add_node(node)
        if node.interactive:
            threading.Thread(target=_stdin_reader, args=(node,), daemon=True).start()
        while not stop.is_set() and not node.done:
            executor.spin_once(timeout_sec=0.1)
        if stop.is_set() and not node.done:
            node.coach.stop("signal")
        node.flush()
        log.info("session ended" if node.coach.engine.state == "finished" else "session stopped")
        return 0
    finally:
        executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())

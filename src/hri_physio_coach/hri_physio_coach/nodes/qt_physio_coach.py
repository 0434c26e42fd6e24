"""qt_physio_coach: the QT cardio-aware exercise coach as a ROS 2 node.

A thin shell around :class:`hri_physio_coach.coach.ExerciseCoach`: heart-rate frames in
(one-sample frames ``[t, bpm]``, std_msgs/Float64MultiArray), robot commands out on
/QtController/input, replies from /QtController/output, every decision as a JSON event on
/coach/events and a state snapshot on /coach/state (latched). The session runs on the node's
ROS clock, so with ``use_sim_time`` it follows /clock and can run many times faster than real
time. The node exits when the session ends (status 0), on SIGINT/SIGTERM or ``stop`` (0), and
when it finds it is not alone (status 1): a second coach publishing on its events topic (or
sending robot commands while publishing coach topics), or a second /clock taking turns with
the first. Every line on /coach/control is handled; unknown words are counted in the state.

Examples::

    qt_physio_coach                                   # starts at once, packaged coach.yaml
    qt_physio_coach --interactive                     # waits for 'start' on stdin or /coach/control
    qt_physio_coach --conf my_coach.yaml --policy fuzzy --ros-args -p part_age:=45.0
    qt_physio_coach --ros-args -p use_sim_time:=true -p hr_topic:=/physio/polar_h10/ecg/hr
"""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Any

from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription import MessageInfo
from rclpy.time_source import CLOCK_TOPIC
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, String

from hri_physio_bridge.frames import FrameFormatError
from hri_physio_bridge.json_files import strict_json
from hri_physio_bridge.node_runner import ManagedNode, run_node
from hri_physio_bridge.qos import command_qos, event_qos, frame_qos, latched_qos
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.ros_frames import msg_to_frame
from hri_physio_bridge.ros_tools import wait_all_acked
from hri_physio_coach.coach import CoachError, ExerciseCoach
from hri_physio_coach.config import COACH_NODE, CoachNodeConfig
from hri_physio_coach.conflicts import SECOND_CLOCK, SECOND_COACH, EchoFilter, SourceWatch
from hri_physio_coach.control import START_WORDS, STOP_WORDS, Control, SessionControl
from hri_physio_coach.paths import default_config_file
from hri_physio_coach.routine import RoutineError

PROG = COACH_NODE
#: The name the graph gives an endpoint whose node it does not know (yet, or any more): rmw_dds_common's.
UNKNOWN_NODE_NAME = "_NODE_NAME_UNKNOWN_"
# Events worth a line in the ROS log (all of them go to /coach/events).
_LOGGED = {"session_start", "phase", "activity", "calibration", "zone", "rule_update", "hr_lost",
           "hr_resumed", "command_failed", "command_unanswered", "session_end", "session_stopped",
           "conflict"}


def _gid(info: MessageInfo) -> bytes | None:
    gid = info.get("publisher_gid") if isinstance(info, dict) else None
    return bytes(gid["data"])[:16] if gid and gid.get("data") is not None else None


class QtPhysioCoachNode(ManagedNode):
    """Parameters, topics and the tick timer around an :class:`ExerciseCoach`.

    The coach is driven from the executor thread (timer and subscriptions) and, at the end,
    from :meth:`run` on the main thread: every access holds ``_lock``.
    """

    def __init__(self, config: CoachNodeConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._state_dirty = True
        self._waiting_said = False  # the coach's waiting_for_hr, as last published
        #: Subscriptions the command publisher has matched, as last published (command_listeners).
        self._command_listeners_said = 0
        self.conflict: dict[str, Any] | None = None
        self._control_log = RateLimitedLog(self.get_logger().warning)
        self._own_events = EchoFilter()
        self._own_commands = EchoFilter()
        self._clocks = SourceWatch()
        self._coach_nodes: dict[bytes, str | None] = {}  # command publisher -> its node, if a coach
        self.coach = ExerciseCoach(cfg, self._now, self._send, self._on_event)
        # Before the session, not at its first rule update: the predictive policies' scipy takes over a
        # second to import, and a coach stalled there would stop a sim clock or decide late at 1x.
        began = time.monotonic()
        self.coach.warm_up()
        warm_up_s = time.monotonic() - began
        self.control = SessionControl(self.coach, cfg.interactive)
        self.commands = self.create_publisher(String, cfg.command_topic, command_qos())
        self.events = self.create_publisher(String, cfg.events_topic, event_qos())
        self.state_pub = self.create_publisher(String, cfg.state_topic, latched_qos())
        self.create_subscription(Float64MultiArray, cfg.hr_topic, self._on_hr, frame_qos())
        self.create_subscription(String, cfg.reply_topic, self._on_reply, command_qos())
        self.create_subscription(String, cfg.control_topic, self._on_control, command_qos())
        # Our own topics heard back: anything we did not send there comes from another coach.
        self.create_subscription(String, cfg.events_topic, self._on_events_heard, event_qos())
        self.create_subscription(String, cfg.command_topic, self._on_commands_heard, command_qos())
        if self.get_parameter("use_sim_time").value:
            clock_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
            self.create_subscription(Clock, CLOCK_TOPIC, self._on_clock, clock_qos)
        self.create_timer(cfg.tick_period, self._tick)
        self.get_logger().info(
            f"participant {self.coach.participant}, policy {cfg.policy}, routine "
            f"{self.coach.routine.name} ({self.coach.routine.duration / 60:.1f} min), HR from {cfg.hr_topic}"
            + (": waiting for 'start'" if cfg.interactive else "")
            + f" (policy ready in {warm_up_s:.1f} s)"
        )

    # --- plumbing ----------------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _send(self, line: str) -> None:
        self._own_commands.sent(line)
        self.commands.publish(String(data=line))

    def _publish_event(self, event: dict[str, Any]) -> None:
        payload = to_json(event)
        self._own_events.sent(payload)
        self.events.publish(String(data=payload))

    def _on_event(self, event: dict[str, Any]) -> None:
        self._publish_event(event)
        self._state_dirty = True
        kind = event.get("event")
        if kind in _LOGGED:
            text = _summary(event)
            if kind == "conflict":
                self.get_logger().error(text)
            elif kind in ("command_failed", "hr_lost"):
                self.get_logger().warning(text)
            else:
                self.get_logger().info(text)

    def state(self) -> dict[str, Any]:
        """The coach's state plus the node's: control lines handled and any conflict found."""
        return {**self.coach.state(), "control": dict(self.control.counts), "start_at": self.control.start_at,
                "conflict": self.conflict["conflict"] if self.conflict else None,
                "command_listeners": self._command_listeners_said}

    def _finish(self) -> None:
        self.finished = True
        self._wake.set()

    # --- inputs ------------------------------------------------------------------------------
    def _on_hr(self, msg: Float64MultiArray) -> None:
        try:
            frame = msg_to_frame(msg)
        except FrameFormatError as exc:
            self.get_logger().warning(f"ignoring a malformed HR frame: {exc}")
            return
        with self._lock:
            self.control.on_hr(frame, self._now())
        # A rule update waiting for this heart rate decides now, not at the next tick: under a launcher
        # that holds sim time until the coach has decided, the next tick might not come.
        self._tick()

    def _on_reply(self, msg: String) -> None:
        try:
            reply = json.loads(msg.data)
        except ValueError:
            self.get_logger().warning(f"ignoring a reply that is not JSON: {msg.data[:80]!r}")
            return
        if isinstance(reply, dict):
            with self._lock:
                self.coach.on_reply(reply)

    def _on_control(self, msg: String) -> None:
        self.request(msg.data)

    def request(self, line: str) -> None:
        """One control line from the control topic or stdin: ``start``, or ``stop``/``exit``."""
        with self._lock:
            control = self.control.request(line)
            self._state_dirty = True
            if control is Control.STOP:
                self._finish()
            elif control is Control.UNKNOWN:
                self._control_log.report("unknown", f"unknown control line {line.strip()[:60]!r} "
                                         f"(known: {', '.join(START_WORDS + STOP_WORDS)})",
                                         "unknown control line(s)")

    # --- not alone ---------------------------------------------------------------------------
    def _on_events_heard(self, msg: String) -> None:
        if self._own_events.is_foreign(msg.data):
            self._conflict(SECOND_COACH, self.config.events_topic,
                           "another publisher on the coach's events topic")

    def _on_commands_heard(self, msg: String, info: MessageInfo) -> None:
        if not self._own_commands.is_foreign(msg.data):
            return
        gid = _gid(info)
        if gid is None:
            return
        if gid not in self._coach_nodes:
            self._coach_nodes[gid] = self._coach_node_of(gid)
        node = self._coach_nodes[gid]
        if node is not None:
            self._conflict(SECOND_COACH, self.config.command_topic, f"coach node {node} sends robot commands",
                           seen=node)

    def _coach_node_of(self, gid: bytes) -> str | None:
        """The name of the node behind a command publisher if it is a coach (None: it is not, or unknown)."""
        cfg = self.config
        for info in self.get_publishers_info_by_topic(cfg.command_topic):
            if bytes(info.endpoint_gid)[:16] != gid:
                continue
            name, namespace = info.node_name, info.node_namespace
            try:
                topics = {t for t, _ in self.get_publisher_names_and_types_by_node(name, namespace)}
            except Exception:  # the node is gone (rclpy's NodeNameNonExistentError)
                return None
            if name == self.get_name() or topics & {cfg.events_topic, cfg.state_topic}:
                return f"{namespace.rstrip('/')}/{name}"
        return None

    def _on_clock(self, _msg: Clock, info: MessageInfo) -> None:
        gid = _gid(info)
        if gid is not None and self._clocks.seen(gid):
            self._conflict(SECOND_CLOCK, CLOCK_TOPIC, "two publishers take turns on the clock")

    def _conflict(self, kind: str, topic: str, what: str, seen: str | None = None) -> None:
        """Say so (event and error log) and stop: a session mixed with another is worth nothing.

        ``seen``: the other node as identified when the conflict was found; it is named even if graph
        discovery no longer (or not yet) lists it by name.
        """
        with self._lock:
            if self.conflict is not None:
                return
            me = self.get_fully_qualified_name()
            infos = self.get_publishers_info_by_topic(topic)
            others = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos)
            if me in others:
                others.remove(me)  # one of them is this node's own publisher (same-named nodes stay)
            unnamed = [n for n in others if n.endswith(UNKNOWN_NODE_NAME)]
            others = [n for n in others if n not in unnamed]
            if seen is not None and seen not in others:
                others.append(seen)
            who = ", ".join(others) or ("not known by name yet" if unnamed else "already gone")
            reason = (f"{what} ({topic}; other publishers: {who}): "
                      "another session shares this ROS domain; stopping")
            self.conflict = {"conflict": kind, "topic": topic, "publishers": others, "reason": reason}
            self._on_event({"t": self._now(), "event": "conflict", "participant": self.coach.participant,
                            **self.conflict})
            self.control.stop(f"conflict: {kind}")
            self._publish_state()
            self._finish()

    # --- the session -------------------------------------------------------------------------
    def _tick(self) -> None:
        with self._lock:
            if not self.finished:
                self.control.tick(self._now())
                if self.control.finished:
                    self._finish()
            waiting = self.coach.waiting_for_heart_rate()
            if waiting != self._waiting_said:  # a launcher driving sim time lets the clock on for it
                self._waiting_said, self._state_dirty = waiting, True
            listeners = self.commands.get_subscription_count()
            if listeners != self._command_listeners_said:  # a launcher starts once every listener has it
                self._command_listeners_said, self._state_dirty = listeners, True
            if self._state_dirty:
                self._publish_state()

    def _publish_state(self) -> None:
        self._state_dirty = False
        self.state_pub.publish(String(data=to_json(self.state())))

    def on_stop(self, signal_name: str) -> None:
        self.get_logger().info(f"{signal_name} received: stopping the session")
        with self._lock:
            # A signal, or a failed callback (run_node names it): the session record says which.
            self.control.stop_reason = self.control.stop_reason or (
                "signal" if signal_name.startswith("SIG") else signal_name)
        self._wake.set()

    def run(self, stop: threading.Event) -> int:
        if self.config.interactive:
            threading.Thread(target=_stdin_reader, args=(self,), daemon=True).start()
        while not self._wake.wait(1.0) and not stop.is_set():
            pass
        with self._lock:
            state = self.control.end()
            self._publish_state()
        self.flush()
        log = self.get_logger()
        if self.conflict is not None:
            log.error(f"stopped: {self.conflict['reason']}")
            return 1
        log.info({"finished": "session ended", "idle": "stopped before the session started"}.get(
            state, "session stopped"))
        return 0

    def flush(self, timeout: float = 2.0) -> None:
        wait_all_acked((self.commands, self.events, self.state_pub), timeout)


def to_json(event: dict[str, Any]) -> str:
    """One event as strict JSON (anything not JSON-native is written as text)."""
    return strict_json(event, default=str)


def _summary(event: dict[str, Any]) -> str:
    kind = event["event"]
    t = event.get("t", 0.0)
    if kind == "rule_update":
        d = event["decision"]
        hr = event["inputs"]["hr_mean"]
        hr_text = "-" if hr is None else f"{hr:.1f}"
        return (f"[{t:.1f}] rule update: HR {hr_text} -> {d['action']} ({d['reason']}), "
                f"step {d['index_after']}")
    if kind == "conflict":
        return f"[{t:.1f}] conflict ({event['conflict']}): {event['reason']}"
    detail = {k: v for k, v in event.items() if k not in ("t", "event", "participant")}
    return f"[{t:.1f}] {kind}: {to_json(detail)[:200]}"


def _stdin_reader(node: QtPhysioCoachNode) -> None:
    print("type 'start' to begin the session ('stop' ends it)", flush=True)
    for line in sys.stdin:
        node.request(line)


def main(argv: list[str] | None = None) -> int:
    return run_node(PROG, CoachNodeConfig, QtPhysioCoachNode, argv=argv, description=__doc__,
                    default_conf=default_config_file(), startup_errors=(CoachError, RoutineError))


if __name__ == "__main__":
    sys.exit(main())

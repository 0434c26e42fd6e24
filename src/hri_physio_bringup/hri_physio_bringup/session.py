"""hri_physio_session: the whole closed loop on the built-in defaults, with no hardware.

Starts, as separate processes (the console scripts a lab would run):

* ``simulated_participant`` - a person on the step wearing a simulated Polar H10 (ECG, HR and
  RR on LSL), whose heart rate follows the robot's gesture speed and music tempo;
* ``physio_receiver`` x2 - LSL -> ROS 2 for HR (``/physio/polar_h10/hr``) and ECG;
* ``neurokit_processor`` - ECG -> HR/HRV features (``/physio/polar_h10/ecg/...``);
* ``qt_physio_coach`` - the exercise coach, adapting on the strap's HR (or the processor's);
* ``qt_controller`` + ``mock_qt_robot`` - the robot side;
* ``audio_streamer`` + ``video_streamer`` - the music (null sink unless ``--audio-sink device``) and
  the reference videos (offscreen), on the session's clock, their status and preview in the bag;
* ``physio_recorder`` - every topic into a rosbag2 (MCAP) directory;
* ``live_view`` (with ``--live [HOST:]PORT``) - the session served live to Foxglove over its
  WebSocket protocol, on 127.0.0.1:8765 unless told otherwise.

Every node's configuration is checked before anything starts. The session gets a folder of its
own, ``<out>/<participant id>_<date-time>/`` (bag, ``logs/<node>.log``, ``configs/<node>.yaml``,
``summary.json``, the report), a ROS domain of its own (claimed, so two sessions on one machine
never mix) and LSL stream names of its own. This process drives ``/clock`` (every node but the
receivers, processor and recorder runs on sim time), so the 23-minute routine runs ``--speed``
times faster than real time. It waits until the robot side is up and heart rate reaches the
coach's input, sends ``start`` to the coach, shows one live progress display (plain lines when
the output is not a terminal; every node line with ``--verbose``), and when the coach ends the
session stops every process cleanly (the recorder last), prints a summary and the folder.

A node that dies mid-session is restarted or ends the session (:mod:`hri_physio_bringup.supervision`:
restartable and essential nodes, backoff, ``--max-restarts``); each restart is said on the console,
published on ``/session/events`` (recorded) and listed in ``summary.json`` and the report.

``--source polar:<device id>`` puts a real Polar H10 in the simulated participant's place
(``polar_streamer``; real time only), ``--source polar-replay:<capture>`` a capture of one.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError, OneLineErrorParser, add_config_arguments, given_options
from hri_physio_bridge.launcher import ManagedProcess, ProcessGroup
from hri_physio_bridge.ros_tools import BackgroundNode, clock_message
from hri_physio_bridge.stop_signals import install_stop_handlers
from hri_physio_bridge.waiting import wait_until
from hri_physio_bringup.clock import ClockGuard, ClockHistory, SimClock
from hri_physio_bringup.console import (
    LiveConsole,
    PlainConsole,
    Progress,
    SessionConsole,
    VerboseConsole,
)
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.hosts import SESSION_ENDED, HostWatch, parse_heartbeat
from hri_physio_bringup.isolation import (
    DomainClaim,
    DomainInUse,
    claim_domain,
    claim_lab_domain,
    holder_info,
    new_device_id,
    parse_domain,
)
from hri_physio_bringup.lab import Lab, LabError, describe, load_lab, lsl_config, ros_environment
from hri_physio_bringup.live import DEFAULT_LIVE
from hri_physio_bringup.options import PROG, SessionConfig
from hri_physio_bringup.plan import (
    COACH,
    POLAR_STREAMER,
    SessionPlan,
    coach_config,
    for_role,
    plan_session,
)
from hri_physio_bringup.supervision import Loss, Restart, Supervisor, gap_line, restarts_text, status_text
from hri_physio_bringup.view import SessionView, every_listener_matched, overdue, session_counts, summary
from hri_physio_coach.participant.perception import message_key, parse_receipt

#: Session seconds past the routine's end after which a coach that has not ended is stopped.
END_MARGIN = 60.0
#: Session seconds the clock runs on after the coach's end: the robot's last speech, the last events.
TAIL = 10.0
#: Wall seconds the system must look ready before 'start': publishers match their subscribers.
SETTLE = 2.0
CLOCK_DEPTH = 1000
#: Wall seconds between two rounds of the launcher's loop (clock, supervision, progress): when the
#: clock's next step is due, but at least LOOP_MIN (at high speed steps go out in small bursts, as
#: they always did) and at most LOOP_MAX (deaths and a stop are seen within it).
LOOP_MIN, LOOP_MAX = 0.01, 0.1


class ClockAndWatcher(BackgroundNode):
    """Publishes /clock and watches the session's topics, on its own executor thread."""

    def __init__(self, view: SessionView, hr_topic: str, receivers: dict[str, str],
                 listeners: tuple[tuple[str, str], ...], guard: ClockGuard | None = None,
                 strap_node: str | None = None, supervisor: Supervisor | None = None,
                 hosts: HostWatch | None = None) -> None:
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64MultiArray, String

        from hri_physio_bridge.qos import command_qos, event_qos, frame_qos, latched_qos
        from hri_physio_bridge.ros_frames import msg_to_frame

        super().__init__("session_launcher")
        self._string_cls = String
        self.view = view
        self.listeners = listeners
        self.guard = guard
        self.lock = threading.Lock()
        self.sim_now = math.nan  # the last /clock published: what sim time it is when a sample arrives
        self.clock_history = ClockHistory()  # which /clock value was the newest when a message went out
        # Deep: at high --speed hundreds of clock messages a second must reach the recorder too.
        self.clock_pub = self.node.create_publisher(Clock, "/clock", CLOCK_DEPTH)
        self.control_pub = self.node.create_publisher(String, topics.COACH_CONTROL, command_qos())
        self.events_pub = self.node.create_publisher(String, topics.SESSION_EVENTS, event_qos())
        self.hosts = hosts
        #: A lab's hosts heard or lost: (console line, event to publish) for the main thread to say.
        self.host_news: list[tuple[str, dict[str, Any] | None]] = []
        #: Per host role: the smallest (station wall clock - host wall clock) over its heartbeats, in s.
        self.wall_offsets: dict[str, float] = {}
        if hosts is not None:
            self._watch_hosts(hosts)
        strap = hr_topic == topics.POLAR_H10_HR

        def strap_samples(frame: Any) -> None:
            view.strap_samples += frame.num_samples
            if guard is not None:
                for t in frame.timestamps:
                    guard.hr_sample(float(t), self.sim_now)

        def on_hr(msg: Float64MultiArray) -> None:
            frame = msg_to_frame(msg)
            with self.lock:
                for t, bpm in zip(frame.timestamps, frame.values[:, -1], strict=True):
                    view.on_hr(float(bpm), float(t), self.sim_now)
                if strap:
                    strap_samples(frame)

        def on_strap(msg: Float64MultiArray) -> None:
            frame = msg_to_frame(msg)
            with self.lock:
                strap_samples(frame)

        def on_json(apply: Callable[[dict], None]) -> Callable[[String], None]:
            def callback(msg: String) -> None:
                try:
                    data = json.loads(msg.data)
                except ValueError:
                    return  # not ours to judge: the recorder keeps the raw message
                if isinstance(data, dict):
                    with self.lock:
                        apply(data)
            return callback

        def on_event(msg: String) -> None:
            with self.lock:
                view.on_event_text(msg.data)
                if guard is not None and view.started_at is not None:
                    guard.session_started(view.started_at)

        def set_state(data: dict) -> None:
            view.state = data
            if guard is not None:
                decision = data.get("next_decision")
                guard.coach_decision(float(decision) if isinstance(decision, int | float) else None,
                                     bool(data.get("waiting_for_hr", True)))

        def set_model(data: dict) -> None:
            view.model_hr = float(data.get("hr_model", math.nan))

        def count_action(_data: dict) -> None:
            view.robot_actions += 1

        def receiver_status(node: str) -> Callable[[dict], None]:
            return lambda data: view.receivers.__setitem__(node, data)

        self.node.create_subscription(Float64MultiArray, hr_topic, on_hr, frame_qos())
        if not strap:
            self.node.create_subscription(Float64MultiArray, topics.POLAR_H10_HR, on_strap, frame_qos())
        self.node.create_subscription(String, topics.COACH_STATE, on_json(set_state), latched_qos())
        self.node.create_subscription(String, topics.COACH_EVENTS, on_event, event_qos())
        self.node.create_subscription(String, topics.PARTICIPANT_STATE, on_json(set_model), event_qos(100))
        self.node.create_subscription(String, topics.QT_MOCK_EVENTS, on_json(count_action), event_qos())
        for node in receivers:
            self.node.create_subscription(String, f"/{node}/status", on_json(receiver_status(node)), 10)
        if supervisor is not None:
            self._watch_outputs(receivers, supervisor)
        if strap_node is not None:
            self.node.create_subscription(String, f"/{strap_node}/status",
                                          on_json(lambda data: setattr(view, "strap_status", data)), 10)
        if guard is not None:
            self._watch_the_loop(guard)
        self.start()

    def _watch_outputs(self, receivers: dict[str, str], supervisor: Supervisor) -> None:
        """Each receiver's output frames, where a restarted receiver's gap begins and ends: kept by the
        middleware (the newest 1000 frames) and taken only around a restart (:meth:`output_stamps`)."""
        from std_msgs.msg import Float64MultiArray

        from hri_physio_bridge.qos import frame_qos

        self.outputs = self.taken_on_demand("outputs")
        for node, topic in receivers.items():
            supervisor.track(node)
            self.outputs.subscribe(node, Float64MultiArray, topic, frame_qos())

    def output_stamps(self, node: str) -> list[Any]:
        """The sample stamps (an array) of each frame the receiver ``node`` published since the last call."""
        from hri_physio_bridge.ros_frames import msg_to_frame

        return [msg_to_frame(msg).timestamps for msg in self.outputs.take(node)]

    def _watch_hosts(self, hosts: HostWatch) -> None:
        """The lab's other hosts: their heartbeats, and the latched end of the session for them."""
        from std_msgs.msg import String

        from hri_physio_bridge.qos import latched_qos
        from hri_physio_bringup.lab_host import heartbeat_qos

        self.lab_session_pub = self.node.create_publisher(String, topics.LAB_SESSION, latched_qos())

        def on_heartbeat(msg: String) -> None:
            data = parse_heartbeat(msg.data, hosts.lab)
            if data is None:
                return
            received = time.time()
            with self.lock:
                t = self.sim_now if math.isfinite(self.sim_now) else 0.0
                self.host_news += hosts.heard(data, time.monotonic(), t)
                if isinstance(data.get("wall"), int | float):
                    offset = received - float(data["wall"])
                    role = str(data["role"])
                    self.wall_offsets[role] = min(self.wall_offsets.get(role, math.inf), offset)

        self.node.create_subscription(String, topics.LAB_HOSTS, on_heartbeat, heartbeat_qos())

    def lab_step(self, say: Callable[[str], None]) -> None:
        """Say (and publish on /session/events) what the lab's hosts did since the last call."""
        if self.hosts is None:
            return
        with self.lock:
            t = self.sim_now if math.isfinite(self.sim_now) else 0.0
            news, self.host_news = self.host_news + self.hosts.check(time.monotonic(), t), []
        for line, event in news:
            say(line)
            if event is not None:
                self.publish_event(event)

    def end_lab_session(self, t: float) -> None:
        """Tell the lab's other hosts that the session has ended (latched: a host reconnecting hears it)."""
        if self.hosts is not None:
            self.lab_session_pub.publish(self._string_cls(data=json.dumps(
                {"event": SESSION_ENDED, "lab": self.hosts.lab.lab, "t": t if math.isfinite(t) else None})))

    def publish_event(self, event: dict[str, Any]) -> None:
        """One event on /session/events (JSON)."""
        self.events_pub.publish(self._string_cls(data=json.dumps(event)))

    def _watch_the_loop(self, guard: ClockGuard) -> None:
        """What the clock guard needs: robot commands and their answers, audio requests and the status."""
        from std_msgs.msg import String

        from hri_physio_bridge.qos import command_qos, event_qos

        def locked(action: Callable[[Any], None]) -> Callable[[Any], None]:
            def callback(msg: Any) -> None:
                with self.lock:
                    action(msg)
            return callback

        def locked_with_info(action: Callable[[Any, dict], None]) -> Callable[[Any, dict], None]:
            def callback(msg: Any, info: dict) -> None:  # rclpy passes MessageInfo to a 2-argument callback
                with self.lock:
                    action(msg, info)
            return callback

        def settled(msg: Any) -> None:
            try:
                counts = json.loads(msg.data).get("requests") or {}
                done = sum(int(counts.get(k, 0)) for k in ("started", "failed", "superseded"))
            except (ValueError, AttributeError, TypeError):
                return  # not a status this launcher can read: the recorder keeps it as it is
            guard.media_settled(done)

        def sent_at(info: dict) -> float:
            """The sim time when a message went out, from its source timestamp (the clock may have run on
            before this thread heard it); the received time bounds a sender whose wall clock runs ahead."""
            wall = min(int(info.get("source_timestamp") or 0) or math.inf,
                       int(info.get("received_timestamp") or 0) or math.inf)
            t = self.clock_history.at(int(wall)) if math.isfinite(wall) else None
            return self.sim_now if t is None else t

        def command(msg: Any, info: dict) -> None:
            guard.command_sent(self.sim_now)
            guard.instruction(topics.QT_COMMANDS, message_key(msg.data), sent_at(info))

        def status(msg: Any, info: dict) -> None:
            settled(msg)
            guard.instruction(topics.AUDIO_STATUS, message_key(msg.data), sent_at(info))

        def heard(msg: Any) -> None:
            confirmation = parse_receipt(msg.data)
            if confirmation is not None:
                guard.participant_heard(*confirmation)

        sub, now = self.node.create_subscription, lambda: self.sim_now
        sub(String, topics.QT_COMMANDS, locked_with_info(command), command_qos())
        sub(String, topics.QT_REPLIES, locked(lambda _m: guard.command_answered()), command_qos())
        sub(String, topics.AUDIO_REQUEST, locked(lambda _m: guard.media_requested(now())), command_qos())
        sub(String, topics.AUDIO_STATUS, locked_with_info(status), event_qos())
        if guard.reaction_period > 0:
            sub(String, topics.PARTICIPANT_HEARD, locked(heard), event_qos(100))

    def advance(self, clock: SimClock) -> None:
        """Publish the clock values that are due, no further than the guard allows."""
        with self.lock:
            limit = None if self.guard is None else self.guard.limit(clock.t)
            stop = None if self.guard is None else self.guard.stop
        for t in clock.due_steps(limit, stop):
            self.publish_clock(t)

    def publish_clock(self, t: float) -> None:
        with self.lock:
            self.clock_history.published(time.time_ns(), t)
        self.clock_pub.publish(clock_message(t))
        self.sim_now = t

    def send_start(self) -> None:
        self.control_pub.publish(self._string_cls(data="start"))

    def subscriber_nodes(self, topic: str) -> set[str]:
        return {info.node_name for info in self.node.get_subscriptions_info_by_topic(topic)}

    def robot_side_ready(self) -> bool:
        """Every node listens where the plan says: the controller (and a simulated participant) to the
        robot commands, the coach to its control topic, the mock robot to the speech, the streamers to
        their requests (a request published before its subscriber exists would be lost)."""
        return all(node in self.subscriber_nodes(topic) for topic, node in self.listeners)

    def commands_reach(self) -> tuple[int | None, int]:
        """(subscriptions the coach's command publisher has matched, by its state; subscriptions the
        graph shows on the command topic)."""
        with self.lock:
            matched = (self.view.state or {}).get("command_listeners")
        return matched, len(self.node.get_subscriptions_info_by_topic(topics.QT_COMMANDS))


def build_parser() -> argparse.ArgumentParser:
    p = OneLineErrorParser(
        prog=PROG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="The closed loop on the built-in defaults: simulated participant (Polar H10 on LSL) -> "
        "physio_receiver -> qt_physio_coach -> qt_controller -> mock_qt_robot, recorded to a bag, in a "
        "session folder of its own (bag, logs/, configs/, summary.json, report).",
        epilog="Examples: hri_physio_session  |  hri_physio_session --speed 1 --policy fuzzy  |  "
        "hri_physio_session --routine my_routine.yaml --out /data/study1\n\n"
        "Isolation: the session claims a ROS domain of its own (a free one, printed at the start; or "
        "ROS_DOMAIN_ID if you export it, refused while another session holds it) and LSL stream names "
        "of its own (--device-id).\n\n"
        "A lab of several computers: give each host the same lab file and its role, e.g. "
        "hri_physio_session --lab lab.yaml --role sensor|robot|station (config/lab.example.yaml; "
        "docs/ARCHITECTURE.md, \"Running a lab\").",
    )
    add_config_arguments(p, SessionConfig, skip=("live",))
    for group in p._action_groups:  # the launcher's options are not ROS parameters
        if group.title and group.title.startswith("options (also"):
            group.title = "session options"
            # --live alone serves on the default address: a flag with an optional value.
            group.add_argument("--live", dest="live", nargs="?", const=DEFAULT_LIVE, default=None,
                               metavar="[HOST:]PORT", help=SessionConfig.help_text("live"))
    return p


def check_live_port(address: tuple[str, int]) -> None:
    """The live view's address must be free on this host: said before anything starts (ConfigError)."""
    host, port = address
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            raise ConfigError(f"live: cannot serve on {host}:{port}: {exc.strerror or exc}") from None


@dataclass
class Outcome:
    """How the run went: what the exit status and summary.json say."""

    code: int = 0
    problem: str | None = None
    stopped_by: str | None = None
    wall: float = 0.0
    node_codes: dict[str, int] = field(default_factory=dict)
    stop_seconds: dict[str, float] = field(default_factory=dict)  # SIGINT to the end of its work, per node
    #: How the clock guard held sim time back for the loop (ClockGuard.report), None: no guard.
    clock: dict[str, Any] | None = None
    #: Every restart of a node (Restart.record) and the loss that ended the session (Loss.event), if any.
    restarts: list[dict[str, Any]] = field(default_factory=list)
    lost: dict[str, Any] | None = None
    awaiting_restart: list[str] = field(default_factory=list)  # dead, their backoff not over at the end
    #: Stopped (Ctrl-C, SIGTERM) before the system was ready: not a failure, the session never began.
    stopped_in_startup: bool = False

    def fail(self, problem: str, code: int = 1) -> None:
        if self.problem is None:
            self.problem, self.code = problem, code


@dataclass
class LabRun:
    """This host's part of a lab session: the lab, its role, what it opened; the station's view at the end."""

    lab: Lab
    role: str
    env: dict[str, str]  # the ROS discovery variables set for this host's processes
    lsl_config: str  # the generated lsl_api.cfg (LSLAPICFG)
    hosts: HostWatch | None = None
    outages: list[dict[str, Any]] = field(default_factory=list)
    wall_offsets: dict[str, float] = field(default_factory=dict)
    #: Per receiver: the LSL time correction it applied to the strap's samples (its last status).
    lsl_corrections: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        lab = self.lab
        return {
            "lab": lab.lab, "role": self.role, "host": lab.host_of(self.role),
            "address": lab.address_of(self.role), "discovery": lab.discovery, "ros": self.env,
            "lsl_config": self.lsl_config, "hosts": None if self.hosts is None else self.hosts.report(),
            "outages": self.outages,
            "clock_offsets": {
                "ros": "every ROS node of the lab runs on this station's /clock (use_sim_time): the "
                       "session's time is the same on every host whatever their wall clocks say",
                "lsl": "the strap's samples are stamped on the sensor host's LSL clock (a simulated strap's "
                       "follow the session's clock); the station's receivers add LSL's time correction "
                       "(liblsl clocksync: the measured offset of that clock from the station's) to each",
                # Per receiver: the correction applied (offset_s: the last; min_s, max_s, span_s: how it
                # moved over the session), from its last status.
                "lsl_time_correction": self.lsl_corrections,
                # Receive time here minus send time there, smallest over the heartbeats: the wall-clock
                # offset plus the one-way delay, so an upper bound of the offset.
                "wall_offset_upper_bound_s": {role: round(v, 4) for role, v in self.wall_offsets.items()},
            },
        }


def make_console(options: SessionConfig, title: str) -> SessionConsole:
    if options.verbose:
        return VerboseConsole(sys.stdout, options.progress_every)
    if sys.stdout.isatty():
        return LiveConsole(title)
    return PlainConsole(sys.stdout, options.progress_every)


def start_nodes(group: ProcessGroup, plan: SessionPlan, folder: SessionFolder) -> None:
    for node in plan.nodes:
        conf = folder.write_config(node.name, node.config_yaml())
        group.start(node.name, node.script, node.argv(conf), echo=False, log_path=folder.log_file(node.name))


def drive(done: Callable[[], bool], clock: SimClock, stop: threading.Event) -> bool:
    """Call ``done`` whenever the clock's next step is due (see LOOP_MIN, LOOP_MAX) until it holds
    (True) or a stop (False, or ``done()`` once more when the stop came during a pause)."""
    while True:
        if done():
            return True
        if stop.is_set():
            return False
        if stop.wait(min(LOOP_MAX, max(LOOP_MIN, clock.next_step_in()))):
            return done()


#: What :func:`wait_for_system` says when a stop came before the system was ready.
INTERRUPTED_IN_STARTUP = "interrupted during start-up"


def wait_for_system(watcher: ClockAndWatcher, group: ProcessGroup, clock: SimClock, view: SessionView,
                    stop: threading.Event, timeout: float, say: Callable[[str], None] = print) -> str | None:
    """Drive the clock until the robot side listens and heart rate reaches the coach's input."""
    ready_since: list[float] = []
    dead: list[ManagedProcess] = []

    def ready() -> bool:
        watcher.advance(clock)
        watcher.lab_step(say)
        dead[:] = [p for p in group.procs if p.returncode is not None]
        if dead:
            return True
        with watcher.lock:
            # The strap's HR proves LSL -> ROS 2; the coach's own input must flow too (the
            # processor's first HR needs a full window of ECG).
            hr_flowing = view.strap_samples >= 2 and view.hr_seen >= 1
        hosts_up = watcher.hosts is None or watcher.hosts.all_up()
        commands_reach = every_listener_matched(*watcher.commands_reach())
        if hr_flowing and hosts_up and watcher.robot_side_ready() and commands_reach:
            ready_since[:] = ready_since or [time.monotonic()]
            return time.monotonic() - ready_since[0] >= SETTLE
        return False

    if wait_until(ready, timeout, stop=stop, poll=0.02):
        if dead:
            p = dead[0]
            return f"{p.name} exited during start-up with status {p.returncode}: {p.error_line()}"
        return None
    if stop.is_set():
        return INTERRUPTED_IN_STARTUP
    with watcher.lock:
        strap = view.strap_samples
        waiting = [] if watcher.hosts is None else watcher.hosts.waiting_for()
    hosts = f"; lab hosts not heard: {', '.join(waiting)}" if waiting else ""
    matched, listeners = watcher.commands_reach()
    return (f"the system was not ready after {timeout:g} s (strap heart-rate samples on ROS 2: {strap}; "
            f"robot side listening: {watcher.robot_side_ready()}; the coach's commands reach {matched} of "
            f"{listeners} listener(s){hosts}); see the folder's logs/")


class Supervision:
    """The launcher's side of :mod:`~hri_physio_bringup.supervision`: restarts what died, says so."""

    def __init__(self, supervisor: Supervisor, group: ProcessGroup, watcher: ClockAndWatcher,
                 console: SessionConsole, out: Outcome, rates: dict[str, float]) -> None:
        self.supervisor, self.group, self.watcher = supervisor, group, watcher
        self.console, self.out, self.rates = console, out, rates

    def step(self, sim_t: float, coach: ManagedProcess) -> bool:
        """Deaths seen, restarts due, receiver gaps closed; True when a loss ends the session."""
        sup = self.supervisor
        for p in list(self.group.procs):
            code = p.returncode
            if code is None or sup.pending(p.name) or (p is coach and code == 0):
                continue
            decision = sup.died(p.name, code, sim_t, p.error_line() if code > 0 else "")
            if isinstance(decision, Loss):
                self.watcher.publish_event(decision.event())
                self.out.fail(decision.problem(sup.max_restarts))
                return True
        for record in sup.due():
            old = next(p for p in self.group.procs if p.name == record.node)
            if sup.tracks(record.node):  # what it published before it died: where its gap begins
                self._take_outputs(record.node)
            self.group.restart(old, f"[session] --- {record.node} died with exit status "
                               f"{status_text(record.exit_status)}: restart {record.restart} of "
                               f"{sup.max_restarts}, same command line; its output continues here ---")
            sup.started(record, sim_t)
            self.watcher.publish_event(record.event())
            self.console.say(record.line(sup.max_restarts))
        for record in self._closed_gaps():
            event = record.gap_event(self.rates.get(record.node))
            record.missing = event["missing"]
            self.watcher.publish_event(event)
            self.console.say(gap_line(event))
        return False

    def _take_outputs(self, node: str) -> Restart | None:
        """Tell the supervisor the frames the receiver ``node`` published since the last take; the
        restart whose gap they closed, if any."""
        closed = None
        for stamps in self.watcher.output_stamps(node):
            closed = self.supervisor.output(node, stamps) or closed
        return closed

    def _closed_gaps(self) -> list[Restart]:
        """The restarted receivers whose first new frame has come since the last call."""
        closed = [self._take_outputs(node) for node in self.supervisor.watching()]
        return [record for record in closed if record is not None]

    def report(self) -> None:
        self._closed_gaps()  # a gap closed since the last step is in the summary (its event is not sent)
        self.out.restarts = [r.record() for r in self.supervisor.records]
        loss = self.supervisor.loss
        self.out.lost = None if loss is None else loss.event()
        self.out.awaiting_restart = self.supervisor.awaiting_restart()


def run_session(options: SessionConfig, plan: SessionPlan, folder: SessionFolder, console: SessionConsole,
                view: SessionView, group: ProcessGroup, stop: threading.Event, out: Outcome,
                teardown: contextlib.ExitStack, lab: LabRun | None = None) -> SimClock:
    """Start the nodes, wait for them, run the routine to its end (or a stop); returns the sim clock.

    The launcher's own ROS 2 teardown goes on ``teardown``, for its caller to run once the summary is
    written: a teardown stuck in the middleware ends the process (see ``shut_down_ros``), and what
    the session did must be on disk by then."""
    receivers = {name: topic for name, (topic, _rate) in plan.receivers.items()}
    # A simulated participant's loop can be held to the clock; a real strap lives in real time.
    guard = None if options.polar else ClockGuard(hr_wait=plan.coach.hr_wait,
                                                  reaction_period=plan.reaction_period)
    strap = next((n.name for n in plan.nodes if n.script == POLAR_STREAMER), None)
    supervisor = Supervisor(options.max_restarts)
    hosts = None if lab is None else HostWatch(lab.lab, lab.role)
    watcher = ClockAndWatcher(view, plan.hr_topic, receivers, plan.listeners, guard, strap, supervisor, hosts)
    teardown.callback(watcher.close)
    rates = {name: rate for name, (_topic, rate) in plan.receivers.items()}
    supervision = Supervision(supervisor, group, watcher, console, out, rates)
    # The clock runs at --speed from the beginning: before 'start' the participant sits and the
    # processor fills its first window (60 s of ECG) without keeping the launcher waiting.
    clock = SimClock(start=float(int(time.time())), speed=options.speed)
    try:
        start_nodes(group, plan, folder)
        problem = wait_for_system(watcher, group, clock, view, stop, options.startup_timeout, console.say)
        if problem == INTERRUPTED_IN_STARTUP:  # the researcher's stop: the session never began
            out.stopped_in_startup = True
            console.say("[session] stopped during start-up: the session did not begin")
            return clock
        if problem:
            out.fail(problem)
            return clock
        coach = next(p for p in group.procs if p.name == COACH)
        watcher.send_start()
        wall0 = time.monotonic()
        console.say(f"[session] system ready: session started at {options.speed:g}x")

        def finished() -> bool:
            watcher.advance(clock)
            watcher.lab_step(console.say)
            if supervision.step(clock.t, coach):
                return True
            with watcher.lock:
                wall = time.monotonic() - wall0
                progress = Progress.of(view, clock.t, plan.routine_duration, None)
                if progress.elapsed and wall > 0:
                    progress = Progress.of(view, clock.t, plan.routine_duration, progress.elapsed / wall)
                late = overdue(view, clock.t, plan.routine_duration, END_MARGIN)
            console.progress(progress)
            if late:
                out.fail(f"the coach did not end its session {END_MARGIN:g} s after the routine's end")
                return True
            # Its normal end. Any other exit is a loss, which supervision.step names on the next round
            # (the coach may die between that step and this look: the launcher must not name it here).
            return coach.returncode == 0

        drive(finished, clock, stop)
        out.wall = time.monotonic() - wall0
        if coach.returncode not in (None, 0):
            out.fail(f"{COACH} ended with status {coach.returncode}: {coach.error_line()}")
        elif coach.returncode == 0:
            # Let the robot finish its last speech and the last events reach us.
            end = clock.t + TAIL

            def tail_done() -> bool:
                watcher.advance(clock)
                watcher.lab_step(console.say)
                return supervision.step(clock.t, coach) or clock.t >= end

            drive(tail_done, clock, stop)
        return clock
    finally:
        if out.stopped_by:
            console.say(f"{out.stopped_by}: stopping the session")
        if lab is not None:
            watcher.lab_step(console.say)
            watcher.end_lab_session(clock.t)
            lab.hosts, lab.outages = hosts, hosts.outages if hosts is not None else []
            lab.wall_offsets = dict(watcher.wall_offsets)
        out.node_codes = group.stop()
        for fault in group.teardown_faults():
            console.say(f"[session] warning: {fault}")
        if lab is not None:  # the receivers' last statuses (published as they stopped) hold their corrections
            with watcher.lock:
                lab.lsl_corrections = {name: (view.receivers.get(name) or {}).get("clock_correction")
                                       for name in receivers}
        out.stop_seconds = dict(group.stop_seconds)
        supervision.report()
        watcher.stop_spinning()
        if guard is not None:
            out.clock = guard.report(clock)
            if clock.held_wall >= 1.0:
                causes = ", ".join(f"{cause} {n}" for cause, n in sorted(guard.holds.items()))
                console.say(f"[session] the clock waited {clock.held_wall:.1f} s of wall time for the loop "
                            f"(holds: {causes}): the nodes could not keep up with {clock.speed:g}x here "
                            f"(a busy machine, or more speed than it has); what ran is as at full speed")


def _write_report(folder: SessionFolder) -> list[str]:
    """The session's report (hri_physio_report) into its folder; the names of the files written."""
    from hri_physio_coach.report import make_report

    result = make_report(folder.path)
    return [p.name for p in result.files.values()]


def _report(folder: SessionFolder, console: SessionConsole) -> list[str] | None:
    # A second Ctrl-C may end the report (the session's data is safe by now).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        files = _write_report(folder)
    except KeyboardInterrupt:
        console.say(f"{PROG}: warning: report interrupted (hri_physio_report {folder.display()} writes it)")
        return None
    except Exception as exc:  # the report must not cost the session's exit status: say it in one line
        (folder.path / "logs").mkdir(exist_ok=True)
        (folder.path / "logs" / "report.log").write_text(traceback.format_exc(), encoding="utf-8")
        first = str(exc).splitlines()[0] if str(exc) else ""
        console.say(f"{PROG}: warning: no report ({type(exc).__name__}: {first}; details in logs/report.log)")
        return None
    console.say(f"[session] report: {', '.join(files)}")
    return files


def _summary_json(options: SessionConfig, plan: SessionPlan, folder: SessionFolder, claim: DomainClaim,
                  started: datetime, view: SessionView, out: Outcome, group: ProcessGroup,
                  clock: SimClock | None, report: list[str] | None, running: bool = False,
                  lab: LabRun | None = None) -> dict[str, Any]:
    procs = {p.name: p for p in group.procs}
    counts = session_counts(view)
    if running:
        outcome = "running"
    elif view.conflict or out.code == 0:
        outcome = counts["outcome"]  # finished, stopped (a signal), not started, conflict
    else:
        outcome = "failed"
    extra = {} if lab is None else {"lab": lab.summary()}
    return {
        **extra,
        "participant": plan.coach.participant,
        "folder": str(folder.path.resolve()),
        "started": started.isoformat(timespec="seconds"),
        "ended": None if running else datetime.now().isoformat(timespec="seconds"),
        "outcome": outcome,
        "exit_status": None if running else out.code,
        "problem": out.problem,
        "node_lost": out.lost,
        "restarts": out.restarts,
        "stopped_by": out.stopped_by,
        "wall_seconds": round(out.wall, 3),
        "speed": options.speed,
        "sim_time_end": None if clock is None else clock.t,
        "clock": out.clock,
        "ros_domain": claim.domain,
        "ros_domain_chosen": claim.chosen,
        "lsl_device_id": plan.device_id,
        "bag": None if options.no_record else folder.bag.name,
        "options": options.model_dump(mode="json"),
        "nodes": {
            n.name: {"script": n.script, "config": f"configs/{n.name}.yaml", "log": f"logs/{n.name}.log",
                     "argv": procs[n.name].argv[1:] if n.name in procs else None,
                     "exit_status": out.node_codes.get(n.name),
                     "teardown_fault": procs[n.name].teardown_fault if n.name in procs else None,
                     "stop_seconds": out.stop_seconds.get(n.name),
                     "restarts": sum(r["node"] == n.name for r in out.restarts)}
            for n in plan.nodes
        },
        "session": counts,
        "report": report,
    }


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        options = SessionConfig.from_mapping(given_options(args, SessionConfig), "command line")
        try:
            requested = parse_domain(os.environ.get("ROS_DOMAIN_ID"))
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        lab = None
        if options.lab:
            try:
                lab = load_lab(options.lab)
            except LabError as exc:
                raise ConfigError(str(exc)) from None
            if requested is not None and requested != lab.ros_domain:
                raise ConfigError(f"ROS_DOMAIN_ID={requested} differs from the lab file's ros_domain "
                                  f"{lab.ros_domain}: unset ROS_DOMAIN_ID (the lab file says the domain)")
        coach = coach_config(options)
        started = datetime.now()
        device = options.device_id or (lab.device_id if lab is not None else new_device_id())
        label = coach.participant if lab is None or options.role == "station" else (
            f"{coach.participant}_{options.role}")
        # Every node's configuration, checked before anything starts (on the folder it would get).
        plan_session(options, SessionFolder.plan(options.out, label, started), device, coach)
        if options.live_address is not None and options.role in ("", "station"):
            check_live_port(options.live_address)
    except ConfigError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr, flush=True)
        return 2
    folder = SessionFolder.plan(options.out, label, started)
    try:
        if lab is not None:
            info = holder_info(folder.path.resolve(), started.isoformat(timespec="seconds"),
                               f"lab {lab.lab} {options.role}")
            claim = claim_lab_domain(lab.ros_domain, options.role, info)
        else:
            info = holder_info(folder.path.resolve(), started.isoformat(timespec="seconds"))
            claim = claim_domain(requested, info)
    except DomainInUse as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr, flush=True)
        return 1
    try:
        os.environ["ROS_DOMAIN_ID"] = str(claim.domain)  # for this process's node and every child
        for _ in range(100):
            try:
                folder.create()
                break
            except FileExistsError:  # the same participant started another session this second
                folder = SessionFolder.plan(options.out, label, started)
            except OSError as exc:
                where = f" ({exc.filename})" if exc.filename and str(exc.filename) != str(folder.path) else ""
                print(f"{PROG}: error: cannot create the session folder {folder.path}: {exc.strerror}{where}",
                      file=sys.stderr, flush=True)
                return 1
        plan = plan_session(options, folder, device, coach)
        if lab is None:
            return _run(options, plan, folder, claim, started)
        # Discovery opened as far as the lab file says, for this process's node and every child.
        env = ros_environment(lab, options.role)
        os.environ.update(env)
        cfg = folder.path / "lsl_api.cfg"
        cfg.write_text(lsl_config(lab, options.role), encoding="utf-8")
        os.environ["LSLAPICFG"] = str(cfg.resolve())
        run = LabRun(lab, options.role, env, cfg.name)
        plan = for_role(plan, options.role)
        if options.role != "station":
            from hri_physio_bringup.lab_host import run_host

            return run_host(options, lab, plan, folder, claim, started, env)
        return _run(options, plan, folder, claim, started, run)
    finally:
        claim.release()


def _run(options: SessionConfig, plan: SessionPlan, folder: SessionFolder, claim: DomainClaim,
         started: datetime, lab: LabRun | None = None) -> int:
    out = Outcome()
    stop = install_stop_handlers(lambda name: setattr(out, "stopped_by", name))
    console = make_console(options, f"HRI Physio session {plan.coach.participant}")
    view = SessionView(warn=console.say)
    group = ProcessGroup(on_line=console.node_line)
    who = (f"Polar H10 {plan.device_id}" + (" (replayed capture)" if options.polar_replay else "")
           if options.polar else f"simulated participant (age {options.age:g})")
    console.say(f"HRI Physio session {plan.coach.participant}: {who} "
                f"-> LSL -> ROS 2 -> coach ({plan.coach.policy}) -> mock QT robot, audio and video "
                f"streamers, "
                f"at {options.speed:g}x real time")
    domain = (f"ROS domain {claim.domain} (export ROS_DOMAIN_ID={claim.domain} to watch it)" if claim.chosen
              else f"ROS domain {claim.domain} (ROS_DOMAIN_ID)")
    console.say(f"[session] folder {folder.display()}; {domain}; LSL streams PolarH10/{plan.device_id}/*")
    live = options.live_address
    if live is not None:
        host, port = live
        where = "this host only" if host in ("127.0.0.1", "localhost", "::1") else "open to the network"
        console.say(f"[session] live view on ws://{host}:{port} ({where}): in Foxglove, open a Foxglove "
                    f"WebSocket connection to it with src/hri_physio_bringup/config/foxglove_layout.json")
    if lab is not None:
        console.say(describe(lab.lab, lab.role))
        console.say(f"[lab] waiting for the hosts: {', '.join(HostWatch(lab.lab, lab.role).waiting_for())}")
    folder.write_summary(_summary_json(options, plan, folder, claim, started, view, out, group, None, None,
                                       running=True))
    clock: SimClock | None = None
    teardown = contextlib.ExitStack()
    try:
        clock = run_session(options, plan, folder, console, view, group, stop, out, teardown, lab)
    finally:
        console.close()
        bag = folder.bag if not options.no_record and folder.bag.exists() else None
        now = None if clock is None else clock.t
        restarted = Counter(r["node"] for r in out.restarts)
        console.say(summary(view, out.wall, str(bag) if bag else None, now=now, restarts=dict(restarted)))
        if out.restarts:
            console.say(restarts_text(out.restarts))
        # A node that died and was waiting for its restart when the session ended is in out.restarts.
        # Stopped in start-up, a node may have had no signal handler yet: SIGINT ended it (-2), or it
        # was in the interpreter's own start (a fatal error, 1). The session never began: no failure.
        bad = {} if out.stopped_in_startup else {
            name: c for name, c in out.node_codes.items() if c != 0 and name not in out.awaiting_restart}
        if bad and out.code == 0:
            out.fail(f"node exit statuses {bad}")
        if not stop.is_set() and view.ended_at is None and out.code == 0:
            out.fail("the session did not reach its end")
        wants_report = bag is not None and not options.no_report
        if wants_report and view.started_at is None:
            console.say("[session] no report: the session did not begin (the bag holds its start-up)")
            wants_report = False
        report = _report(folder, console) if wants_report else None
        folder.write_summary(_summary_json(options, plan, folder, claim, started, view, out, group, clock,
                                           report, lab=lab))
        if out.problem:
            print(f"{PROG}: error: {out.problem}", file=sys.stderr, flush=True)
        console.say(f"[session] session folder: {folder.display()}")
        teardown.close()
    return out.code


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())

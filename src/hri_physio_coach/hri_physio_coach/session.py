"""hri_physio_session: the whole closed loop on the built-in defaults, with no hardware.

Starts, as separate processes (the console scripts a lab would run):

* ``simulated_participant`` - a person on the step wearing a simulated Polar H10 (ECG, HR and
  RR on LSL), whose heart rate follows the robot's gesture speed and music tempo;
* ``physio_receiver`` x2 - LSL -> ROS 2 for HR (``/physio/polar_h10/hr``) and ECG;
* ``neurokit_processor`` - ECG -> HR/HRV features (``/physio/polar_h10/ecg/...``);
* ``qt_physio_coach`` - the exercise coach, adapting on the strap's HR (or the processor's);
* ``qt_controller`` + ``mock_qt_robot`` - the robot side;
* ``recorder`` - every topic into a rosbag2 (MCAP) directory.

This process drives ``/clock`` (every node but the receivers, processor and recorder runs on
sim time), so the 23-minute routine runs ``--speed`` times faster than real time (1 = real
time). It waits until the robot side is up and heart rate reaches the coach's input, then sends
``start`` to the coach, prints live progress, and when the coach ends the session stops every
process cleanly (the recorder last) and prints a summary.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import threading
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from hri_physio_bridge.bag.topics import bag_name
from hri_physio_bridge.launcher import ProcessGroup
from hri_physio_bridge.nodes.common import install_stop_handlers
from hri_physio_bridge.ros_tools import BackgroundNode, clock_message
from hri_physio_coach.session_view import CLOCK_STEP, SessionView, SimClock, summary

HR_TOPIC = "/physio/polar_h10/hr"
ECG_TOPIC = "/physio/polar_h10/ecg"
ECG_HR_TOPIC = "/physio/polar_h10/ecg/hr"
#: Valid HR samples a rule update needs when the coach listens to the processor's HR.
ECG_HR_MIN_SAMPLES = 3
#: Seconds without HR before the coach pauses adaptation, on the processor's HR (4 hops).
ECG_HR_TIMEOUT = 20.0


class ClockAndWatcher(BackgroundNode):
    """Publishes /clock and watches the session's topics, on its own executor thread."""

    def __init__(self, view: SessionView, hr_topic: str) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64MultiArray, String

        from hri_physio_bridge.qos import frame_qos
        from hri_physio_bridge.ros_frames import msg_to_frame

        super().__init__("session_launcher")
        self._string_cls = String
        self.view = view
        self.lock = threading.Lock()
        self.clock_pub = self.node.create_publisher(Clock, "/clock", 10)
        self.control_pub = self.node.create_publisher(String, "/coach/control", 10)

        def on_hr(msg: Float64MultiArray) -> None:
            frame = msg_to_frame(msg)
            with self.lock:
                for bpm in frame.values[:, -1]:
                    view.on_hr(float(bpm))
                if hr_topic == HR_TOPIC:
                    view.strap_samples += frame.num_samples

        def on_json(apply: Callable[[dict], None]) -> Callable[[String], None]:
            def callback(msg: String) -> None:
                try:
                    data = json.loads(msg.data)
                except json.JSONDecodeError:
                    return  # not ours to judge: the recorder keeps the raw message
                with self.lock:
                    apply(data)
            return callback

        def set_state(data: dict) -> None:
            view.state = data

        def set_model(data: dict) -> None:
            view.model_hr = float(data.get("hr_model", math.nan))

        def count_action(_data: dict) -> None:
            view.robot_actions += 1

        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        def on_strap(msg: Float64MultiArray) -> None:
            with self.lock:
                view.strap_samples += msg_to_frame(msg).num_samples

        self.node.create_subscription(Float64MultiArray, hr_topic, on_hr, frame_qos())
        if hr_topic != HR_TOPIC:
            self.node.create_subscription(Float64MultiArray, HR_TOPIC, on_strap, frame_qos())
        self.node.create_subscription(String, "/coach/state", on_json(set_state), latched)
        self.node.create_subscription(String, "/coach/events", on_json(view.on_event), 1000)
        self.node.create_subscription(String, "/participant/state", on_json(set_model), 100)
        self.node.create_subscription(String, "/qt_robot/mock/events", on_json(count_action), 1000)
        self.start()

    def publish_clock(self, t: float) -> None:
        self.clock_pub.publish(clock_message(t))

    def send_start(self) -> None:
        self.control_pub.publish(self._string_cls(data="start"))

    def count_subscribers(self, topic: str) -> int:
        return self.node.count_subscribers(topic)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hri_physio_session",
        description="The closed loop on the built-in defaults: simulated participant (Polar H10 on LSL) -> "
        "physio_receiver -> qt_physio_coach -> qt_controller -> mock_qt_robot, recorded to a bag.",
        epilog="Examples: hri_physio_session  |  hri_physio_session --speed 1 --policy fuzzy  |  "
        "hri_physio_session --routine my_routine.yaml --no-record",
    )
    p.add_argument("--speed", type=float, default=30.0,
                   help="sim seconds per wall second once the session starts (default 30: the 23-min "
                        "routine in about 46 s; 1 = real time)")
    p.add_argument("--policy", choices=("threshold", "fuzzy", "static"), default="threshold",
                   help="adaptation policy (default threshold)")
    p.add_argument("--age", type=float, default=33.0, help="participant age, years (default 33)")
    p.add_argument("--participant-seed", type=int, default=1,
                   help="seed of the simulated participant's variability (default 1)")
    p.add_argument("--hr-source", choices=("strap", "ecg"), default="strap",
                   help=f"coach input: the strap's HR ({HR_TOPIC}, default) or the processor's "
                        f"HR from ECG ({ECG_HR_TOPIC})")
    p.add_argument("--conf", type=Path, help="coach YAML file (default: the packaged coach.yaml)")
    p.add_argument("--routine", type=Path, help="routine YAML file (default: the packaged routine)")
    p.add_argument("--bag-dir", type=Path, default=Path("bags"),
                   help="where the session's bag directory is created (default bags/)")
    p.add_argument("--no-record", action="store_true", help="do not record a bag")
    p.add_argument("--no-ecg", action="store_true", help="do not stream ECG into ROS 2 nor process it")
    p.add_argument("--device-id", default="SIM0001", help="simulated Polar device id (default SIM0001)")
    p.add_argument("--startup-timeout", type=float, default=60.0,
                   help="wall seconds to wait for the nodes and the first heart rate (default 60)")
    p.add_argument("--quiet-nodes", action="store_true", help="do not echo the nodes' own log lines")
    p.add_argument("--progress-period", type=float, default=2.0,
                   help="wall seconds between progress lines (default 2)")
    return p


def _check(args: argparse.Namespace) -> str | None:
    if not (math.isfinite(args.speed) and args.speed > 0):
        return f"--speed must be > 0, got {args.speed:g}"
    if not 0 < args.age <= 120:
        return f"--age must be in (0, 120] years, got {args.age:g}"
    for name in ("conf", "routine"):
        path = getattr(args, name)
        if path is not None and not path.is_file():
            return f"--{name} {path} does not exist"
    if args.hr_source == "ecg" and args.no_ecg:
        return "--hr-source ecg needs the ECG path: drop --no-ecg"
    return None


def start_nodes(group: ProcessGroup, args: argparse.Namespace, echo: bool) -> Path | None:
    """Start every node; returns the bag directory the recorder writes (None: not recording)."""
    sim = ["-p", "use_sim_time:=true"]
    dev = args.device_id
    bag: Path | None = None
    if not args.no_record:
        args.bag_dir.mkdir(parents=True, exist_ok=True)
        bag = args.bag_dir / bag_name("session", datetime.now())
        group.start("recorder", "recorder", ["-o", str(bag), "--session-id", "session",
                                             "--discovery-period", "0.2", "--status-period", "10"], echo=echo)
    joint_rate = f"joint_state_rate:={1 / CLOCK_STEP:.1f}"
    group.start("mock", "mock_qt_robot", ["--ros-args", *sim, "-p", joint_rate], echo=echo)
    group.start("controller", "qt_controller", ["--ros-args", *sim], echo=echo)
    group.start("participant", "simulated_participant", [
        "--ros-args", *sim, "-p", f"age:={args.age:.1f}", "-p", f"seed:={args.participant_seed}",
        "-p", f"device_id:={dev}", "-p", f"update_period:={CLOCK_STEP:.3f}"], echo=echo)
    # Each receiver holds its input until all of its listeners are there, so the bag and the
    # coach (or processor) get every sample from the first: HR goes to this launcher's watcher,
    # the recorder and (strap source) the coach; ECG to the processor and the recorder.
    recorder = int(bag is not None)
    streams = [("HR", HR_TOPIC, 1, 1.0, 1 + recorder + (args.hr_source == "strap"))]
    if not args.no_ecg:
        streams.append(("ECG", ECG_TOPIC, 13, 130.0, 1 + recorder))
    for stream, topic, frame, rate, listeners in streams:
        node = f"{stream.lower()}_receiver"
        group.start(node, "physio_receiver", [
            "--input", f"lsl:PolarH10/{dev}/{stream}", "--output", f"ros:{topic}",
            "--output-frame", str(frame), "--sampling-rate", f"{rate:g}",
            "--resolve-timeout", f"{args.startup_timeout:g}",
            "--wait-for-consumers", f"{args.startup_timeout:g}", "--min-consumers", str(listeners),
            "--ros-args", "-r", f"__node:={node}",
        ], echo=echo)
    if not args.no_ecg:
        group.start("processor", "neurokit_processor", ["--input", f"ros:{ECG_TOPIC}"], echo=echo)
    coach = ["--interactive", "--policy", args.policy]
    if args.conf is not None:
        coach += ["--conf", str(args.conf)]
    hr_topic = ECG_HR_TOPIC if args.hr_source == "ecg" else HR_TOPIC
    coach += ["--hr-topic", hr_topic, "--ros-args", *sim, "-p", f"part_age:={args.age:.1f}",
              "-p", f"tick_period:={CLOCK_STEP:.3f}"]
    if args.hr_source == "ecg":
        # One processor HR per 5 s hop: 6 per 30 s rule update, below the strap's default of 10.
        coach += ["-p", f"min_valid_samples:={ECG_HR_MIN_SAMPLES}", "-p", f"hr_timeout:={ECG_HR_TIMEOUT:.1f}"]
    if args.routine is not None:
        coach += ["-p", f"routine_file:={args.routine.resolve()}"]
    group.start("coach", "qt_physio_coach", coach, echo=echo)
    return bag


def wait_for_system(watcher: ClockAndWatcher, group: ProcessGroup, clock: SimClock, view: SessionView,
                    stop: threading.Event, timeout: float) -> str | None:
    """Drive the clock until the robot side listens and heart rate reaches the coach's input."""
    deadline = time.monotonic() + timeout
    ready_since: float | None = None
    while not stop.is_set():
        for t in clock.due_steps():
            watcher.publish_clock(t)
        dead = [p for p in group.procs if p.returncode is not None]
        if dead:
            tail = "\n".join(dead[0].lines[-5:])
            return f"{dead[0].name} exited during start-up with code {dead[0].returncode}:\n{tail}"
        with watcher.lock:
            # The strap's HR proves LSL -> ROS 2; the coach's own input must flow too (the
            # processor's first HR needs a full window of ECG).
            hr_flowing = view.strap_samples >= 2 and view.hr_seen >= 1
        ready = (hr_flowing and watcher.count_subscribers("/coach/control") >= 1
                 and watcher.count_subscribers("/QtController/input") >= 2  # controller, participant
                 and watcher.count_subscribers("/qt_robot/speech/say") >= 1)
        if ready:
            ready_since = ready_since or time.monotonic()
            if time.monotonic() - ready_since >= 2.0:  # let the publishers match their subscribers
                return None
        if time.monotonic() > deadline:
            return (f"the system was not ready after {timeout:g} s (strap heart-rate samples on ROS 2: "
                    f"{view.strap_samples}; subscribers of /QtController/input: "
                    f"{watcher.count_subscribers('/QtController/input')})")
        time.sleep(0.02)
    return "interrupted during start-up"


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    problem = _check(args)
    if problem:
        print(f"hri_physio_session: error: {problem}", file=sys.stderr)
        return 2
    stop = install_stop_handlers(lambda name: print(f"\n{name}: stopping the session", flush=True))
    view = SessionView()
    hr_topic = ECG_HR_TOPIC if args.hr_source == "ecg" else HR_TOPIC
    watcher = ClockAndWatcher(view, hr_topic)
    group = ProcessGroup()
    # The clock runs at --speed from the beginning: before 'start' the participant sits and the
    # processor fills its first window (60 s of ECG) without keeping the launcher waiting.
    clock = SimClock(start=float(int(time.time())), speed=args.speed)
    print(f"HRI Physio session: simulated participant (age {args.age:g}) -> LSL -> ROS 2 -> coach "
          f"({args.policy}) -> mock QT robot, at {args.speed:g}x real time", flush=True)
    code = 0
    wall = 0.0
    bag: Path | None = None
    try:
        bag = start_nodes(group, args, echo=not args.quiet_nodes)
        problem = wait_for_system(watcher, group, clock, view, stop, args.startup_timeout)
        if problem:
            print(f"hri_physio_session: error: {problem}", file=sys.stderr, flush=True)
            return 1
        coach = next(p for p in group.procs if p.name == "coach")
        watcher.send_start()
        wall0 = time.monotonic()
        print(f"[session] system ready: session started at {args.speed:g}x", flush=True)
        next_report = time.monotonic() + args.progress_period
        while not stop.is_set() and coach.returncode is None:
            for t in clock.due_steps():
                watcher.publish_clock(t)
            dead = [p for p in group.procs if p.returncode is not None and p is not coach]
            if dead:
                print(f"hri_physio_session: error: {dead[0].name} exited early with code "
                      f"{dead[0].returncode}", file=sys.stderr, flush=True)
                code = 1
                break
            if time.monotonic() >= next_report:
                next_report += args.progress_period
                with watcher.lock:
                    print(view.progress(clock.t), flush=True)
            time.sleep(0.01)
        wall = time.monotonic() - wall0
        if coach.returncode not in (None, 0):
            code = 1
        # Let the robot finish its last speech and the last events reach us: a few more sim seconds.
        end = clock.t + 10.0
        while clock.t < end and not stop.is_set():
            for t in clock.due_steps():
                watcher.publish_clock(t)
            time.sleep(0.01)
    finally:
        codes = group.stop()
        watcher.close()
    recorded = str(bag) if bag is not None and bag.exists() else None
    print(summary(view, wall, recorded, now=clock.t), flush=True)
    bad = {name: c for name, c in codes.items() if c != 0}
    if bad:
        print(f"hri_physio_session: error: node exit codes {bad}", file=sys.stderr, flush=True)
        code = 1
    if not stop.is_set() and view.ended_at is None:
        print("hri_physio_session: error: the session did not reach its end", file=sys.stderr, flush=True)
        code = 1
    return code


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())

"""qt_physio_coach as a ROS 2 node: CLI, start/stop, control lines, not alone, the whole session.

The integration test runs the robot side as a researcher would (qt_controller +
mock_qt_robot, all on sim time) with the coach, publishes /clock and scripted HR frames
itself, and checks what the mock robot actually did.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from helpers import NodeProcess, own_lines, publish_burst, wait_until
from hri_physio_bridge import topics
from hri_physio_bridge.ros_tools import ExecutorThread, clock_message

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / "bin"
SIM_START = 1000.0
CLOCK = "/clock"  # rclpy.time_source.CLOCK_TOPIC


def run(*args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "qt_physio_coach"), *args], capture_output=True, text=True,
                          timeout=timeout, env=dict(os.environ), stdin=subprocess.DEVNULL)


# --- command line -------------------------------------------------------------------------------
def test_help() -> None:
    c = run("--help")
    assert c.returncode == 0, c.stderr
    for fragment in ("--interactive", "--conf", "--policy", "hr_topic", "/physio/polar_h10/hr", "part_age",
                     "use_sim_time"):
        assert fragment in c.stdout, fragment


@pytest.mark.parametrize(
    "args,message",
    [
        (["--ros-args", "-p", "part_age:=0.0"], "part_age: expected greater than 0"),
        (["--ros-args", "-p", "part_age:=130"], "part_age: expected less than or equal to 120"),
        (["--ros-args", "-p", "part_age:=abc"], "part_age: expected a valid number"),
        (["--ros-args", "-p", "calib_skip:=maybe"], "calib_skip: expected a valid boolean"),
        (["--ros-args", "-p", "zone_low:=0.8"], "zone bounds out of order"),
        (["--ros-args", "-p", "policy:=pid"], "policy: expected 'threshold'"),
        (["--ros-args", "-p", "speed_modifier:=[1.0]"], "one music tempo per gesture speed"),
        (["--ros-args", "-p", "part_agee:=30.0"], "unknown parameter(s) part_agee"),
        (["--ros-args", "--params-file", "/nonexistent/p.yaml"], "/nonexistent/p.yaml does not exist"),
        (["--part-age", "old"], "part_age: expected a valid number"),
        (["--conf", "EMPTY_LADDER"], "speed_modifier: List should have at least 1 item"),
        (["--conf", "/nonexistent/coach.yaml"], "configuration file /nonexistent/coach.yaml does not exist"),
        (["--ros-args", "-p", "routine_file:=/nonexistent/routine.yaml"], "does not exist"),
        (["--ros-args", "-p", "tick_period:=0.0"], "tick_period: expected greater than 0"),
    ],
)
def test_invalid_configuration_is_one_clear_line(args: list[str], message: str, tmp_path: Path) -> None:
    if "EMPTY_LADDER" in args:
        conf = tmp_path / "coach.yaml"
        conf.write_text("speed_modifier: []\naudio_suffix: []\n")
        args = [str(conf) if a == "EMPTY_LADDER" else a for a in args]
    c = run(*args)
    assert c.returncode == 2, (c.stdout, c.stderr)
    lines = own_lines(c.stderr)
    assert len(lines) == 1 and lines[0].startswith("qt_physio_coach: error: "), c.stderr
    assert message in lines[0] and "Traceback" not in c.stderr


# --- a probe on the test side -------------------------------------------------------------------
class Probe:
    """Publishes /clock and HR frames; collects coach events, commands, replies and mock events."""

    def __init__(self, context: Any, hr_topic: str) -> None:
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64MultiArray, String

        from hri_physio_bridge.qos import command_qos, frame_qos, latched_qos

        self.node = Node("coach_test_probe", context=context)
        self.clock_pub = self.node.create_publisher(Clock, CLOCK, 10)
        self.hr_pub = self.node.create_publisher(Float64MultiArray, hr_topic, frame_qos())
        self.control = self.node.create_publisher(String, topics.COACH_CONTROL, command_qos())
        self.input = self.node.create_publisher(String, topics.QT_COMMANDS, 10)
        self.lock = threading.Lock()
        self.coach_events: list[dict[str, Any]] = []
        self.mock_events: list[dict[str, Any]] = []
        self.commands: list[str] = []
        self.replies: list[dict[str, Any]] = []
        self.node.create_subscription(String, topics.COACH_EVENTS, self._add(self.coach_events, True), 5000)
        self.node.create_subscription(String, topics.QT_MOCK_EVENTS, self._add(self.mock_events, True), 5000)
        self.node.create_subscription(String, topics.QT_COMMANDS, self._add(self.commands, False), 5000)
        self.node.create_subscription(String, topics.QT_REPLIES, self._add(self.replies, True), 5000)
        self.states: list[dict[str, Any]] = []
        self.node.create_subscription(String, topics.COACH_STATE, self._add(self.states, True), latched_qos())
        self._spinner = ExecutorThread(self.node, context=context)

    def _add(self, into: list, parse: bool):
        def callback(msg: Any) -> None:
            with self.lock:
                into.append(json.loads(msg.data) if parse else msg.data)
        return callback

    def publish_clock(self, t: float) -> None:
        self.clock_pub.publish(clock_message(t))

    def publish_hr(self, t: float, bpm: float) -> None:
        import numpy as np

        from hri_physio_bridge.frames import Frame
        from hri_physio_bridge.ros_frames import frame_to_msg

        self.hr_pub.publish(frame_to_msg(Frame(np.array([t]), np.array([[bpm]]), ("hr",))))

    def command(self, line: str) -> None:
        from std_msgs.msg import String

        # Subscribers: this probe and qt_controller.
        wait_until(lambda: self.input.get_subscription_count() >= 2, 30, "qt_controller's input")
        self.input.publish(String(data=line))

    def events(self, kind: str, source: str = "coach") -> list[dict[str, Any]]:
        with self.lock:
            pool = self.coach_events if source == "coach" else self.mock_events
            return [e for e in pool if e["event"] == kind]

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()


@pytest.fixture
def probe(ros_context: Any) -> Any:
    p = Probe(ros_context, "/test/coach/hr")
    try:
        yield p
    finally:
        p.close()


# --- start and stop -----------------------------------------------------------------------------
def test_interactive_waits_for_start_on_stdin_and_stops_on_sigterm(probe: Probe) -> None:
    from std_msgs.msg import String

    with NodeProcess("qt_physio_coach", "--interactive", "--ros-args", "-p", "hr_topic:=/test/coach/hr",
                     stdin=subprocess.PIPE) as coach:
        wait_until(lambda: probe.control.get_subscription_count() > 0, 20, "the coach to subscribe")
        # An unknown line is counted, and the state after it is published on a tick that ran the start
        # logic first: no start planned then proves the coach waits (it plans on its first tick otherwise).
        probe.control.publish(String(data="hello"))
        wait_until(lambda: any(st["control"]["received"] == 1 for st in probe.states), 20,
                   "the state that counts the unknown line")
        state = next(st for st in probe.states if st["control"]["received"] == 1)
        assert (state["state"], state["start_at"]) == ("idle", None), state
        # The state says how many subscriptions its commands reach (the probe's; a launcher starts on it).
        wait_until(lambda: any(st["command_listeners"] >= 1 for st in probe.states), 20, "command_listeners")
        assert not probe.events("session_start"), "started before 'start'"
        assert "waiting for 'start'" in coach.output
        assert coach.proc.stdin is not None
        coach.proc.stdin.write("start\n")
        coach.proc.stdin.flush()
        wait_until(lambda: probe.events("session_start"), 20, "session_start after 'start' on stdin")
        wait_until(lambda: probe.events("activity"), 20, "the first activity")
        # The state is published on the tick after the events: wait for the one that says it runs.
        wait_until(lambda: any(st["state"] == "running" for st in probe.states), 20, "a running state")
        state = next(st for st in probe.states if st["state"] == "running")
        where = (state["state"], state["phase"], state["activity"])
        assert where == ("running", "calibration", "seated_rest")
        assert state["participant"] == probe.events("session_start")[0]["participant"]
        assert (state["ladder_speed"], state["ladder_tempo"], state["policy"]) == (0.95, 115.0, "threshold")
        assert coach.stop(signal.SIGTERM) == 0, coach.output
        wait_until(lambda: probe.events("session_stopped"), 10, "the session_stopped event")
        assert probe.events("session_stopped")[0]["reason"] == "signal"
        assert "Traceback" not in coach.output


def test_without_interactive_the_session_starts_at_once(probe: Probe) -> None:
    with NodeProcess("qt_physio_coach", "--ros-args", "-p", "hr_topic:=/test/coach/hr") as coach:
        # /coach/state is latched: it reaches a late subscriber, unlike the session_start event.
        wait_until(lambda: any(st["state"] == "running" for st in probe.states), 30,
                   lambda: f"a running state on /coach/state\n{coach.output}")
        assert "waiting for 'start'" not in coach.output
        assert coach.stop(signal.SIGINT) == 0, coach.output
        assert "Traceback" not in coach.output


def test_start_on_the_control_topic_and_sigint(probe: Probe) -> None:
    from std_msgs.msg import String

    args = ("--interactive", "--ros-args", "-p", "hr_topic:=/test/coach/hr")
    with NodeProcess("qt_physio_coach", *args) as coach:
        wait_until(lambda: probe.control.get_subscription_count() > 0, 20, "the coach to subscribe")
        probe.control.publish(String(data="start"))
        wait_until(lambda: probe.events("session_start"), 20, "session_start after 'start' on /coach/control")
        assert coach.stop(signal.SIGINT) == 0, coach.output
        assert "Traceback" not in coach.output


# --- control lines: every one handled, also in a burst --------------------------------------------
def test_every_control_line_of_a_burst_is_handled_and_counted(probe: Probe) -> None:
    from std_msgs.msg import String

    burst = 10_000
    args = ("--interactive", "--ros-args", "-p", "hr_topic:=/test/coach/hr")
    with NodeProcess("qt_physio_coach", *args) as coach:
        wait_until(lambda: probe.control.get_subscription_count() > 0, 20, "the coach to subscribe")
        publish_burst(probe.control, (String(data=f"jump {i}") for i in range(burst)))
        probe.control.publish(String(data="start"))  # the line after the burst is not lost either

        def counted() -> dict[str, Any]:
            with probe.lock:
                return probe.states[-1] if probe.states else {}

        wait_until(lambda: counted().get("control", {}).get("received") == burst + 1, 120,
                   lambda: f"every control line counted; last state {counted()}\n{coach.output[-2000:]}")
        state = counted()
        assert state["control"] == {"received": burst + 1, "unknown": burst}
        wait_until(lambda: counted().get("state") == "running", 30, "the start after the burst")
        assert coach.stop(signal.SIGTERM) == 0, coach.output
    warnings = [line for line in coach.output.splitlines() if "unknown control line" in line]
    assert 1 <= len(warnings) < 20, "warnings about unknown words are rate-limited"
    assert "Traceback" not in coach.output


def test_stop_on_the_control_topic_before_the_start_ends_the_node(probe: Probe) -> None:
    from std_msgs.msg import String

    args = ("--interactive", "--ros-args", "-p", "hr_topic:=/test/coach/hr")
    with NodeProcess("qt_physio_coach", *args) as coach:
        wait_until(lambda: probe.control.get_subscription_count() > 0, 20, "the coach to subscribe")
        probe.control.publish(String(data="stop"))
        assert coach.wait(30) == 0, coach.output
        assert not probe.events("session_start")
        assert "stopped before the session started" in coach.output


# --- not alone: a second coach or a second clock on the same domain --------------------------------
def test_two_coaches_on_one_domain_both_say_so_and_stop(probe: Probe) -> None:
    from std_msgs.msg import String

    args = ("--interactive", "--ros-args", "-p", "hr_topic:=/test/coach/hr")
    first = NodeProcess("qt_physio_coach", *args, "-p", "part_name:=First")
    second = NodeProcess("qt_physio_coach", *args, "-p", "part_name:=Second")
    with first, second:
        # Each coach's latched state reaching the probe shows that the probe has matched that
        # coach's endpoints, so its conflict event will reach the probe too.
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        seen: set[str] = set()
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        probe.node.create_subscription(String, topics.COACH_STATE,
                                       lambda msg: seen.add(json.loads(msg.data)["participant"]), qos)
        wait_until(lambda: len(seen) == 2 and probe.control.get_subscription_count() >= 2, 30,
                   "both coaches' states")
        probe.control.publish(String(data="start"))  # one launcher's start reaches both
        codes = (first.wait(90), second.wait(90))
        assert codes == (1, 1), (first.output, second.output)
    wait_until(lambda: len(probe.events("conflict")) >= 2, 20,
               lambda: f"both conflict events: {probe.events('conflict')}\n{first.output}\n{second.output}")
    conflicts = probe.events("conflict")
    assert {e["conflict"] for e in conflicts} == {"second_coach"}
    assert len({e["participant"] for e in conflicts}) == 2  # one from each coach
    # Each says which publishers it saw, as far as graph discovery got: the other coach by name, a
    # publisher whose node is not known by name yet, or none when the other had already stopped.
    for e in conflicts:
        named = "qt_physio_coach" in " ".join(e["publishers"])
        assert named or any(w in e["reason"] for w in ("not known by name yet", "already gone")), e
        assert not any("_UNKNOWN_" in name for name in e["publishers"]), e
    stopped = probe.events("session_stopped")
    assert stopped and all(e["reason"] == "conflict: second_coach" for e in stopped)
    for coach in (first, second):
        assert "another session shares this ROS domain" in coach.output and "Traceback" not in coach.output


def test_a_second_clock_stops_the_coach_but_a_replaced_one_does_not(probe: Probe) -> None:
    from rosgraph_msgs.msg import Clock

    args = ("--ros-args", "-p", "use_sim_time:=true", "-p", "hr_topic:=/test/coach/hr",
            "-p", "tick_period:=0.25")
    with NodeProcess("qt_physio_coach", *args) as coach:
        coach.wait_for_output("participant P-")
        # The coach's time source and its clock watch.
        wait_until(lambda: probe.clock_pub.get_subscription_count() >= 2, 30, "the coach on /clock")
        def heard_after(t_min: float) -> bool:
            with probe.lock:
                return any(e["t"] > t_min for e in probe.coach_events)

        # Until the probe hears the running coach. Any event will do: the first ones (session_start
        # in the first tick) may go out before the coach's events writer has matched the probe.
        # Bounded in wall time: on a busy machine the probe may hear the coach many sim seconds late.
        t = SIM_START
        first = probe.clock_pub
        deadline = time.monotonic() + 120
        while not heard_after(0.0):
            t += 0.25
            first.publish(clock_message(t))
            time.sleep(0.01)
            assert time.monotonic() < deadline, coach.output
        # The launcher restarts: a new clock publisher replaces the first, which is gone.
        probe.node.destroy_publisher(first)
        replacement = probe.node.create_publisher(Clock, CLOCK, 10)
        wait_until(lambda: replacement.get_subscription_count() >= 2, 30, "the coach on the new clock")
        t_switch = t
        deadline = time.monotonic() + 120
        while not heard_after(t_switch):  # the session goes on on the new clock
            t += 0.25
            replacement.publish(clock_message(t))
            time.sleep(0.01)
            assert coach.proc.poll() is None and time.monotonic() < deadline, coach.output
        assert not probe.events("conflict")
        # Now a second clock takes turns with it: two sessions on one domain.
        intruder = probe.node.create_publisher(Clock, CLOCK, 10)
        wait_until(lambda: intruder.get_subscription_count() >= 2, 30, "the coach on the second clock")
        while coach.proc.poll() is None:
            t += 0.25
            replacement.publish(clock_message(t))
            intruder.publish(clock_message(t + 40.0))
            time.sleep(0.01)
            assert time.monotonic() < deadline + 120, coach.output
        assert coach.wait(10) == 1, coach.output
    wait_until(lambda: probe.events("conflict"), 20, "the conflict event")
    (conflict,) = probe.events("conflict")
    assert conflict["conflict"] == "second_clock" and conflict["topic"] == CLOCK
    assert probe.events("session_stopped")[0]["reason"] == "conflict: second_clock"
    assert "Traceback" not in coach.output


# --- the whole session under sim time ------------------------------------------------------------
STEP = 0.25  # s of sim time per /clock message: <= every listening node's timer period
SPEEDUP = 36.0  # sim seconds per wall second: 23 min in ~38 s
HR_WAIT = 3.0  # the coach's default hr_wait (s)
WARM, COND, COOL, END = 180.0, 480.0, 1080.0, 1380.0


def scripted_hr(rel: float) -> float:
    """Seated 85.4, below the zone in the warm-up, in it in conditioning, above it in the cool-down."""
    if rel < WARM + 5:  # a margin: a late sample of the warm-up must not count as resting
        return 85.4
    if rel < COND:
        return 110.0
    if rel < COOL:
        return 140.0
    return 165.0


def hold_for_the_coach(probe: Probe, t: float, stop: threading.Event, most: float = 5.0) -> float:
    """Wall seconds spent not moving the clock to ``t`` past a decision's wait for late heart rate
    (``next_decision`` in /coach/state + hr_wait) before the coach has decided it, as the session
    launcher's clock guard does: a coach starved for a moment on a busy machine would otherwise handle
    a burst of /clock before the heart rate queued behind it."""
    started = time.monotonic()

    def undecided() -> bool:
        with probe.lock:
            state = probe.states[-1] if probe.states else None
        due = None if state is None else state.get("next_decision")
        return due is not None and t >= due + HR_WAIT - 0.1

    while undecided() and not stop.is_set() and time.monotonic() - started < most:
        time.sleep(0.005)
    return time.monotonic() - started


def drive_clock(probe: Probe, stop: threading.Event, t0_holder: dict[str, float]) -> None:
    """/clock at SPEEDUP x real time in STEP increments; one HR frame per sim second."""
    t = SIM_START
    next_hr = SIM_START + 0.5
    wall0 = time.monotonic()
    k = 0
    while not stop.is_set():
        k += 1
        t = SIM_START + k * STEP
        probe.publish_clock(t)
        while next_hr <= t:
            t0 = t0_holder.get("t0")
            probe.publish_hr(next_hr, scripted_hr(next_hr - t0) if t0 is not None else 85.4)
            next_hr += 1.0
        t0_holder["now"] = t
        wall0 += hold_for_the_coach(probe, t + STEP, stop)
        delay = wall0 + k * STEP / SPEEDUP - time.monotonic()
        if delay > 0:
            time.sleep(delay)


def expected_gestures() -> list[tuple[str, float]]:
    """The gestures the robot must play: the routine with the ladder moved by the scripted HR."""
    out = [("base", 0.5), ("marching", 0.95)]
    out += [("marching", s) for s in (1.00, 1.05, 1.10, 1.15)]  # four speed-ups in the warm-up
    out += [("step_up", 1.15)]
    out += [(g, 1.15) for g in ("marching", "lateral", "marching", "arms_forward", "marching", "lateral",
                                "marching")]  # conditioning: in zone, no change
    out += [("step_up", 1.15), ("step_up", 1.10), ("step_up", 1.05), ("step_up", 1.00),
            ("step_up", 0.95)]  # cool-down: slow down (the update at 1200 s precedes the activity change)
    out += [("marching", 0.95), ("marching", 0.90)]
    return out


def expected_audio() -> list[str]:
    tempo = [115, 120, 125, 130, 135] + [135] * 9 + [130, 125, 120, 115, 115, 110]
    return ["relaxing"] + [f"beat:{t}" for t in tempo] + ["relaxing"]  # the packaged built-in sources


def expected_videos() -> list[str]:
    videos = ["marching", "step_up", "marching", "lateral", "marching", "arms_forward", "marching", "lateral",
              "marching", "step_up", "marching"]
    out = ["relaxing", "splash"]
    for v in videos:
        out += [v, "splash"]
    return [*out, "splash"]


def test_whole_session_under_sim_time_with_the_robot_side(probe: Probe) -> None:
    from std_msgs.msg import String

    sim = ["-p", "use_sim_time:=true"]
    mock = NodeProcess("mock_qt_robot", "--ros-args", *sim, "-p", "joint_state_rate:=4.0")
    controller = NodeProcess("qt_controller", "--ros-args", *sim)
    coach = NodeProcess("qt_physio_coach", "--interactive", "--ros-args", *sim, "-p", "tick_period:=0.25",
                        "-p", "hr_topic:=/test/coach/hr", "-p", "part_age:=33.0", "-p", "part_name:=Pilot",
                        "-p", "hr_timeout:=30.0", "-p", "seed:=3")
    stop = threading.Event()
    times: dict[str, float] = {}
    driver = threading.Thread(target=drive_clock, args=(probe, stop, times), daemon=True)
    with mock, controller, coach:
        for proc, text in ((mock, "mock QT robot"), (controller, "listening for commands"),
                           (coach, "participant P-")):
            proc.wait_for_output(text, timeout=30)
        wait_until(lambda: probe.clock_pub.get_subscription_count() >= 3
                   and probe.hr_pub.get_subscription_count() >= 1
                   and probe.node.count_publishers("/qt_robot/mock/events") >= 1, 30, "discovery")
        driver.start()
        try:
            # Make sure the robot side works end to end and its events reach us before the session
            # starts: a probe command, repeated until the mock reports it (discovery takes a while).
            deadline = time.monotonic() + 60
            while not probe.events("volume", "mock"):
                assert time.monotonic() < deadline, "the mock's events never reached the probe"
                probe.command("set volume 60")
                time.sleep(2.0)
            # Some of the repeated probes may have been lost to discovery: wait until the ones
            # that got through are all answered (counts stable for 2 s) before clearing them.
            last: list[tuple[int, int]] = []

            def settled() -> bool:
                last.append((len(probe.events("volume", "mock")), len(probe.replies)))
                recent = last[-100:]
                return len(last) >= 100 and len(set(recent)) == 1 and recent[0][1] >= 1

            wait_until(settled, 30, "the probe commands to be done")
            with probe.lock:
                probe.commands.clear()
                probe.replies.clear()
                probe.mock_events.clear()
            wall0 = time.monotonic()
            probe.control.publish(String(data="start"))
            wait_until(lambda: probe.events("session_start"), 30, "the session to start on sim time")
            t0 = probe.events("session_start")[0]["t"]
            times["t0"] = t0
            assert coach.wait(timeout=90) == 0, coach.output
            wall = time.monotonic() - wall0
            # Let the robot side catch up with the last commands (speech queued, media).
            def final_speech() -> bool:
                speech = probe.events("speech_queued", "mock") + probe.events("speech_started", "mock")
                return any("Congratulations" in e.get("text", "") for e in speech)

            wait_until(final_speech, 30, "the final speech at the mock")
        finally:
            stop.set()
            driver.join(5.0)
        assert wall <= 60.0, f"the 23-min session took {wall:.1f} s of wall time"
        assert mock.stop() == 0 and controller.stop() == 0
    output = coach.output
    assert "Traceback" not in output and "Pilot" not in output  # the log carries the id, not the name

    # --- the coach's own record: exact times relative to the start ---
    rel = lambda e: round(e["t"] - t0, 6)  # noqa: E731
    assert [(rel(e), e["phase"]) for e in probe.events("phase")] == [
        (0.0, "calibration"), (WARM, "warm_up"), (COND, "conditioning"), (COOL, "cool_down")]
    assert [rel(e) for e in probe.events("activity")] == [
        0.0, 180.0, 360.0, 480.0, 540.0, 660.0, 720.0, 840.0, 900.0, 1020.0, 1080.0, 1200.0]
    assert [rel(e) for e in probe.events("session_end")] == [END]
    rules = probe.events("rule_update")
    assert [rel(e) for e in rules] == [WARM + 30.0 * k for k in range(1, 40)]
    behaviours = [rel(e) for e in probe.events("behaviour") if e["kind"] not in ("reminder", "encouragement")]
    slots = [WARM + 20.0 * k for k in range(1, 60)]
    assert behaviours == [t for t in slots if (t - WARM) % 60]
    zone = probe.events("zone")[0]
    assert zone["hr_rest"] == pytest.approx(85.4) and zone["low"] == pytest.approx(125.2, abs=0.051)
    actions = [e["decision"]["action"] for e in rules]
    assert actions[:4] == ["speed_up"] * 4
    assert [a for a in actions if a == "slow_down"] == ["slow_down"] * 5
    assert "gated" not in actions and not probe.events("hr_lost")
    assert not probe.events("command_failed")
    assert all(e["participant"] == zone["participant"] for e in probe.coach_events)

    # --- what went on /QtController/input is what the coach logged, in order ---
    logged = [e["command"] for e in probe.events("command")]
    with probe.lock:
        sent = list(probe.commands)
    assert sent == logged
    with probe.lock:
        replies = list(probe.replies)
    assert len(replies) == len(sent) and all(r["ok"] for r in replies), [r for r in replies if not r["ok"]]

    # --- what the mock robot did ---
    gestures = [(e["name"], round(e["speed"], 2)) for e in probe.events("gesture_started", "mock")]
    # Each exercise gesture is played again and again for its activity (gesture_repeat): the changes are
    # the routine's, and there are many more plays than changes.
    changes = [g for i, g in enumerate(gestures) if i == 0 or g != gestures[i - 1]]
    assert changes == expected_gestures()
    assert len(gestures) > 5 * len(changes)
    assert [e["name"] for e in probe.events("audio", "mock")] == expected_audio()
    assert [e["name"] for e in probe.events("video", "mock")] == expected_videos()
    assert [e["volume"] for e in probe.events("volume", "mock")] == [60]
    said = {e["text"] for kind in ("speech_started", "speech_queued") for e in probe.events(kind, "mock")}
    spoken = [c.removeprefix("set speech ") for c in sent if c.startswith("set speech ")]
    assert set(spoken) <= said
    announcement = next(s for s in spoken if "resting heart rate" in s)
    assert "85.4" in announcement and "125.2" in announcement and "155.1" in announcement
    assert "QT/happy" in {e["name"] for e in probe.events("emotion_started", "mock")}
    # The robot acted on ROS time: the warm-up's first video soon after 180 s of sim time (a wall-time
    # stamp would be decades off). Soon: the command goes coach -> controller -> mock while the clock
    # runs at 36x, so a loaded machine's half second of wall time is 18 s here (13 s were seen).
    first_video = next(e for e in probe.events("video", "mock") if e["name"] == "marching")
    assert 0.0 <= first_video["t"] - (t0 + WARM) < 60.0

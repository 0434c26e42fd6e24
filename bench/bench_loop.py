"""Benchmark the whole closed loop at real time: CPU of every node, and the input path's latency.

Runs ``hri_physio_session --speed 1`` (the built-in defaults: simulated participant, receivers,
processor, coach, controller, mock robot, audio and video streamers, recorder) and, once the
session has started (the launcher says ``system ready``), waits for the routine's ``--phase``
(default ``conditioning``, as issue 28 measures it: 480 s in, after calibration and warm-up; the
exercise, with rule updates, gestures and music changes) and ``--settle`` seconds more. It then
reads utime + stime from /proc/<pid>/stat of the launcher and of every node process at the start
and at the end of a ``--seconds`` window (default 60), and prints each process's CPU time over
that window as a share of one core, and the total. ``--phase calibration`` measures the first
minute instead (seated rest, relaxing music and video, reminders: a quieter loop, 9 minutes less
per run).

Latency of the input path: this process opens its own LSL inlet on the strap's heart-rate stream
(``PolarH10/<device>/HR``) and subscribes, like the coach, to the coach's heart-rate input
(``/physio/polar_h10/hr``, the same QoS). Each sample carries its strap stamp; it is matched by
that stamp, and the latency is the time (``pylsl.local_clock``, one monotonic clock for both ends:
the LSL end runs in a child process of its own, so the ROS end's callbacks cannot delay its clock
reading) from its arrival on LSL to its arrival on the coach's topic: LSL push -> physio_receiver -> ROS 2 ->
the coach's input. The arrival on the topic is the time the subscriber's middleware received the
sample (DDS's ``received_timestamp`` in the message info, mapped onto the same monotonic clock): what
a subscriber's own executor adds after that (waking up, taking the message) depends on that process,
not on the path, and a Python callback in this process is a noisy stand-in for the coach's. That
figure is printed too (``to a Python callback``). p50 and p99 over the window. Not in the figure:
the hop from the strap's push to an inlet (localhost TCP, the same for this inlet as for the
receiver's).

Side by side in one run: ``--baseline-ref REF`` first runs the same session on the sources of git
commit REF (``git archive`` into a temporary folder, put first on PYTHONPATH; the console scripts
and the installed environment are the same), then on the working tree. ``--save FILE`` writes
the figures as JSON; ``--baseline FILE`` prints a saved run next to this one instead.
``--demo`` also runs the 23-minute session at the default 30x and reports its wall time.
``--live idle`` runs the session with ``--live`` (the live view, ``live_view`` in the table, with no
viewer connected); ``--live watched`` also connects a Foxglove WebSocket client that subscribes to
every channel for the whole window (the messages and bytes it took are printed).

The table also gives a floor: ``floor_node.py`` (an rclpy node that only follows ``/clock``) runs in
the session's domain over the same window, the least any node on the sim clock costs on this machine.
And the launcher's floor: after the window, with the session still running, ``launcher_floor.py``
does only the launcher's ROS work for ``--launcher-floor`` seconds (default 30; 0: not measured). It
takes what the launcher's subscriptions take and drives a clock like the session's to as many
processes. What the launcher costs above it is its own work.

``--rounds N`` alternates the two sides N times each (baseline, now, now, baseline, ...) and averages:
this machine drifts by 10-15 % over minutes, which one pair of runs would read as a change.

Run:  source scripts/env.sh && python bench/bench_loop.py --baseline-ref HEAD~5 --rounds 2
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pylsl
from baseline import source_tree

HERE = Path(__file__).resolve()
ROOT = HERE.parent.parent
TICK = os.sysconf("SC_CLK_TCK")
LAUNCHER = "hri_physio_session"
#: Nodes whose work is waiting for messages or timers: each should cost next to nothing.
WAITERS = ("hri_physio_session", "qt_physio_coach", "qt_controller", "mock_qt_robot", "hr_receiver")
GOALS = {"total": 20.0, "waiter": 1.0, "video_streamer": 4.0, "neurokit_processor": 3.0,
         "latency_p99_ms": 5.0, "demo_wall_s": 55.0}


@dataclass
class LoopResult:
    label: str
    seconds: float
    cpu: dict[str, float] = field(default_factory=dict)  # % of one core, by node
    latency_ms: list[float] = field(default_factory=list)  # to the coach's reader (DDS arrival)
    callback_latency_ms: list[float] = field(default_factory=list)  # to this process's Python callback
    demo_wall_s: float | None = None
    #: % of one core of floor_node.py over the same window: an rclpy node that only follows /clock.
    floor: float | None = None
    #: % of one core of launcher_floor.py, and of the launcher, over a window of their own after the main one.
    launcher_floor: float | None = None
    launcher_beside_floor: float | None = None

    @property
    def total(self) -> float:
        return sum(self.cpu.values())

    def p(self, q: float, latencies: list[float] | None = None) -> float:
        values = self.latency_ms if latencies is None else latencies
        return float(np.percentile(values, q)) if values else float("nan")


# -- /proc ---------------------------------------------------------------------------------------


def cpu_seconds(pid: int) -> float | None:
    """utime + stime of ``pid`` in seconds (None: gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) "
    return (int(fields[11]) + int(fields[12])) / TICK


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (children of children too), from /proc/<pid>/task/*/children."""
    out: list[int] = []
    todo = [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = [int(k) for k in (task / "children").read_text().split()]
            except OSError:
                continue
            out.extend(kids)
            todo.extend(kids)
    return out


def node_name(pid: int) -> str:
    """The session's name for a node process: its ``configs/<name>.yaml``, else its script's name."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return f"pid {pid}"
    for arg in argv:
        m = re.search(rb"configs/([\w.-]+)\.yaml$", arg)
        if m:
            return m.group(1).decode()
    scripts = [Path(a.decode(errors="replace")).name for a in argv[1:2] + argv[:1] if a]
    return scripts[0] if scripts else f"pid {pid}"


# -- the latency probe ---------------------------------------------------------------------------


def lsl_arrivals(name: str, measure: Any, counted: Any, stop: Any, conn: Any) -> None:
    """The arrival time (``pylsl.local_clock``) of each sample of LSL stream ``name``, by its stamp,
    taken while ``measure`` is set and ``counted`` is not; sent through ``conn`` once ``stop`` is set.

    Runs in a process of its own: in the bench's process, a ROS callback holding the GIL would delay
    this thread's clock reading (seen: samples that reached ROS "before" LSL, by up to 0.4 ms).
    """
    arrivals: dict[float, float] = {}
    found: list = []
    while not found and not stop.is_set():
        found = pylsl.resolve_byprop("name", name, 1, 1.0)
    if found:
        inlet = pylsl.StreamInlet(found[0], max_buflen=60)
        inlet.open_stream(30)
        while not stop.is_set():
            _sample, stamp = inlet.pull_sample(timeout=0.5)
            if stamp:
                now = pylsl.local_clock()
                if measure.is_set() and not counted.is_set():
                    arrivals[round(float(stamp), 6)] = now
        inlet.close_stream()
    conn.send(arrivals)
    conn.close()


class LatencyProbe:
    """Arrival of each strap HR sample on LSL and on the coach's input topic, by its own stamp.

    The LSL side is a process of its own (:func:`lsl_arrivals`); the ROS side is this process's
    executor thread, the only thread here that works during the window. Both read the same
    monotonic clock (``pylsl.local_clock``).
    """

    def __init__(self, device: str, topic: str, domain: int) -> None:
        import multiprocessing

        import rclpy
        from std_msgs.msg import Float64MultiArray

        from hri_physio_bridge.qos import frame_qos
        from hri_physio_bridge.ros_frames import msg_to_frame
        from hri_physio_bridge.ros_tools import ExecutorThread

        self.ros_arrival: dict[float, float] = {}  # strap stamp -> arrival on the coach's topic (DDS)
        self.callback_arrival: dict[float, float] = {}  # strap stamp -> this process's callback
        self._lsl_arrival: dict[float, float] | None = None  # strap stamp -> arrival on LSL, once ended
        self.measuring = False
        self._lock = threading.Lock()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)  # the session's, whatever this shell says
        self.node = rclpy.create_node(f"bench_loop_{uuid.uuid4().hex[:6]}", context=self.context)

        def on_frame(msg: Float64MultiArray, info: dict) -> None:
            now, wall_ns = pylsl.local_clock(), time.time_ns()
            # The middleware's receive time (system clock, ns) onto the monotonic clock, read together.
            received = now - (wall_ns - int(info["received_timestamp"])) * 1e-9
            stamps = msg_to_frame(msg).timestamps
            with self._lock:
                if self.measuring:
                    for t in stamps:
                        self.ros_arrival[round(float(t), 6)] = received
                        self.callback_arrival[round(float(t), 6)] = now

        self.node.create_subscription(Float64MultiArray, topic, on_frame, frame_qos())
        self._spinner = ExecutorThread(self.node, context=self.context)
        mp = multiprocessing.get_context("spawn")
        self._measure, self._counted, self._stop = mp.Event(), mp.Event(), mp.Event()
        self._conn, child_conn = mp.Pipe(duplex=False)
        self._lsl = mp.Process(target=lsl_arrivals, name="bench-lsl-arrivals", daemon=True,
                               args=(f"PolarH10/{device}/HR", self._measure, self._counted, self._stop,
                                     child_conn))
        self._lsl.start()

    def start_measuring(self) -> None:
        with self._lock:
            self.measuring = True
        self._measure.set()

    def stop_counting_lsl(self) -> None:
        """Samples that arrive on LSL from now on are not counted (those on ROS still are)."""
        self._counted.set()

    def _end_lsl(self) -> dict[float, float]:
        if self._lsl_arrival is None:
            self._stop.set()
            self._lsl_arrival = self._conn.recv() if self._conn.poll(10.0) else {}
            self._lsl.join(5.0)
        return self._lsl_arrival

    def latencies(self, arrival: dict[float, float] | None = None) -> list[float]:
        """Seconds from LSL to the coach's topic (or to ``arrival``) of each sample seen on both, in
        stamp order."""
        lsl = self._end_lsl()
        with self._lock:
            ros = dict(self.ros_arrival if arrival is None else arrival)
        both = sorted(set(lsl) & set(ros))
        return [ros[t] - lsl[t] for t in both]

    def close(self) -> None:
        import rclpy

        self._end_lsl()
        if self._lsl.is_alive():
            self._lsl.kill()
        self._spinner.close()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


# -- one session ---------------------------------------------------------------------------------


class LiveViewer:
    """A Foxglove WebSocket client on a thread of its own: subscribes to every channel, counts what comes."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.messages = 0
        self.bytes = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-viewer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import asyncio

        try:
            asyncio.run(self._watch())
        except Exception as exc:  # reported with the figures, not fatal to the bench
            self.error = f"{type(exc).__name__}: {exc}"

    async def _watch(self) -> None:
        import aiohttp

        async with aiohttp.ClientSession() as session, session.ws_connect(
                self.url, protocols=("foxglove.sdk.v1", "foxglove.websocket.v1")) as ws:
            while not self._stop.is_set():
                try:
                    msg = await ws.receive(timeout=0.5)
                except TimeoutError:
                    continue
                if msg.type == aiohttp.WSMsgType.TEXT:
                    data = json.loads(msg.data)
                    if data.get("op") == "advertise":
                        subs = [{"id": c["id"], "channelId": c["id"]} for c in data["channels"]]
                        await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": subs}))
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    self.messages += 1
                    self.bytes += len(msg.data)
                else:
                    raise RuntimeError(f"connection ended: {msg.type}")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)


def free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def phase_start(kind: str) -> float:
    """Session seconds from the start to the first phase of ``kind`` in the launcher's default routine."""
    from hri_physio_bringup.options import SessionConfig
    from hri_physio_bringup.plan import coach_config
    from hri_physio_coach.evaluate.simulation import session_routine

    start = 0.0
    for phase in session_routine(coach_config(SessionConfig())).phases:
        if phase.kind == kind:
            return start
        start += phase.duration
    raise SystemExit(f"the default routine has no {kind} phase")


def launcher_floor(label: str, domain: int, seconds: float, env: dict[str, str],
                   launcher: int) -> tuple[float, float] | None:
    """% of one core of ``launcher_floor.py`` (in the session's domain) and of the launcher (pid
    ``launcher``), over the same ``seconds`` once it is ready."""
    cmd = [sys.executable, str(HERE.parent / "launcher_floor.py"), "--domain", str(domain)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        said = proc.stdout.readline().strip()  # "ready: ..." (or nothing: it ended, and stderr says why)
        if not said.startswith("ready"):
            status = proc.wait(30)
            print(f"warning: {label}: launcher_floor.py did not start (status {status})", file=sys.stderr)
            return None
        print(f"{label}: launcher floor {said}", flush=True)
        start, wall0 = (cpu_seconds(proc.pid), cpu_seconds(launcher)), time.monotonic()
        time.sleep(seconds)
        end, wall = (cpu_seconds(proc.pid), cpu_seconds(launcher)), time.monotonic() - wall0
        if None in start or None in end or proc.poll() is not None:
            print(f"warning: {label}: launcher_floor.py or the launcher ended early", file=sys.stderr)
            return None
        return (end[0] - start[0]) / wall * 100.0, (end[1] - start[1]) / wall * 100.0
    finally:
        interrupt(proc, 60)


def interrupt(proc: subprocess.Popen, timeout: float) -> None:
    """SIGINT to ``proc`` if it still runs, then SIGKILL after ``timeout`` s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()


def run_loop(label: str, seconds: float, settle: float, env: dict[str, str] | None = None,
             live: str = "off", floor_seconds: float = 0.0) -> LoopResult:
    """The CPU of every process over ``seconds``, from ``settle`` s after the session's start."""
    env = dict(os.environ) if env is None else env
    device = "BENCH" + uuid.uuid4().hex[:6].upper()
    out = Path(tempfile.mkdtemp(prefix="bench_loop_"))
    cmd = [shutil.which(LAUNCHER, path=env["PATH"]) or LAUNCHER, "--speed", "1", "--out", str(out),
           "--device-id", device, "--no-report"]
    port = free_port()
    if live != "off":
        cmd += ["--live", f"127.0.0.1:{port}"]
    viewer: LiveViewer | None = None
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ready = threading.Event()
    lines: list[str] = []
    domain: list[int] = []  # the session's ROS domain, as it announces it (it claims a free one)

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip())
            found = re.search(r"ROS domain (\d+)", line)
            if found and not domain:
                domain.append(int(found.group(1)))
            if "system ready" in line:
                ready.set()

    threading.Thread(target=read, daemon=True).start()
    result = LoopResult(label, seconds)
    probe: LatencyProbe | None = None
    floor: subprocess.Popen | None = None
    try:
        deadline = time.monotonic() + 300
        while not ready.wait(0.5):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{label}: the session did not start:\n" + "\n".join(lines[-20:]))
        if not domain:
            raise RuntimeError(f"{label}: the session did not say its ROS domain:\n" + "\n".join(lines[-20:]))
        probe = LatencyProbe(device, "/physio/polar_h10/hr", domain[0])
        floor_cmd = [sys.executable, str(HERE.parent / "floor_node.py"), "--domain", str(domain[0])]
        floor = subprocess.Popen(floor_cmd, env=env)
        if live == "watched":
            viewer = LiveViewer(f"ws://127.0.0.1:{port}")
        time.sleep(settle)
        pids = {proc.pid: LAUNCHER, **{p: node_name(p) for p in descendants(proc.pid)}}
        start = {pid: cpu_seconds(pid) for pid in pids}
        floor_start = cpu_seconds(floor.pid)
        probe.start_measuring()
        wall0 = time.monotonic()
        taken0 = (viewer.messages, viewer.bytes) if viewer is not None else (0, 0)
        time.sleep(seconds)
        end = {pid: cpu_seconds(pid) for pid in pids}
        floor_end = cpu_seconds(floor.pid)
        wall = time.monotonic() - wall0
        if floor_start is not None and floor_end is not None and floor.poll() is None:
            result.floor = (floor_end - floor_start) / wall * 100.0
        else:
            print(f"warning: {label}: floor_node.py ended early (status {floor.poll()})", file=sys.stderr)
        if viewer is not None:
            print(f"{label}: the live viewer took {viewer.messages - taken0[0]} messages, "
                  f"{(viewer.bytes - taken0[1]) / 1e6:.2f} MB in the window"
                  + (f" (then: {viewer.error})" if viewer.error else ""), flush=True)
        probe.stop_counting_lsl()
        for pid, name in pids.items():
            a, b = start[pid], end[pid]
            if a is None or b is None:
                print(f"warning: {name} (pid {pid}) was not there for the whole window", file=sys.stderr)
                continue
            result.cpu[name] = result.cpu.get(name, 0.0) + (b - a) / wall * 100.0
        # Samples that reached the coach's topic until 2 s after the window are still counted.
        time.sleep(2.0)
        result.latency_ms = [x * 1e3 for x in probe.latencies()]
        result.callback_latency_ms = [x * 1e3 for x in probe.latencies(probe.callback_arrival)]
        if floor_seconds > 0:
            measured = launcher_floor(label, domain[0], floor_seconds, env, proc.pid)
            if measured is not None:
                result.launcher_floor, result.launcher_beside_floor = measured
    finally:
        if viewer is not None:
            viewer.close()
        if floor is not None:
            interrupt(floor, 30)
        interrupt(proc, 90)
        if probe is not None:
            probe.close()
        shutil.rmtree(out, ignore_errors=True)
    bad = [line for line in lines if "node exit statuses" in line or ": error:" in line]
    if bad:  # a node that hung on its way out, or crashed: the figures are not to be trusted
        print(f"warning: {label}: " + "; ".join(bad), file=sys.stderr)
    return result


def merged(rounds: list[LoopResult]) -> LoopResult:
    """One side's rounds as one result: each process's mean CPU, every latency, the mean floor."""
    out = LoopResult(rounds[0].label, rounds[0].seconds)
    for name in {n for r in rounds for n in r.cpu}:
        out.cpu[name] = float(np.mean([r.cpu[name] for r in rounds if name in r.cpu]))
    out.latency_ms = [x for r in rounds for x in r.latency_ms]
    out.callback_latency_ms = [x for r in rounds for x in r.callback_latency_ms]
    floors = [r.floor for r in rounds if r.floor is not None]
    out.floor = float(np.mean(floors)) if floors else None
    pairs = [(r.launcher_floor, r.launcher_beside_floor) for r in rounds if r.launcher_floor is not None]
    if pairs:
        out.launcher_floor, out.launcher_beside_floor = (float(x) for x in np.mean(pairs, axis=0))
    return out


def run_demo(env: dict[str, str] | None = None) -> float:
    """Wall seconds of the whole 23-minute session at the default speed (what scripts/demo runs)."""
    out = Path(tempfile.mkdtemp(prefix="bench_demo_"))
    try:
        subprocess.run([LAUNCHER, "--policy", "predictive", "--out", str(out), "--no-report"], env=env,
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        summary = json.loads(next(out.glob("*/summary.json")).read_text())
        return float(summary["wall_seconds"])
    finally:
        shutil.rmtree(out, ignore_errors=True)


# -- output --------------------------------------------------------------------------------------


def fmt(x: float | None, unit: str = "") -> str:
    return "-" if x is None or x != x else f"{x:.1f}{unit}"


def ratio(new: float | None, old: float | None) -> str:
    return "-" if not new or not old or new != new or old != old else f"{new / old:.2f}"


def table(now: LoopResult, base: LoopResult | None) -> None:
    names = sorted(set(now.cpu) | set(base.cpu if base else {}),
                   key=lambda n: -(base.cpu.get(n, 0.0) if base else now.cpu.get(n, 0.0)))
    print(f"\n== CPU over {now.seconds:g} s at 1x, % of one core ==")
    print(f"{'process':<22} {'baseline':>9} {'now':>7} {'now/base':>9}")
    for n in names:
        old = base.cpu.get(n) if base else None
        print(f"{n:<22} {fmt(old):>9} {fmt(now.cpu.get(n)):>7} {ratio(now.cpu.get(n), old):>9}")
    old_total = base.total if base else None
    print(f"{'total':<22} {fmt(old_total):>9} {fmt(now.total):>7} {ratio(now.total, old_total):>9}")
    old_floor = base.floor if base else None
    print(f"{'floor (not in total)':<22} {fmt(old_floor):>9} {fmt(now.floor):>7} "
          f"{ratio(now.floor, old_floor):>9}")
    print("  floor: floor_node.py in the session's domain, an rclpy node that only follows /clock: the\n"
          "  least any node on the session's sim clock costs on this machine (under any waiting node)")
    if now.launcher_floor is not None or (base and base.launcher_floor is not None):
        print("\n== The launcher beside its floor (a window of their own, after the one above) ==")
        print(f"{'':<22} {'baseline':>9} {'now':>7} {'now/base':>9}")
        for what, old, new in (
                (LAUNCHER, base.launcher_beside_floor if base else None, now.launcher_beside_floor),
                ("launcher_floor.py", base.launcher_floor if base else None, now.launcher_floor)):
            print(f"{what:<22} {fmt(old):>9} {fmt(new):>7} {ratio(new, old):>9}")
        print("  launcher_floor.py: only the launcher's ROS work (its subscriptions' messages taken, a\n"
              "  clock like the session's driven to as many processes); above it: the launcher's own work")
    print("\n== Input path: strap HR sample on LSL -> the coach's input topic (its reader's DDS arrival) ==")
    print(f"{'':<22} {'baseline':>9} {'now':>7} {'now/base':>9}")
    for q in (50, 99):
        old = base.p(q) if base else None
        print(f"{f'p{q} (ms)':<22} {fmt(old):>9} {fmt(now.p(q)):>7} {ratio(now.p(q), old):>9}")
    print(f"{'samples':<22} {len(base.latency_ms) if base else '-':>9} {len(now.latency_ms):>7}")
    print("  to a Python callback (the above, plus this process's executor waking to take it):")
    for q in (50, 99):
        old = base.p(q, base.callback_latency_ms) if base else None
        new = now.p(q, now.callback_latency_ms)
        print(f"{f'  p{q} (ms)':<22} {fmt(old):>9} {fmt(new):>7} {ratio(new, old):>9}")
    if now.demo_wall_s is not None or (base and base.demo_wall_s is not None):
        old = base.demo_wall_s if base else None
        print(f"\n23-minute session at 30x, wall s: baseline {fmt(old)}, now {fmt(now.demo_wall_s)}")


def goals(now: LoopResult) -> None:
    def line(what: str, value: float | None, limit: float, unit: str) -> None:
        met = "-" if value is None else ("MET" if value <= limit else "NOT MET")
        print(f"  {what:<44} {fmt(value, unit):>9}  (<= {limit:g}{unit}) {met}")

    print("\n== Goals (now) ==")
    line("whole loop at 1x", now.total, GOALS["total"], " %")
    worst = max((now.cpu.get(n, 0.0), n) for n in WAITERS)
    line(f"worst waiting node ({worst[1]})", worst[0], GOALS["waiter"], " %")
    if now.floor is not None:
        print(f"  {'  (the floor: a node that only follows /clock)':<44} {fmt(now.floor, ' %'):>9}")
    if worst[1] == LAUNCHER and now.launcher_floor is not None:
        print(f"  {'  (the launcher floor: its ROS work alone)':<44} {fmt(now.launcher_floor, ' %'):>9}")
    line("video_streamer", now.cpu.get("video_streamer"), GOALS["video_streamer"], " %")
    line("neurokit_processor", now.cpu.get("neurokit_processor"), GOALS["neurokit_processor"], " %")
    line("LSL -> coach input p99", now.p(99), GOALS["latency_p99_ms"], " ms")
    line("23-min session at 30x (wall)", now.demo_wall_s, GOALS["demo_wall_s"], " s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0,
                        help="measured window, wall = session seconds at 1x (default 60)")
    parser.add_argument("--phase", choices=("conditioning", "calibration"), default="conditioning",
                        help="the routine's phase the window is in (default conditioning: it begins 480 s "
                        "into the session at 1x)")
    parser.add_argument("--settle", type=float, default=5.0,
                        help="seconds after the phase's start before the window (default 5)")
    parser.add_argument("--baseline-ref", metavar="REF",
                        help="also run the sources of git commit REF first, and print both side by side")
    parser.add_argument("--baseline", metavar="FILE",
                        help="a run saved with --save, printed side by side (then --baseline-ref is not run)")
    parser.add_argument("--save", metavar="FILE", help="write this run's figures as JSON")
    parser.add_argument("--live", choices=("off", "idle", "watched"), default="off",
                        help="run the session with its live view: no viewer (idle) or a client subscribed "
                        "to every channel (watched); live_view's CPU is in the table")
    parser.add_argument("--rounds", type=int, default=1,
                        help="sessions per side, alternated (baseline, now, now, baseline, ...); the table "
                        "gives each node's mean CPU and the latencies of every round (default 1)")
    parser.add_argument("--launcher-floor", type=float, default=30.0, metavar="SECONDS",
                        help="after the window, measure launcher_floor.py beside the launcher for this long "
                        "(default 30; 0: not)")
    parser.add_argument("--demo", action="store_true",
                        help="also time the 23-minute session at 30x (with --baseline-ref: both)")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    settle = phase_start(args.phase) + args.settle
    window = f"{LAUNCHER} --speed 1, {args.seconds:g} s from {settle:g} s: the {args.phase} phase"
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}, python "
          f"{sys.version.split()[0]}, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '(a free one)')}")
    base: LoopResult | None = None
    if args.baseline:
        data = json.loads(Path(args.baseline).read_text())
        base = LoopResult(**data)
    with tempfile.TemporaryDirectory(prefix="bench_loop_src_") as tmp:
        env = source_tree(args.baseline_ref, Path(tmp)) if args.baseline_ref and not args.baseline else None
        bases: list[LoopResult] = []
        nows: list[LoopResult] = []
        for i in range(args.rounds):
            # baseline, now | now, baseline | ...: a machine that drifts (slower or faster over the
            # run) weighs on both sides alike
            order = ["base", "now"] if i % 2 == 0 else ["now", "base"]
            for which in order:
                if which == "base" and env is not None:
                    print(f"baseline: {args.baseline_ref} ({window}), round {i + 1}", flush=True)
                    bases.append(run_loop(args.baseline_ref, args.seconds, settle, env, live=args.live,
                                          floor_seconds=args.launcher_floor))
                elif which == "now":
                    print(f"now: the working tree ({window}), round {i + 1}", flush=True)
                    nows.append(run_loop("now", args.seconds, settle, live=args.live,
                                         floor_seconds=args.launcher_floor))
        if bases:
            base = merged(bases)
            if args.demo:
                base.demo_wall_s = run_demo(env)
    now = merged(nows)
    if args.demo:
        now.demo_wall_s = run_demo()
    if args.save:
        Path(args.save).write_text(json.dumps(asdict(now), indent=1))
    table(now, base)
    goals(now)


if __name__ == "__main__":
    main()

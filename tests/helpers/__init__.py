"""Shared test helpers: where things are, waiting, node subprocesses, ROS 2 frame collectors.

More specific helpers live beside this module (``helpers.bags``, ``helpers.processing``, ...).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: The repository, its tests' data and its packages' sources.
ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SRC = ROOT / "src"
#: Seconds a test waits for a NeuroKit2 node's first sign of life (its subscription, outlet or first
#: line): the processor and the simulator import NeuroKit2 before anything else, and on a loaded CI
#: machine (three test workers beside the session tests and a busy core) that took 50-60 s once.
NEUROKIT_START = 120.0


def wait_until(predicate: Callable[[], bool], timeout: float, what: str | Callable[[], str],
               period: float = 0.02) -> None:
    """Poll ``predicate``; on timeout fail with ``what`` (a callable is evaluated then)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            text = what() if callable(what) else what
            raise AssertionError(f"timed out after {timeout:g} s waiting for {text}")
        time.sleep(period)


#: A line the DDS middleware logs by itself: Fast DDS's "<date> <time> [CATEGORY Error] ...", coloured.
_MIDDLEWARE_LINE = re.compile(r"^(?:\x1b\[[\d;]*m)*\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d+ (?:\x1b\[[\d;]*m)*\[")


def own_lines(stderr: str) -> list[str]:
    """The lines of ``stderr`` our program wrote, without the middleware's own log lines.

    Fast DDS logs, for example, "Failed init_port fastdds_port7004: open_and_lock_file failed" when
    a killed process left its shared-memory port behind, then picks another port. That line is not
    ours to keep to one line; ours still must be.
    """
    return [line for line in stderr.strip().splitlines() if not _MIDDLEWARE_LINE.match(line)]


def wait_unmatched(node, timeout: float = 5.0) -> bool:
    """Until none of ``node``'s publishers and subscriptions is matched any more (at most ``timeout``).

    For a node about to be destroyed whose peers, node subprocesses, have just exited. Fast DDS hears
    of a peer's departure on threads of its own and unmatches its endpoints there; deleting an endpoint
    meanwhile can crash (eProsima/Fast-DDS#3303: a match callback on a reader being deleted). A loaded
    run's test worker died of a segfault in such a ``destroy_node``. Bounded: a peer killed without a
    goodbye leaves only when its lease ends, and the node is then destroyed all the same. Only for a
    node with no live peer left in its domain (it would wait the whole ``timeout``).
    """
    from hri_physio_bridge.waiting import wait_until as waited

    def unmatched() -> bool:
        return (all(p.get_subscription_count() == 0 for p in node.publishers)
                and all(s.get_publisher_count() == 0 for s in node.subscriptions))

    return waited(unmatched, timeout, poll=0.02)


def publish_burst(publisher, messages, timeout: float = 60.0) -> None:
    """Publish every message in order as fast as the reliable KEEP_ALL ``publisher`` takes them.

    Fast DDS keeps at most 5000 unacknowledged samples per writer; a write that finds them all
    still unacknowledged waits 100 ms and then fails ("cannot publish data"). A burst sender
    that must lose nothing sends that same message again once the subscriber has caught up.
    """
    from rclpy.impl.implementation_singleton import rclpy_implementation

    for msg in messages:
        deadline = time.monotonic() + timeout
        while True:
            try:
                publisher.publish(msg)
                break
            except rclpy_implementation.RCLError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)


def run_to_end(command: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess[str]:
    """``subprocess.run`` for a session: output (stdout and stderr together) as text; past ``timeout``
    it gets SIGINT and 60 s to stop its nodes and write its summary before SIGKILL, and the result says
    ``timed out`` on its last line (returncode as it ended)."""
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, text=True, **kwargs)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        out += f"\n(timed out after {timeout:g} s: stopped with SIGINT)"
    return subprocess.CompletedProcess(command, proc.returncode, out, None)


def session_env(**extra: str) -> dict[str, str]:
    """The environment for an ``hri_physio_session`` under test, plus ``extra``.

    Without ``ROS_DOMAIN_ID``: the test process holds its own domain, so the session claims a free
    one of its own (as it does for a user who exported none) and never shares the test's.
    """
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    env.update(extra)
    return env


class NodeProcess:
    """A console-script node in a subprocess, output captured to a file."""

    def __init__(self, script: str, *args: str, stdin: int | None = subprocess.DEVNULL,
                 env: dict[str, str] | None = None, prefix: tuple[str, ...] = ()) -> None:
        """``prefix``: a command the script runs under (e.g. ``ip netns exec <namespace>``)."""
        self.log_file = tempfile.NamedTemporaryFile("w+", suffix=f"-{script}.log", delete=False)  # noqa: SIM115
        exe = str(Path(sys.prefix) / "bin" / script)
        self.proc = subprocess.Popen(
            [*prefix, exe, *args], stdout=self.log_file, stderr=subprocess.STDOUT, stdin=stdin,
            env=dict(os.environ) if env is None else env, text=True,
        )
        self._final_output: str | None = None

    @property
    def output(self) -> str:
        if self._final_output is not None:
            return self._final_output
        return Path(self.log_file.name).read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float = 20.0) -> None:
        wait_until(lambda: text in self.output or self.proc.poll() is not None, timeout,
                   lambda: f"{text!r}; its output so far:\n{self.output[-4000:]}")
        assert text in self.output, f"process exited before printing {text!r}:\n{self.output}"

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 15.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._abort_with_stacks()
            raise AssertionError(
                f"process did not exit within {timeout} s after {sig}:\n{self.output}"
            ) from None

    def _abort_with_stacks(self) -> None:
        """End a process stuck on its way out with SIGABRT: a node prints every thread's stack (its
        output then says where it was stuck); SIGKILL if even that does not end it."""
        self.proc.send_signal(signal.SIGABRT)
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def wait(self, timeout: float = 30.0) -> int:
        """The exit status; after ``timeout`` a failure, once SIGINT let the process say what it was doing
        (a session writes its summary and stops its nodes) and, if need be, SIGKILL ended it."""
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self._abort_with_stacks()
            raise AssertionError(f"process still running after {timeout} s:\n{self.output}") from None

    def __enter__(self) -> NodeProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._final_output = self.output
        self.log_file.close()
        os.unlink(self.log_file.name)


#: Deeper than the nodes' 1000: a test's bursts must not outrun a collector slowed by CI load.
COLLECTOR_DEPTH = 10_000


class RosFrameCollector:
    """An rclpy node on its own executor thread that collects decoded frames from topics."""

    def __init__(self, context: object, name: str = "collector") -> None:
        from rclpy.node import Node

        from hri_physio_bridge.ros_tools import ExecutorThread

        self.node = Node(name, context=context)
        self.frames: dict[str, list] = {}
        self._lock = threading.Lock()
        self._spinner = ExecutorThread(self.node, context=context)

    def subscribe_frames(self, topic: str) -> list:
        from std_msgs.msg import Float64MultiArray

        from hri_physio_bridge.qos import frame_qos
        from hri_physio_bridge.ros_frames import msg_to_frame

        got: list = self.frames.setdefault(topic, [])

        def on_msg(msg: Float64MultiArray) -> None:
            with self._lock:
                got.append(msg_to_frame(msg))

        self.node.create_subscription(Float64MultiArray, topic, on_msg, frame_qos(COLLECTOR_DEPTH))
        return got

    def publishers(self, topic: str) -> int:
        return self.node.count_publishers(topic)

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()


def concat_new_samples(frames: list, frame_size: int, overlap: int) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps and values of every frame, minus the overlap each full frame repeats.

    The receiver's last frame at shutdown is shorter and holds only new samples.
    """
    ts, vs = [], []
    for i, f in enumerate(frames):
        skip = overlap if i and f.num_samples == frame_size else 0
        ts.append(f.timestamps[skip:])
        vs.append(f.values[skip:])
    return np.concatenate(ts), np.concatenate(vs)


def resolve_lsl(name: str | None = None, timeout: float = 30.0, *, pred: str | None = None,
                minimum: int = 1) -> list:
    """The LSL streams named ``name`` (or matching the XPath predicate ``pred``), waited for until
    ``minimum`` of them are seen or ``timeout`` has passed (then what was seen, maybe none).

    A continuous resolver, polled, as the product resolves: liblsl's one-shot resolves
    (``resolve_byprop``) can miss a stream for many seconds on a busy machine.
    """
    import pylsl

    resolver = pylsl.ContinuousResolver(pred=pred if pred is not None else f"name='{name}'")
    found: list = []

    def appeared() -> bool:
        found[:] = resolver.results()
        return len(found) >= minimum

    deadline = time.monotonic() + timeout
    while not appeared() and time.monotonic() < deadline:
        time.sleep(0.1)
    return found

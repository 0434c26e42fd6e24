"""run_node: the ROS parameters a node declares (read-only unless applied at run time), and its exit."""

from __future__ import annotations

from typing import Any

import pytest

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_bridge.node_runner import ManagedNode, _descriptor
from hri_physio_bridge.ros_tools import ExecutorThread
from qt_controller.config import MockQtRobotConfig

pytestmark = pytest.mark.ros


class Options(NodeConfig):
    rate: float = option(2.0, "a rate", unit="Hz", gt=0)
    gain: float = option(1.0, "a gain", ge=0, le=10, dynamic=True)


def test_descriptors_are_read_only_unless_the_option_is_dynamic() -> None:
    assert _descriptor(Options, "rate").read_only and not _descriptor(Options, "gain").read_only
    assert "(settable at run time)" in Options.describe("gain")
    assert "settable" not in Options.describe("rate")
    dynamic = set(MockQtRobotConfig.dynamic_options())
    assert dynamic == {"speech_seconds_per_char", "emotion_seconds", "max_joint_speed", "gesture_busy_policy"}
    for name in MockQtRobotConfig.model_fields:
        assert _descriptor(MockQtRobotConfig, name).read_only == (name not in dynamic)


def test_a_node_that_does_not_apply_a_dynamic_option_refuses_its_change(ros_context: Any) -> None:
    from rclpy.parameter import Parameter

    class Node(ManagedNode):
        def __init__(self) -> None:
            super().__init__("runner_test_node", context=ros_context)
            self.config = self.declare_config(Options())

    node = Node()
    spinner = ExecutorThread(node, context=ros_context)
    try:
        (result,) = node.set_parameters([Parameter("gain", value=2.0)])
        assert not result.successful and "applies no change of gain" in result.reason
        (result,) = node.set_parameters([Parameter("rate", value=3.0)])
        assert not result.successful and "read-only" in result.reason
        assert (node.get_parameter("gain").value, node.get_parameter("rate").value) == (1.0, 2.0)
        (result,) = node.set_parameters([Parameter("use_sim_time", value=False)])  # rclpy's own
        assert result.successful
    finally:
        spinner.close()
        node.destroy_node()


NODE_SCRIPT = """
import ctypes, gc, sys, threading, time, weakref
import rclpy
from hri_physio_bridge import node_runner, ros_tools
from hri_physio_bridge.config import NodeConfig, option

class Options(NodeConfig):
    status: int = option(3, "the exit status", ge=0)

made = []

class Node(node_runner.ManagedNode):
    def __init__(self, config):
        super().__init__("teardown_test")
        self.config = self.declare_config(config)
        self.callbacks = [lambda: self]  # a reference cycle, as a streamer's callback makes
        made.append(weakref.ref(self))
    def run(self, stop):
        print("worked", flush=True)
        return self.config.status

def sleep_holding_the_gil():  # as Fast DDS deleting a writer from rclpy's C++: no Python thread runs
    ctypes.PyDLL(None).sleep(3600)

if sys.argv[1] != "normal":  # long enough for the real parts of a teardown on a busy machine
    ros_tools.TEARDOWN_TIMEOUT = 3.0
if sys.argv[1] == "hang":
    rclpy.try_shutdown = lambda: time.sleep(3600)  # a middleware teardown that never ends
elif sys.argv[1] == "hang_destroying_the_node":
    Node.destroy_node = lambda self: time.sleep(3600)  # a writer's deletion that never ends
elif sys.argv[1] == "hang_holding_the_gil":
    Node.destroy_node = lambda self: sleep_holding_the_gil()
elif sys.argv[1] == "hang_freeing_the_node":
    Node.__del__ = lambda self: time.sleep(3600)  # a destructor that waits, as native ones can
gc.disable()  # only run_node may free the node's cycle
status = node_runner.run_node("teardown_test", Options, Node, argv=sys.argv[2:])
if made and made[0]() is not None:
    sys.exit("the node outlived run_node: " + repr(gc.get_referrers(made[0]())))
sys.exit(status)
"""


@pytest.mark.parametrize("mode", ["hang", "hang_destroying_the_node", "hang_holding_the_gil",
                                  "hang_freeing_the_node", "normal"])
def test_a_stuck_middleware_teardown_is_bounded_and_the_work_s_status_is_said_first(mode: str,
                                                                                     tmp_path) -> None:
    import subprocess
    import sys
    import time

    from hri_physio_bridge.exit_progress import said_status

    script = tmp_path / "node.py"
    script.write_text(NODE_SCRIPT)
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, str(script), mode, "--status", "0"], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert time.monotonic() - t0 < 60  # the hour-long hangs were cut off
    assert done.stdout == "worked\n"
    lines = done.stderr.splitlines()
    assert "teardown_test: finished with exit status 0; shutting down ROS 2" in lines, done.stderr
    assert [said_status(line) for line in lines if said_status(line) is not None] == [0]
    if mode == "normal":
        assert done.returncode == 0, done.stderr
        assert "Timeout" not in done.stderr
    else:  # faulthandler's timer: where it hung, then status 1
        assert done.returncode == 1, done.stderr
        assert "Timeout (0:00:03)!" in done.stderr
        hung_in = {"hang": "<lambda>", "hang_destroying_the_node": "<lambda>",
                   "hang_holding_the_gil": "sleep_holding_the_gil", "hang_freeing_the_node": "<lambda>"}[mode]
        assert f"in {hung_in}" in done.stderr, done.stderr


@pytest.mark.parametrize(("status", "code"), [("4", 4), ("-1", 2)])
def test_a_node_that_fails_says_no_done_line(status: str, code: int, tmp_path) -> None:
    """Its work failed (status 4), or it never started (a bad option: status 2): its own error says so."""
    import subprocess
    import sys

    script = tmp_path / "node.py"
    script.write_text(NODE_SCRIPT)
    done = subprocess.run([sys.executable, str(script), "normal", "--status", status], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == code and "finished with exit status" not in done.stderr, done.stderr


FAILING_CALLBACK_SCRIPT = """
import sys
from hri_physio_bridge import node_runner
from hri_physio_bridge.config import NodeConfig, option

class Options(NodeConfig):
    fail_after: int = option(3, "the timer call that raises", ge=1)
    on_stop_fails: bool = option(False, "on_stop raises too")

class Node(node_runner.ManagedNode):
    def __init__(self, config):
        super().__init__("failing_callback_test")
        self.config = self.declare_config(config)
        self.calls = 0
        self.create_timer(0.05, self.tick)
    def tick(self):
        self.calls += 1
        if self.calls == self.config.fail_after:
            raise ZeroDivisionError("the bug in this callback")
    def on_stop(self, signal_name):
        print(f"on_stop: {signal_name}", flush=True)
        if self.config.on_stop_fails:
            raise RuntimeError("on_stop failed as well")
    def close(self):
        print(f"closed after {self.calls} calls", flush=True)

sys.exit(node_runner.run_node("failing_callback_test", Options, Node, argv=sys.argv[1:]))
"""


@pytest.mark.parametrize("on_stop_fails", ["false", "true"])
def test_a_callback_that_raises_stops_the_node_with_status_1(tmp_path, on_stop_fails: str) -> None:
    """The spin ends with the exception: the node stops as after a signal (on_stop, run returns,
    close), says why in one line after the traceback, and exits 1, instead of living on unspun; also
    when its on_stop fails as well."""
    import subprocess
    import sys

    script = tmp_path / "node.py"
    script.write_text(FAILING_CALLBACK_SCRIPT)
    done = subprocess.run([sys.executable, str(script), "--on-stop-fails", on_stop_fails],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 1, done.stderr
    assert "on_stop: a failed callback" in done.stdout and "closed after 3 calls" in done.stdout, done.stdout
    assert "Traceback" in done.stderr and "ZeroDivisionError: the bug in this callback" in done.stderr
    errors = [line for line in done.stderr.splitlines() if line.startswith("failing_callback_test: error:")]
    assert errors == ["failing_callback_test: error: a callback failed (ZeroDivisionError: the bug in this "
                      "callback); the node stopped"], done.stderr
    assert "finished with exit status" not in done.stderr


def test_the_executor_thread_waits_without_polling_and_close_wakes_it(ros_context: Any) -> None:
    """The spin waits until there is work (no timeout to poll a flag): close() itself ends the wait."""
    import threading

    import rclpy
    from std_msgs.msg import String

    node = rclpy.create_node("executor_thread_test", context=ros_context)
    heard = threading.Event()
    node.create_subscription(String, "/executor_thread_test", lambda _m: heard.set(), 10)
    publisher = node.create_publisher(String, "/executor_thread_test", 10)
    spinner = ExecutorThread(node, context=ros_context)
    try:
        for _ in range(100):  # matched within a few tries: a message wakes the waiting thread
            publisher.publish(String(data="hello"))
            if heard.wait(0.1):
                break
        assert heard.is_set()
    finally:
        spinner.close(join_timeout=30.0)
        node.destroy_node()
    assert not spinner._thread.is_alive()  # woken by close(), not by a timeout of its own


FINISHING_SCRIPT = """
import sys
from hri_physio_bridge import node_runner
from hri_physio_bridge.config import NodeConfig

class Node(node_runner.ManagedNode):
    def __init__(self, config):
        super().__init__("finishing_test")
        self.config = self.declare_config(config)
        self.calls = 0
        self.create_timer(0.05, self.tick)
    def tick(self):
        self.calls += 1
        if self.calls == 3:
            self.finished = True  # the default run() waits for this or a stop signal
    def close(self):
        print(f"closed after {self.calls} calls, finished {self.finished}", flush=True)

sys.exit(node_runner.run_node("finishing_test", NodeConfig, Node, argv=sys.argv[1:]))
"""


def test_a_node_that_sets_finished_ends_the_default_run(tmp_path) -> None:
    """The default run() waits (no polling) and ``finished = True`` from a callback wakes it: the node
    closes and exits 0 by itself."""
    import re
    import subprocess
    import sys

    script = tmp_path / "node.py"
    script.write_text(FINISHING_SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr
    closed = re.fullmatch(r"closed after (\d+) calls, finished True\n", done.stdout)
    assert closed is not None and int(closed.group(1)) >= 3, done.stdout  # a busy machine may tick on

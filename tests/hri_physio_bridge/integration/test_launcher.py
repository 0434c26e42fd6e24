"""The process launcher: output capture, clean stop escalation, missing scripts."""

from __future__ import annotations

import io
import os
import signal
import stat
import sys
from pathlib import Path

import pytest

from hri_physio_bridge.launcher import ManagedProcess, ProcessGroup, find_executable


def script(tmp_path: Path, name: str, body: str) -> str:
    path = tmp_path / name
    path.write_text(f"#!{sys.executable}\n{body}")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return str(path)


@pytest.fixture
def on_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    return tmp_path


def ignoring(on_path: Path, name: str, *signals: str) -> str:
    """A script that ignores ``signals``, prints 'ready' and idles."""
    ignore = "".join(f"signal.signal(signal.{sig}, signal.SIG_IGN)\n" for sig in signals)
    return script(on_path, name, f"import signal, time\n{ignore}print('ready', flush=True)\n"
                                 "while True: time.sleep(0.05)\n")


def started(group: ProcessGroup, *names: str) -> list[ManagedProcess]:
    """Start the scripts ``<name>_node`` as ``name`` and wait until each has printed 'ready'."""
    procs = [group.start(name, f"{name}_node", env=dict(os.environ)) for name in names]
    for p in procs:
        while "ready" not in p.lines:
            assert p.returncode is None
    return procs


def test_output_is_prefixed_and_kept(on_path: Path) -> None:
    script(on_path, "hello_node", "print('hello'); print('bye')\n")
    out = io.StringIO()
    group = ProcessGroup(out=out)
    p = group.start("greeter", "hello_node", env=dict(os.environ))
    assert group.wait_any_exit(10) is p
    assert group.stop() == {"greeter": 0}
    assert out.getvalue().splitlines() == ["[greeter] hello", "[greeter] bye"]
    assert p.lines == ["hello", "bye"]


def test_stop_sends_sigint_first_and_escalates(on_path: Path) -> None:
    script(on_path, "polite_node", (
        "import signal, sys, time\n"
        "signal.signal(signal.SIGINT, lambda *a: (print('flushed', flush=True), sys.exit(0)))\n"
        "print('ready', flush=True)\n"
        "while True: time.sleep(0.05)\n"))
    ignoring(on_path, "stubborn_node", "SIGINT", "SIGTERM")
    group = ProcessGroup(out=io.StringIO())
    polite, _ = started(group, "polite", "stubborn")
    codes = group.stop(grace=0.5)
    assert codes["polite"] == 0 and "flushed" in polite.lines
    assert codes["stubborn"] == -signal.SIGABRT  # after SIGINT and SIGTERM were ignored


def test_a_node_still_working_on_its_way_out_is_not_cut_short(on_path: Path) -> None:
    """A drain that takes longer than the grace (a busy machine, a long backlog) runs to its end."""
    script(on_path, "draining_node", (
        "import signal, sys, time\n"
        "from hri_physio_bridge.stop_signals import install_stop_handlers\n"
        "stop = install_stop_handlers()\n"
        "print('ready', flush=True)\n"
        "stop.wait()\n"
        "t0 = time.process_time()\n"
        "while time.process_time() - t0 < 1.5: pass  # 1.5 s of CPU: the backlog\n"
        "print('drained', flush=True)\n"))
    group = ProcessGroup(out=io.StringIO())
    (draining,) = started(group, "draining")
    codes = group.stop(grace=0.3)
    assert codes == {"draining": 0} and "drained" in draining.lines
    assert group.stop_seconds["draining"] >= 1.5


def test_the_next_node_is_stopped_once_this_one_s_work_is_over_not_its_teardown(on_path: Path,
                                                                              tmp_path: Path) -> None:
    """Reverse start order is kept (each node outlives those started after it), and a node's ROS 2
    teardown, after its done line, overlaps the next node's stop instead of coming before it."""
    events = tmp_path / "events.txt"
    for name in ("first", "second", "third"):
        script(on_path, f"{name}_node", (
            "import time\n"
            "from hri_physio_bridge.exit_progress import done_line\n"
            "from hri_physio_bridge.stop_signals import install_stop_handlers\n"
            "def note(what):\n"
            f"    with open({str(events)!r}, 'a') as f: f.write(f'{name} {{what}} {{time.monotonic()}}\\n')\n"
            "stop = install_stop_handlers()\n"
            "print('ready', flush=True)\n"
            "stop.wait()\n"
            "note('stopping')\n"
            f"print(done_line({name!r}, 0), flush=True)\n"
            "time.sleep(3.0)  # a slow middleware teardown\n"
            "note('exiting')\n"))
    group = ProcessGroup(out=io.StringIO())
    started(group, "first", "second", "third")
    assert group.stop(grace=5.0) == {"first": 0, "second": 0, "third": 0}
    at = {(n, what): float(t) for n, what, t in (line.split() for line in events.read_text().splitlines())}
    for later, earlier in (("third", "second"), ("second", "first")):
        assert at[(later, "stopping")] < at[(earlier, "stopping")] < at[(later, "exiting")], at
    assert group.teardown_faults() == []


def test_a_node_stuck_on_its_way_out_prints_where_before_it_is_killed(on_path: Path) -> None:
    """SIGINT is taken, the node then hangs (as in a close that never returns): SIGABRT shows where."""
    script(on_path, "stuck_node", (
        "import sys, time\n"
        "from hri_physio_bridge.node_runner import _enable_stack_dumps\n"
        "from hri_physio_bridge.stop_signals import install_stop_handlers\n"
        "_enable_stack_dumps()\n"
        "stop = install_stop_handlers()\n"
        "def close_that_never_returns():\n"
        "    while True: time.sleep(0.05)\n"
        "print('ready', flush=True)\n"
        "stop.wait()\n"
        "close_that_never_returns()\n"))
    ignoring(on_path, "deaf_node", "SIGINT", "SIGTERM", "SIGABRT")
    group = ProcessGroup(out=io.StringIO())
    stuck, _ = started(group, "stuck", "deaf")
    codes = group.stop(grace=0.5)
    assert codes == {"stuck": -signal.SIGABRT, "deaf": -signal.SIGKILL}
    assert any("close_that_never_returns" in line for line in stuck.lines), stuck.lines


def test_a_node_s_outcome_is_the_status_its_work_ended_with_not_its_teardown_s(on_path: Path) -> None:
    """A node that said its work ended (status 0) and then died in the middleware's teardown (cut off
    with status 1, or a crash) counts as 0; the teardown is a fault said apart. A node that said
    nothing is its process's status."""
    from hri_physio_bridge.exit_progress import done_line

    script(on_path, "cut_node", f"import os\nprint({done_line('cut_node', 0)!r}, flush=True)\n"
                                "print('Timeout (0:00:05)!', flush=True)\nos._exit(1)\n")
    script(on_path, "crash_node", "import os, resource, signal\n"
                                  f"print({done_line('crash_node', 3)!r}, flush=True)\n"
                                  "resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # no core file\n"
                                  "os.kill(os.getpid(), signal.SIGSEGV)\n")
    script(on_path, "fine_node", f"import sys\nprint({done_line('fine_node', 0)!r}, flush=True)\n")
    script(on_path, "plain_node", "import sys\nprint('oops', flush=True)\nsys.exit(5)\n")
    group = ProcessGroup(out=io.StringIO())
    cut, crash, fine, plain = (group.start(n, f"{n}_node", env=dict(os.environ))
                               for n in ("cut", "crash", "fine", "plain"))
    for p in (cut, crash, fine, plain):
        p.proc.wait(30)
    assert (cut.returncode, crash.returncode, fine.returncode, plain.returncode) == (0, 3, 0, 5)
    assert group.stop() == {"cut": 0, "crash": 3, "fine": 0, "plain": 5}
    assert group.teardown_faults() == [
        "cut finished its work (exit status 0), then its process exited with status 1 while shutting "
        "down ROS 2 (the middleware's teardown hung or failed; its log has the stack)",
        f"crash finished its work (exit status 3), then its process was killed by signal {signal.SIGSEGV} "
        "while shutting down ROS 2 (the middleware's teardown hung or failed; its log has the stack)",
    ]
    assert fine.teardown_fault is None and plain.teardown_fault is None
    assert plain.error_line() == "oops"
    assert crash.error_line() == "no output (exit status 3)"  # the done line is no error message


def test_a_failed_node_is_reported_by_its_own_error_line() -> None:
    """What a launcher says when a node refuses to start: the node's one-line error, not a count."""
    group = ProcessGroup(out=io.StringIO())
    sim = group.start("simulator", "physio_simulator", ["--bpm", "0"], env=dict(os.environ), echo=False)
    assert group.wait_any_exit(60) is sim
    group.stop()
    assert sim.returncode == 2
    line = sim.error_line()
    assert line.startswith("physio_simulator: error:") and "bpm" in line, sim.lines


def test_wait_any_exit_ends_on_timeout_and_on_stop(on_path: Path) -> None:
    import threading

    script(on_path, "idle_node", "import time\nwhile True: time.sleep(0.05)\n")
    group = ProcessGroup(out=io.StringIO())
    group.start("idle", "idle_node", env=dict(os.environ))
    assert group.wait_any_exit(0.2) is None
    stop = threading.Event()
    threading.Timer(0.2, stop.set).start()
    assert group.wait_any_exit(None, stop=stop) is None and stop.is_set()
    group.stop(grace=2.0)


def test_an_exit_is_seen_without_asking_the_kernel_at_each_look(on_path: Path) -> None:
    """The session's loop reads every process's ``returncode`` at each clock step: a reaper thread per
    process sets it, so a look is an attribute read. The exit is seen even when a grandchild still
    holds the output pipe open (the output reader alone would never know)."""
    from hri_physio_bridge.waiting import wait_until

    script(on_path, "forking_node", (
        "import subprocess, sys\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
        "print(child.pid, flush=True)\n"
        "print('ready', flush=True)\n"
        "import time; time.sleep(0.3); sys.exit(3)\n"))
    group = ProcessGroup(out=io.StringIO())
    (p,) = started(group, "forking")
    polls: list[int] = []
    real_poll = p.proc.poll
    p.proc.poll = lambda: polls.append(1) or real_poll()  # type: ignore[method-assign]
    assert wait_until(lambda: p.returncode is not None, 10.0, poll=0.01)
    assert p.returncode == 3 and polls == []
    assert p.reader.is_alive()  # the grandchild keeps the pipe open
    os.kill(int(p.lines[0]), signal.SIGKILL)
    p.proc.poll = real_poll  # type: ignore[method-assign]
    assert group.stop(grace=2.0) == {"forking": 3}


def test_missing_console_script_is_named() -> None:
    with pytest.raises(FileNotFoundError, match="console script 'no_such_node' not found"):
        find_executable("no_such_node")


def test_children_are_stopped_when_the_launcher_is_killed(on_path: Path, tmp_path: Path) -> None:
    import signal
    import subprocess
    import time

    pid_file = tmp_path / "child.pid"
    script(on_path, "sleepy_node", (
        "import os, time\n"
        f"open({str(pid_file)!r}, 'w').write(str(os.getpid()))\n"
        "while True: time.sleep(0.05)\n"))
    launcher = subprocess.Popen([sys.executable, "-c", (
        "import os, time\n"
        "from hri_physio_bridge.launcher import ProcessGroup\n"
        "ProcessGroup().start('sleepy', 'sleepy_node', env=dict(os.environ))\n"
        "while True: time.sleep(0.05)\n")], env=dict(os.environ))
    deadline = time.monotonic() + 20
    while not (pid_file.exists() and pid_file.read_text()):
        assert time.monotonic() < deadline and launcher.poll() is None
        time.sleep(0.02)
    child = int(pid_file.read_text())
    launcher.send_signal(signal.SIGKILL)  # no chance to stop anything itself
    launcher.wait(10)
    deadline = time.monotonic() + 10
    while Path(f"/proc/{child}").exists() and "Z" not in Path(f"/proc/{child}/stat").read_text().split()[2]:
        assert time.monotonic() < deadline, "the child outlived its launcher"
        time.sleep(0.02)


def test_a_dead_process_restarts_in_its_place_with_its_argv_environment_and_log(on_path: Path,
                                                                                tmp_path: Path) -> None:
    script(on_path, "echo_node", (
        "import os, sys, time\n"
        "print('args', sys.argv[1:], os.environ['MARK'], flush=True)\n"
        "print('ready', flush=True)\n"
        "while True: time.sleep(0.05)\n"))
    script(on_path, "other_node", "import time\nprint('ready', flush=True)\nwhile True: time.sleep(0.05)\n")
    group = ProcessGroup(out=io.StringIO())
    log = tmp_path / "echo.log"
    first = group.start("echo", "echo_node", ["--conf", "x.yaml"], env={**os.environ, "MARK": "m1"},
                        echo=False, log_path=log)
    other = group.start("other", "other_node", env=dict(os.environ))
    while "ready" not in first.lines:
        assert first.returncode is None
    with pytest.raises(RuntimeError, match="echo is still running"):
        group.restart(first, "restarting")
    first.proc.send_signal(signal.SIGKILL)
    first.proc.wait(10)
    second = group.restart(first, "--- restarted after exit status -9 ---")
    assert group.procs == [second, other] and second.proc.pid != first.proc.pid
    while "ready" not in second.lines:
        assert second.returncode is None
    group.stop(grace=2.0)
    assert second.argv == first.argv and second.lines[0] == "args ['--conf', 'x.yaml'] m1"
    assert log.read_text().splitlines()[:5] == ["args ['--conf', 'x.yaml'] m1", "ready",
                                            "--- restarted after exit status -9 ---",
                                            "args ['--conf', 'x.yaml'] m1", "ready"]

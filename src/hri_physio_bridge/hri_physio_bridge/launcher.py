"""A small process launcher: start node console scripts, prefix their output, stop them cleanly.

There is no ``ros2 launch`` in the pip-wheel ROS 2 used here, so systems are
started by this launcher (on a full ROS 2 install the same nodes also run with
``ros2 run``). Stopping sends SIGINT, then SIGTERM, then SIGABRT, then SIGKILL, each after a
grace period, so nodes can flush their logs and bags; the grace after SIGINT lasts as long as the
node keeps working (:mod:`hri_physio_bridge.exit_progress`), so a drain on a busy machine is not cut
short. A node that hangs on its way out prints every
thread's stack on SIGABRT (``run_node`` enables :mod:`faulthandler`) before it dies, so its log
shows where it was stuck. A node's outcome is the exit status it gave its work before the
middleware's teardown (:attr:`ManagedProcess.returncode`); a teardown that hung or crashed after
it is said apart (:meth:`ProcessGroup.teardown_faults`). Each process's whole output can go
to a log file of its own (``log_path``), whatever is echoed to the console. A process that died
can be started again in its place (:meth:`ProcessGroup.restart`), appending to its log.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from hri_physio_bridge.exit_progress import ExitProgress, read_activity, said_status
from hri_physio_bridge.waiting import wait_until

#: The most time a stopping process that keeps working gets after SIGINT.
STOP_LIMIT = 120.0
#: How often a stopping process is looked at.
STOP_POLL = 0.1
#: How often a stopping process's output is looked at for its done line.
SAID_POLL = 0.02
#: Wall seconds a process that said its work is over gets to shut ROS 2 down and exit before it is
#: escalated (it bounds that teardown itself, at ``ros_tools.TEARDOWN_TIMEOUT``, 5 s).
TEARDOWN_GRACE = 15.0


def find_executable(name: str) -> str:
    """Path of a console script: next to this interpreter first, then on PATH."""
    local = Path(sys.prefix) / "bin" / name
    if local.exists():
        return str(local)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(
            f"console script {name!r} not found (is the project installed? run scripts/setup)"
        )
    return found


def _die_with_parent() -> None:
    """In the child, before exec: be sent SIGTERM if the launcher dies (Linux), even by SIGKILL.

    Children run in their own session (so one Ctrl-C is not delivered twice), which also means
    nothing else would stop them if the launcher were killed.
    """
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


PR_SET_PDEATHSIG = 1


@dataclass
class ManagedProcess:
    name: str
    argv: list[str]
    proc: subprocess.Popen
    reader: threading.Thread
    lines: list[str] = field(default_factory=list)
    log_path: Path | None = None
    env: dict[str, str] | None = None  # as given to start(): a restart gets the same
    echo: bool = True
    #: The exit status the node gave its work (:func:`~hri_physio_bridge.exit_progress.done_line`).
    said: int | None = None

    @property
    def returncode(self) -> int | None:
        """The node's outcome once its process has ended: the status it said its work ended with, if it
        said one (a teardown of the middleware that hung or crashed after it does not change that), else
        the process's own exit status.

        Read at every step of a session's clock, for every process: the status comes from the
        process's reaper thread (see :meth:`ProcessGroup._launch`), not from a ``waitpid`` per look."""
        code = self.proc.returncode
        if code is None:
            return None
        if self.reader.is_alive():
            self.reader.join(1.0)  # the process's last lines, the done line among them
        return code if self.said is None else self.said

    @property
    def teardown_fault(self) -> str | None:
        """What went wrong after the node's work was over, if anything: the process ended with another
        status than the one its work ended with."""
        code = self.proc.poll()
        if code is None or self.said is None or code == self.said:
            return None
        how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
        return (f"{self.name} finished its work (exit status {self.said}), then its process {how} while "
                f"shutting down ROS 2 (the middleware's teardown hung or failed; its log has the stack)")

    def error_line(self) -> str:
        """What the process said when it failed: its ``<prog>: error: ...`` line (else its last
        error-level log line, else its last line, its done line aside)."""
        lines = [line.strip() for line in self.lines if line.strip() and said_status(line) is None]
        for marker in (": error:", "[ERROR]"):
            found = [line for line in lines if marker in line]
            if found:
                return found[-1]
        return lines[-1] if lines else f"no output (exit status {self.returncode})"


class ProcessGroup:
    """Processes started together and stopped together, in reverse order."""

    def __init__(self, out: TextIO = sys.stdout, on_line: Callable[[str, str], None] | None = None,
                 keep_lines: int = 200) -> None:
        self.out = out
        self.on_line = on_line
        self.keep_lines = keep_lines
        self.procs: list[ManagedProcess] = []
        self.stop_seconds: dict[str, float] = {}
        self._lock = threading.Lock()

    def start(self, name: str, script: str, args: Sequence[str] = (), env: dict[str, str] | None = None,
              echo: bool = True, log_path: Path | None = None) -> ManagedProcess:
        """Start ``script`` as ``name``; its output (stdout and stderr) is kept, echoed if ``echo``,
        passed to ``on_line`` and written whole to ``log_path`` (created or truncated) if given."""
        argv = [find_executable(script), *args]
        env = dict(os.environ) if env is None else env  # kept as it is now: a restart gets the same
        managed = self._launch(name, argv, env, echo, log_path, "w", None)
        self.procs.append(managed)
        return managed

    def restart(self, old: ManagedProcess, note: str) -> ManagedProcess:
        """Start ``old``'s command again (same argv, environment, echo), in its place in the group; its
        log file is appended to, after the line ``note``. ``old`` must have exited."""
        if old.returncode is None:
            raise RuntimeError(f"{old.name} is still running: it cannot be restarted")
        old.reader.join(2.0)  # its last lines reach the log before the note
        managed = self._launch(old.name, old.argv, old.env, old.echo, old.log_path, "a", note)
        self.procs[self.procs.index(old)] = managed
        return managed

    def _launch(self, name: str, argv: list[str], env: dict[str, str] | None, echo: bool,
                log_path: Path | None, mode: str, note: str | None) -> ManagedProcess:
        log = open(log_path, mode, encoding="utf-8") if log_path is not None else None  # noqa: SIM115
        try:
            if log is not None and note is not None:
                log.write(note + "\n")
                log.flush()
            proc = self._popen(argv, env)
        except BaseException:
            if log is not None:
                log.close()
            raise
        managed = ManagedProcess(name, argv, proc, threading.Thread(), log_path=log_path, env=env, echo=echo)
        managed.reader = threading.Thread(target=self._pump, args=(managed, echo, log), daemon=True)
        managed.reader.start()
        # Reaps the process the moment it ends (``proc.returncode`` is then set): the launcher's loop
        # reads that attribute, ten times a second per process, instead of asking the kernel each time.
        threading.Thread(target=proc.wait, name=f"{name}-reaper", daemon=True).start()
        return managed

    @staticmethod
    def _popen(argv: list[str], env: dict[str, str] | None) -> subprocess.Popen:
        return subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=env if env is not None else dict(os.environ), text=True, errors="replace", bufsize=1,
            start_new_session=True,  # our Ctrl-C is forwarded by stop(), not delivered twice
            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
        )

    def _pump(self, managed: ManagedProcess, echo: bool, log: TextIO | None) -> None:
        assert managed.proc.stdout is not None
        try:
            for raw in managed.proc.stdout:
                line = raw.rstrip("\n")
                if log is not None:
                    log.write(raw if raw.endswith("\n") else raw + "\n")
                    log.flush()  # a crash of the launcher still leaves the log on disk
                managed.lines.append(line)
                said = said_status(line)
                if said is not None:
                    managed.said = said
                del managed.lines[: -self.keep_lines]
                if self.on_line is not None:
                    self.on_line(managed.name, line)
                if echo:
                    with self._lock:
                        print(f"[{managed.name}] {line}", file=self.out, flush=True)
        finally:
            if log is not None:
                log.close()

    def wait_any_exit(self, timeout: float | None = None,
                      stop: threading.Event | None = None) -> ManagedProcess | None:
        """The first process found to have exited, or None after ``timeout`` (or a stop)."""
        exited: list[ManagedProcess] = []

        def any_exited() -> bool:
            exited[:] = [p for p in self.procs if p.returncode is not None]
            return bool(exited)

        return exited[0] if wait_until(any_exited, timeout, stop=stop) else None

    def stop(self, grace: float = 10.0, limit: float = STOP_LIMIT) -> dict[str, int]:
        """Stop every process (reverse start order); returns exit codes by name.

        After SIGINT a process gets ``grace`` s, and more for as long as it keeps working (up to
        ``limit`` s): a node draining its input on a busy machine is not cut short, a stuck one is
        escalated. The next process is signalled once this one's work is over: it has exited, or has
        said so (its done line) and is shutting ROS 2 down. That teardown, most of a node's stop
        (0.3-0.6 s against 0.01-0.1 s for the work), then overlaps the next stops, and each node still
        outlives every node started after it. Every process has ended when this returns.
        :attr:`stop_seconds` says how long each took to end its work.
        """
        for p in reversed(self.procs):
            t0 = time.monotonic()
            self._stop_one(p, grace, limit)
            self.stop_seconds[p.name] = round(time.monotonic() - t0, 3)
        for p in reversed(self.procs):
            if not _wait_for(p, lambda p=p: p.proc.poll() is not None, TEARDOWN_GRACE):
                _escalate(p, grace, lambda p=p: p.proc.poll() is not None)
        for p in self.procs:
            p.reader.join(2.0)
        return {p.name: p.returncode for p in self.procs}  # every process has ended: no None

    def teardown_faults(self) -> list[str]:
        """Each ended process's :attr:`ManagedProcess.teardown_fault`, in start order."""
        return [fault for p in self.procs if (fault := p.teardown_fault) is not None]

    @staticmethod
    def _stop_one(p: ManagedProcess, grace: float, limit: float) -> None:
        """SIGINT, then wait until ``p``'s work is over (escalating if it is stuck before that)."""
        def over() -> bool:
            return p.proc.poll() is not None or p.said is not None

        if not over():
            p.proc.send_signal(signal.SIGINT)
            progress = ExitProgress(time.monotonic(), grace, limit)
            while not over() and progress.more_time(time.monotonic(), read_activity(p.proc.pid)):
                _wait_for(p, over, STOP_POLL)
        _escalate(p, grace, over)


def _wait_for(p: ManagedProcess, done: Callable[[], bool], timeout: float) -> bool:
    """Until ``done()`` (looked at every SAID_POLL s, or at once when ``p`` exits), at most ``timeout``."""
    def sleep(seconds: float) -> bool:  # a wait that ends when the process does
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.proc.wait(seconds)
        return False

    return wait_until(done, timeout, poll=SAID_POLL, sleep=sleep)


def _escalate(p: ManagedProcess, grace: float, done: Callable[[], bool]) -> None:
    """SIGTERM, SIGABRT (a stack dump in its log), SIGKILL, each with its wait, until ``done()``."""
    for sig, wait in ((signal.SIGTERM, grace / 2), (signal.SIGABRT, 2.0), (signal.SIGKILL, 5.0)):
        if done():
            return
        p.proc.send_signal(sig)
        _wait_for(p, done, wait)
    p.proc.wait()

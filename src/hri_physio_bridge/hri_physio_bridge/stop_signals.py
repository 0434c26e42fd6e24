"""SIGINT/SIGTERM as one stop event, for node processes and launchers alike (no rclpy here).

Nothing is done in the Python-level signal handler itself. Python runs a handler on the main
thread between two bytecodes, which may be inside ``threading.Event.wait()`` while that thread
holds the event's internal lock; a handler that then sets the same event (or takes any lock the
main thread may hold) waits for itself forever. That was the shutdown hang of the nodes: the
main thread waiting on the stop event, SIGINT arriving while it re-acquired the event's lock,
the handler's ``stop.set()`` blocking on that lock (stack dumps showed ``handler -> Event.set``
under ``Event.wait``). So the C-level handler's wakeup byte (``signal.set_wakeup_fd``) is read by
a watcher thread, which sets the event and calls ``on_stop`` like any other thread would.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import threading
from collections.abc import Callable
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: The write end of the pipe installed last and its watcher (a second installation replaces the first).
_installed: list[tuple[int, threading.Thread]] = []


def _do_nothing(_signum: int, _frame: Any) -> None:
    """The Python-level handler: only there so that the signal does not kill the process."""


def install_stop_handlers(on_stop: Callable[[str], None] | None = None) -> threading.Event:
    """SIGINT/SIGTERM call ``on_stop`` once and then set the returned event, on a watcher thread.

    Call it from the main thread (as ``signal.signal`` requires). A signal that comes while the
    main thread holds a lock, even the returned event's own, is handled once the lock is free.
    """
    stop = threading.Event()
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    wanted = {int(s) for s in STOP_SIGNALS}

    def watch() -> None:
        try:
            while True:
                try:
                    received = os.read(read_fd, 64)
                except OSError:
                    return
                if not received:  # the write end closed: replaced or released
                    return
                for signum in received:
                    if signum in wanted and not stop.is_set():
                        # on_stop first: what it records is there for whoever sees the event set.
                        if on_stop is not None:
                            on_stop(signal.Signals(signum).name)
                        stop.set()
        finally:
            os.close(read_fd)

    watcher = threading.Thread(target=watch, name="stop-signals", daemon=True)
    watcher.start()
    previous = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    earlier = next((entry for entry in _installed if entry[0] == previous), None)
    if earlier is not None:  # an earlier call's: its watcher sees the pipe close and ends
        _installed.remove(earlier)
        with contextlib.suppress(OSError):
            os.close(earlier[0])
    _installed.append((write_fd, watcher))
    for s in STOP_SIGNALS:
        signal.signal(s, _do_nothing)
    atexit.register(_ignore_stop_signals)
    return stop


def release_stop_handlers(timeout: float = 1.0) -> None:
    """For a process whose stop is done: the watcher ends and lets go of its ``on_stop`` (a node's
    method holds the whole node, which would otherwise live until the interpreter's exit). Later
    SIGINT/SIGTERM do nothing. Call it from the main thread."""
    if not _installed:
        return
    write_fd, watcher = _installed.pop()
    current = signal.set_wakeup_fd(-1)
    if current not in (write_fd, -1):  # set by someone else since: theirs stays
        signal.set_wakeup_fd(current)
    with contextlib.suppress(OSError):
        os.close(write_fd)  # the watcher reads the end of the pipe and returns
    watcher.join(timeout)


def _ignore_stop_signals() -> None:
    """At exit: a late SIGINT/SIGTERM (a launcher's second one) must not turn a clean exit into -15.

    Python restores the default handlers as it finalizes; an ignored signal stays ignored. A
    process that hangs later on is still ended by the launcher's SIGABRT and SIGKILL.
    """
    for s in STOP_SIGNALS:
        with contextlib.suppress(ValueError):  # not the main thread
            signal.signal(s, signal.SIG_IGN)

"""SIGINT/SIGTERM become one stop event, even when the signal comes while the main thread holds a lock.

Each case runs in a fresh Python process (signal handlers belong to the main thread of a process).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest


def run(body: str) -> subprocess.CompletedProcess:
    script = textwrap.dedent("""
        import os, signal, threading, time
        from hri_physio_bridge.stop_signals import install_stop_handlers
        names = []
        stop = install_stop_handlers(names.append)
    """) + textwrap.dedent(body)
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=20)


def test_a_signal_while_the_main_thread_holds_the_stop_events_own_lock_stops_it() -> None:
    # What hung nodes at shutdown: SIGINT arriving while the main thread, inside stop.wait(),
    # held the event's lock; a handler setting the event waited for the main thread forever.
    done = run("""
        with stop._cond:  # as Event.wait() holds it while it re-acquires after a timeout
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.3)  # the signal is delivered now, on this thread, with the lock held
            assert not stop.is_set()
        assert stop.wait(5), "never stopped"
        print("stopped by", names)
    """)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "stopped by ['SIGINT']"


@pytest.mark.parametrize("first,second", [("SIGTERM", "SIGINT"), ("SIGINT", "SIGINT")])
def test_on_stop_is_called_once_and_before_the_event_is_set(first: str, second: str) -> None:
    done = run(f"""
        seen = []
        stop2 = install_stop_handlers(lambda name: seen.append((name, stop2.is_set())))
        os.kill(os.getpid(), signal.{first})
        assert stop2.wait(5)
        os.kill(os.getpid(), signal.{second})
        time.sleep(0.3)
        print(seen)
    """)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"[('{first}', False)]"


def test_a_stop_wait_in_a_loop_is_ended_by_sigterm_from_another_process() -> None:
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import sys
        from hri_physio_bridge.stop_signals import install_stop_handlers
        stop = install_stop_handlers()
        print("ready", flush=True)
        while not stop.wait(0.001):
            pass
        print("stopped", flush=True)
    """)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        for _ in range(50):  # many signals into many short waits: none is lost, none hangs
            proc.send_signal(15)
        assert proc.wait(10) == 0
        assert proc.stdout.read().strip() == "stopped"
    finally:
        if proc.poll() is None:
            proc.kill()


def test_release_ends_the_watcher_lets_go_of_on_stop_and_later_signals_do_nothing() -> None:
    done = run("""
        import gc, weakref
        from hri_physio_bridge.stop_signals import release_stop_handlers

        class Holder:  # as a node: on_stop is its method
            def on_stop(self, name):
                names.append(name)

        holder = Holder()
        stop2 = install_stop_handlers(holder.on_stop)
        deadline = time.monotonic() + 10
        while len(watchers := [t for t in threading.enumerate() if t.name == "stop-signals"]) > 1:
            assert time.monotonic() < deadline  # the first installation's watcher ends once replaced
            time.sleep(0.01)
        held = weakref.ref(holder)
        del holder
        gc.collect()
        assert held() is not None  # the watcher holds it
        release_stop_handlers()
        assert not watchers[0].is_alive()
        gc.collect()
        assert held() is None
        assert signal.set_wakeup_fd(-1) == -1
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.3)
        print("alive", names, stop2.is_set())
    """)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "alive [] False"

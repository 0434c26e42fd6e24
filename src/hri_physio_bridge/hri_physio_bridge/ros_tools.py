"""Small rclpy helpers for launchers and tools that watch or drive a running system."""

from __future__ import annotations

import contextlib
import faulthandler
import gc
import io
import logging
import sys
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator
from typing import Any


def clock_message(t: float) -> Any:
    """A rosgraph_msgs/Clock for ``t`` seconds (nanoseconds rounded, never 1e9)."""
    from rosgraph_msgs.msg import Clock

    msg = Clock()
    msg.clock.sec = int(t)
    msg.clock.nanosec = min(round((t - int(t)) * 1e9), 999_999_999)
    return msg


def wait_all_acked(publishers: Iterable[Any], timeout: float,
                   clock: Callable[[], float] = time.monotonic) -> bool:
    """Wait until every publisher's reliable subscribers have acknowledged what it sent, within one
    ``timeout`` shared by all: a node closing twenty outputs waits ``timeout`` at most, not twenty
    times it (on a busy machine the sum outlasted the launcher's patience). True if all were acked."""
    from rclpy.duration import Duration

    deadline = clock() + timeout
    acked = True
    for pub in publishers:
        left = max(0.0, deadline - clock())
        acked = bool(pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))) and acked
    return acked


class ExecutorThread:
    """A single-threaded executor spinning ``nodes`` on a daemon thread until :meth:`close`.

    ``context`` is the rclpy context of the nodes (None: the default one). The thread waits until a
    message, a timer or :meth:`close` comes: an idle node costs nothing (it used to wake 20 times a
    second to look at a flag, rebuilding its wait set each time). The executor is
    :class:`hri_physio_bridge.executor.LeanExecutor`, which keeps its wait set between wake-ups.

    A callback that raises ends the spin (as in rclpy): its traceback goes to stderr, the exception
    is kept in :attr:`error` and ``on_error(exception)`` is called, so the owner can stop instead of
    living on with a node that no longer takes messages.
    """

    def __init__(self, *nodes: Any, context: Any = None,
                 on_error: Callable[[BaseException], None] | None = None) -> None:
        from rclpy.task import Future

        from hri_physio_bridge.executor import LeanExecutor

        self.executor = LeanExecutor(context=context)
        for node in nodes:
            self.executor.add_node(node)
        self.error: BaseException | None = None
        self._on_error = on_error
        self._closed: Any = Future()  # done at close(): ends the spin, waking its wait
        self._thread = threading.Thread(target=self._spin, name="executor", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            self.executor.spin_until_future_complete(self._closed)
        except ExternalShutdownException:
            pass  # the context was shut down: the process is ending anyway
        except Exception as exc:
            self.error = exc
            traceback.print_exc(file=sys.stderr)
            if self._on_error is not None:
                try:
                    self._on_error(exc)
                except Exception:
                    traceback.print_exc(file=sys.stderr)

    def close(self, join_timeout: float = 10.0) -> None:
        """Stop spinning and shut the executor down (the nodes stay for their owner to destroy).

        The owner destroys the nodes next, which is unsafe while this thread still waits on them, so
        the join is generous for a loaded machine; idle, it takes milliseconds."""
        if not self._closed.done():
            self._closed.set_result(None)
        if self._thread.is_alive():
            self._thread.join(join_timeout)
        self.executor.shutdown(timeout_sec=1.0)


class TakenOnDemand:
    """Subscriptions that no executor waits on: the middleware keeps each one's newest messages (its
    QoS depth) and :meth:`take` hands them over when asked.

    For a stream watched only now and then (a receiver's output around its restart): in an executor,
    each of its messages would wake the spinning thread (ten a second for ECG frames) for nothing.
    The subscriptions live on a node of their own (``name``, in ``context``: None is rclpy's default
    one), which no executor spins; :meth:`destroy` destroys it.
    """

    def __init__(self, name: str, context: Any = None) -> None:
        import rclpy

        self.node = rclpy.create_node(name, context=context, start_parameter_services=False,
                                      enable_rosout=False)
        self._subs: dict[str, Any] = {}

    def subscribe(self, key: str, msg_type: Any, topic: str, qos: Any) -> None:
        self._subs[key] = self.node.create_subscription(msg_type, topic, _never_called, qos)

    def take(self, key: str) -> list[Any]:
        """The messages of ``key``'s subscription received since the last take, oldest first."""
        sub = self._subs[key]
        taken: list[Any] = []
        with sub.handle:
            while (message := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                taken.append(message[0])
        return taken

    def destroy(self) -> None:
        self._subs.clear()
        self.node.destroy_node()


class MessageArrivals:
    """Waits until one of some subscriptions that no executor spins holds a message.

    For a loop that takes its messages itself (the recorder): between passes it sleeps in the
    middleware's wait rather than trying every queue, so a quiet topic costs nothing (an empty take
    costs 3 us; 52 topics tried 50 times a second were a fifth of the recorder's CPU in a session).
    :meth:`wake`, from any thread, ends a wait early.
    """

    def __init__(self, node: Any) -> None:
        self._context = node.context
        self._guard = node.create_guard_condition(_never_called)
        self._wait_set: Any = None
        self._size = -1

    def wake(self) -> None:
        self._guard.trigger()

    def wait(self, subs: dict[str, Any], timeout: float) -> list[str]:
        """The topics of ``subs`` (topic: subscription) that hold a message, once one does, or after
        ``timeout`` seconds, or when woken (then possibly none)."""
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        if self._wait_set is None or self._size != len(subs):
            with self._context.handle:
                self._wait_set = _rclpy.WaitSet(len(subs), 1, 0, 0, 0, 0, self._context.handle)
            self._size = len(subs)
        ws = self._wait_set
        topic_of: dict[int, str] = {}
        entered: list[Any] = []
        try:
            self._context.handle.__enter__()
            entered.append(self._context.handle)
            ws.clear_entities()
            for topic, sub in subs.items():
                sub.handle.__enter__()
                entered.append(sub.handle)
                ws.add_subscription(sub.handle)
                topic_of[sub.handle.pointer] = topic
            self._guard.handle.__enter__()
            entered.append(self._guard.handle)
            ws.add_guard_condition(self._guard.handle)
            ws.wait(max(0, int(timeout * 1e9)))
            return [topic_of[p] for p in ws.get_ready_entities("subscription") if p in topic_of]
        finally:
            for handle in reversed(entered):
                handle.__exit__(None, None, None)


def _never_called(_message: Any) -> None:
    """The callback of a :class:`TakenOnDemand` subscription, which no executor runs."""


#: The most time the middleware's teardown (rcl shutdown, the DDS participant) may take at exit.
TEARDOWN_TIMEOUT = 5.0


def shut_down_ros(*nodes: Any, timeout: float | None = None) -> None:
    """Destroy ``nodes``, shut rclpy down and destroy its context (the DDS participant), within
    ``timeout`` (``TEARDOWN_TIMEOUT``): past it, the process prints every thread's stack and exits
    with status 1. (:func:`shut_down_node_process` when the caller can let go of its nodes.)

    Left to the interpreter's exit, the participant is deleted by C++ destructors after Python's
    own shutdown, where a hang shows no Python stack and outlasts the launcher's grace. The teardown
    itself can hang in Fast DDS (deleting a writer, seen on loaded machines), inside a call that
    holds the GIL: no Python thread runs then, so the bound is faulthandler's own C thread. A node
    whose work went well has printed :func:`~hri_physio_bridge.exit_progress.done_line` before
    this, so the launcher still knows that it did; a launcher calls this once its summary is written.
    """
    shut_down_node_process(list(nodes), timeout=timeout)


def shut_down_node_process(nodes: list[Any], timeout: float | None = None) -> None:
    """:func:`shut_down_ros` for nodes the caller lets go of: ``nodes`` is emptied, and once they are
    destroyed what they left in reference cycles (callbacks that hold their node, wrappers of rcl
    handles) is freed, while the middleware is still whole, before rclpy shuts down.

    Left to the interpreter's exit, those cycles are collected after the context is gone and the
    other threads are frozen, with no Python stack and no bound: a processor that had said it was done
    once stood 15 s "Garbage-collecting" there until the test's SIGABRT.
    """
    import rclpy

    _flush_outputs()
    with _bounded_teardown(timeout):
        while nodes:
            node = nodes.pop()
            if node is not None:
                node.destroy_node()
            del node
        gc.collect()
        rclpy.try_shutdown()
        rclpy.get_default_context().destroy()
    # Whatever is left goes with the process. The interpreter's last collection would run after the
    # context is gone, with no bound (seen again: a processor done and shut down stood 15 s
    # "Garbage-collecting" at exit): nothing that exists now is collected again.
    gc.freeze()


@contextlib.contextmanager
def _bounded_teardown(timeout: float | None) -> Iterator[None]:
    """Past ``timeout`` (``TEARDOWN_TIMEOUT``) inside the block, every thread's stack and exit status 1,
    from faulthandler's own C thread (the block may hold the GIL)."""
    limit = TEARDOWN_TIMEOUT if timeout is None else timeout
    try:
        faulthandler.dump_traceback_later(limit, exit=True, file=sys.stderr)
    except (AttributeError, ValueError, io.UnsupportedOperation):  # stderr is no real file (pytest)
        faulthandler.dump_traceback_later(limit, exit=True, file=sys.__stderr__)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


def _flush_outputs() -> None:
    """Flush what Python buffers (logs, stdout, stderr), so that a teardown cut off by faulthandler's
    ``_exit`` does not lose it."""
    for handler in logging.getLogger().handlers:
        with contextlib.suppress(Exception):
            handler.flush()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()


class BackgroundNode:
    """An rclpy node spun on its own thread, in a process that handles its own signals.

    rclpy is initialised without its signal handlers, so the owner's SIGINT/SIGTERM handlers
    decide how to stop. Create subscriptions on ``self.node`` before or after ``start()``.
    """

    def __init__(self, name_prefix: str) -> None:
        import rclpy

        rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"{name_prefix}_{uuid.uuid4().hex[:4]}")
        self._spinner: ExecutorThread | None = None
        self._on_demand: list[TakenOnDemand] = []

    def taken_on_demand(self, suffix: str) -> TakenOnDemand:
        """Subscriptions beside this node's that no thread spins (destroyed by :meth:`close`)."""
        reader = TakenOnDemand(f"{self.node.get_name()}_{suffix}")
        self._on_demand.append(reader)
        return reader

    def start(self) -> None:
        self._spinner = ExecutorThread(self.node)

    def stop_spinning(self) -> None:
        """No callback runs after this (the node stays, for :meth:`close`)."""
        if self._spinner is not None:
            self._spinner.close()
            self._spinner = None

    def close(self) -> None:
        """Stop spinning, then destroy the node and rclpy's context within ``TEARDOWN_TIMEOUT`` (see
        :func:`shut_down_ros`: a teardown stuck in the middleware ends the process with status 1)."""
        self.stop_spinning()
        shut_down_ros(*(reader.node for reader in self._on_demand), self.node)

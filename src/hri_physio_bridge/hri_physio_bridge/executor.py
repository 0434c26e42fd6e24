"""A single-threaded rclpy executor whose wake-up costs what the work needs (runtime shell).

rclpy's ``SingleThreadedExecutor`` rebuilds its whole wait set on every wake-up: it walks every
entity of every node (a node has seven parameter and type services, and two QoS event handlers per
publisher and subscription: some sixty entities), enters each handle through an ``ExitStack``,
constructs a new ``WaitSet``, and after each callback triggers its own guard condition, so every
message costs a second, empty round of the same. A node on sim time wakes at least 20 times a second
at 1x (each ``/clock`` step, and the timers it moves), and that bookkeeping, not the node's work,
was most of the CPU of every node that only waits (0.7 ms a message, 1.5-2 % of a core).

:class:`LeanExecutor` keeps what it waits on between wake-ups (rebuilt only when an entity or a
node is added or removed: rclpy calls :meth:`wake` then), reuses one ``WaitSet``, and calls each
ready callback directly. What it does per wake-up is what the base executor does, in the same order:
tasks first (coroutines, future callbacks), then of each node its ready waitables (QoS events),
timers, subscriptions (one message each), guard conditions, client responses and service requests.
Coroutine callbacks become tasks, as rclpy's ``await_or_execute`` would await them. Only one thread
may spin it; callback groups do not matter with one thread.
"""

from __future__ import annotations

import inspect
import time
from typing import Any

from rclpy.event_handler import EventHandler
from rclpy.exceptions import InvalidHandle, TimerCancelledError
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription
from rclpy.timer import TimerInfo

#: Seconds between waits that include the QoS event handlers (see LeanExecutor).
EVENT_PERIOD = 1.0


def _is_coroutine(callback: Any) -> bool:
    return inspect.iscoroutinefunction(callback) or (
        not inspect.isroutine(callback) and inspect.iscoroutinefunction(type(callback).__call__))


def _take(entity: Any, take: Any) -> Any:
    """``take(handle)`` on the entity's handle held; None once the entity is destroyed."""
    try:
        with entity.handle:
            return take(entity.handle)
    except InvalidHandle:
        return None


class _Entities:
    """What one wait waits on: every node's entities, their handles, and the wait set sized for them."""

    def __init__(self, executor: LeanExecutor) -> None:
        self.nodes = executor.get_nodes()
        self.subs: list[Any] = []
        self.timers: list[Any] = []
        self.clients: list[Any] = []
        self.services: list[Any] = []
        self.guards: list[Any] = []
        self.waitables: list[Any] = []
        # Per node, in the base executor's order of service.
        self.by_node: list[tuple[list[Any], list[Any], list[Any], list[Any], list[Any], list[Any]]] = []
        for node in self.nodes:
            entry = (list(node.waitables), list(node.timers), list(node.subscriptions), list(node.guards),
                     list(node.clients), list(node.services))
            self.by_node.append(entry)
            self.waitables += entry[0]
            self.timers += entry[1]
            self.subs += entry[2]
            self.guards += entry[3]
            self.clients += entry[4]
            self.services += entry[5]
        own = [gc for gc in (executor._guard, executor._sigint_gc) if gc is not None]
        events = 0
        for waitable in self.waitables:
            events += waitable.get_num_entities().num_events
        counts = [len(self.subs), len(self.guards) + len(own), len(self.timers), len(self.clients),
                  len(self.services), events]
        for waitable in self.waitables:
            n = waitable.get_num_entities()
            counts[0] += n.num_subscriptions
            counts[1] += n.num_guard_conditions
            counts[2] += n.num_timers
            counts[3] += n.num_clients
            counts[4] += n.num_services
        self.own_guards = own
        #: QoS event handlers, waited on at most once per EVENT_PERIOD; the other waitables every time.
        self.events = [w for w in self.waitables if isinstance(w, EventHandler)]
        self.waitables = [w for w in self.waitables if not isinstance(w, EventHandler)]
        self.context = executor.context
        with self.context.handle:
            self.wait_set = _rclpy.WaitSet(*counts, self.context.handle)


class LeanExecutor(Executor):
    """A single-threaded executor that keeps its wait set between wake-ups (see the module's docstring)."""

    def __init__(self, *, context: Any = None) -> None:
        super().__init__(context=context)
        self._entities: _Entities | None = None
        self._stale = True
        self._events_due = 0.0  # monotonic time from which a wait includes the QoS events
        #: The name of the TimerInfo parameter of each timer callback, or None (looked up once, not per call).
        self._timer_info_arg: dict[Any, str | None] = {}

    # -- what changes the wait set -------------------------------------------------------------

    def wake(self) -> None:
        """rclpy calls this when a node's entities change, a future is done, or the context shuts down."""
        self._stale = True
        super().wake()

    def add_node(self, node: Any) -> bool:
        self._stale = True
        return super().add_node(node)

    def remove_node(self, node: Any) -> None:
        self._stale = True
        super().remove_node(node)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        done = super().shutdown(timeout_sec)
        self._entities = None  # the wait set goes with its last reference, as rclpy's own do
        return done

    # -- spinning ------------------------------------------------------------------------------

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self._spin_once_impl(timeout_sec)

    def _spin_once_until_future_complete(self, future: Any, timeout_sec: Any = None) -> None:
        self._spin_once_impl(timeout_sec, future.done)

    def spin_once_until_future_complete(self, future: Any, timeout_sec: Any = None) -> None:
        future.add_done_callback(lambda _f: self.wake())
        self._spin_once_until_future_complete(future, timeout_sec)

    def _spin_once_impl(self, timeout_sec: Any = None, condition: Any = lambda: False) -> None:
        """Run the tasks that can (first, as rclpy does), then wait and run what is ready; again until
        something ran, ``condition`` holds, the timeout is over or the executor is shut down."""
        timeout = getattr(timeout_sec, "timeout", timeout_sec)
        deadline = None if timeout is None or timeout < 0 else time.monotonic() + timeout
        while not self._is_shutdown:
            ran = self._run_tasks()
            if condition():
                return
            nsec = -1 if deadline is None else max(0, int((deadline - time.monotonic()) * 1e9))
            ready = self._wait(nsec)
            if ready is None:
                return
            with self._work_tracker:
                ran = self._dispatch(*ready) or ran
            if ran or (deadline is not None and time.monotonic() >= deadline):
                return

    def _run_tasks(self) -> bool:
        """Run each task not done (oldest first) until it ends or awaits something; True if one ran."""
        with self._tasks_lock:
            if not self._tasks:
                return False
            tasks = list(self._tasks)
        ran = False
        for task, _entity, _node in tasks:
            if not task.executing() and not task.done():
                ran = True
                with self._work_tracker:
                    task()
                exception = task.exception()
                if exception is not None:
                    raise exception
        with self._tasks_lock:
            self._tasks = [t for t in self._tasks if not t[0].done()]
        return ran

    def _wait(self, nsec: int) -> tuple[_Entities, set, set, set, set, set, list] | None:
        """Wait up to ``nsec`` (-1: until something comes); the entities ready, their data taken."""
        if self._stale or self._entities is None:
            self._stale = False
            self._entities = _Entities(self)
        e = self._entities
        ws = e.wait_set
        # QoS events (rclpy's default incompatible-QoS and -type warnings) are waited on once a second
        # at most: a wait without them lasts no longer than until they are due again.
        now = time.monotonic()
        with_events = now >= self._events_due
        if with_events:
            self._events_due = now + EVENT_PERIOD
        elif e.events:
            due = int((self._events_due - now) * 1e9) + 1
            nsec = due if nsec < 0 else min(nsec, due)
        entered: list[Any] = []
        try:
            e.context.handle.__enter__()
            entered.append(e.context.handle)
            ws.clear_entities()
            for kind, add in ((e.subs, ws.add_subscription), (e.timers, ws.add_timer),
                              (e.clients, ws.add_client), (e.services, ws.add_service),
                              (e.guards, ws.add_guard_condition)):
                for entity in kind:
                    handle = entity.handle
                    try:
                        handle.__enter__()
                    except InvalidHandle:  # destroyed: rclpy will wake us to rebuild
                        self._stale = True
                        continue
                    entered.append(handle)
                    add(handle)
            for gc in e.own_guards:
                gc.handle.__enter__()
                entered.append(gc.handle)
                ws.add_guard_condition(gc.handle)
            waitables = []
            for waitable in (e.waitables + e.events) if with_events else e.waitables:
                try:
                    waitable.__enter__()
                except InvalidHandle:
                    self._stale = True
                    continue
                entered.append(waitable)
                waitable.add_to_wait_set(ws)
                waitables.append(waitable)
            ws.wait(nsec)
            if self._is_shutdown:
                return None
            if not self._context.ok():
                raise ExternalShutdownException()
            ready_waitables = [w for w in waitables if w.is_ready(ws)]
            data = [(w, w.take_data()) for w in ready_waitables]
            return (e, set(ws.get_ready_entities("subscription")), set(ws.get_ready_entities("timer")),
                    set(ws.get_ready_entities("guard_condition")), set(ws.get_ready_entities("client")),
                    set(ws.get_ready_entities("service")), data)
        finally:
            for handle in reversed(entered):
                handle.__exit__(None, None, None)

    def _dispatch(self, e: _Entities, subs: set[int], timers: set[int], guards: set[int], clients: set[int],
                  services: set[int], waitable_data: list) -> bool:
        """Run what is ready, node by node in rclpy's order; True if anything was (not only a wake())."""
        ready_waitables = dict(waitable_data)
        ran = False
        for n_waitables, n_timers, n_subs, n_guards, n_clients, n_services in e.by_node:
            for waitable in n_waitables:
                if waitable in ready_waitables:
                    ran = True
                    for future in waitable._futures:
                        future._set_executor(self)
                    task = self.create_task(waitable.execute, ready_waitables[waitable])
                    task()
                    if task.exception() is not None:
                        raise task.exception()
            for entities, ready, run in ((n_timers, timers, self._call_timer),
                                         (n_subs, subs, self._take_message),
                                         (n_guards, guards, self._call_guard),
                                         (n_clients, clients, self._take_response),
                                         (n_services, services, self._take_request)):
                if ready:
                    for entity in entities:
                        if self._pointer(entity) in ready:
                            ran = True
                            run(entity)
        return ran

    @staticmethod
    def _pointer(entity: Any) -> int | None:
        try:
            return entity.handle.pointer
        except InvalidHandle:
            return None

    def _call(self, callback: Any, *args: Any) -> None:
        if _is_coroutine(callback):
            self.create_task(callback, *args)
        else:
            callback(*args)

    def _call_guard(self, gc: Any) -> None:
        if gc.callback:
            self._call(gc.callback)

    def _call_timer(self, tmr: Any) -> None:
        try:
            with tmr.handle:
                if not tmr.handle.is_timer_ready():  # a cancelled timer (rcl's quirk)
                    return
                info = tmr.handle.call_timer_with_info()
        except (InvalidHandle, TimerCancelledError):
            return
        callback = tmr.callback
        if not callback:
            return
        info_arg = self._timer_info_arg
        if callback not in info_arg:
            parameters = inspect.signature(callback).parameters.values()
            info_arg[callback] = next((p.name for p in parameters if p.annotation == TimerInfo), None)
        name = info_arg[callback]
        if name is None:
            self._call(callback)
            return
        timer_info = TimerInfo(expected_call_time=info["expected_call_time"],
                               actual_call_time=info["actual_call_time"], clock_type=tmr.clock.clock_type)
        if _is_coroutine(callback):
            self.create_task(callback, **{name: timer_info})
        else:
            callback(**{name: timer_info})

    def _take_message(self, sub: Any) -> None:
        taken = _take(sub, lambda handle: handle.take_message(sub.msg_type, sub.raw))
        if taken is None:
            return
        if sub._callback_type is Subscription.CallbackType.MessageOnly:
            self._call(sub.callback, taken[0])
        else:
            self._call(sub.callback, *taken)

    def _take_response(self, client: Any) -> None:
        taken = _take(client, lambda handle: handle.take_response(client.srv_type.Response))
        if taken is None or taken[0] is None:
            return
        header, response = taken
        try:
            future = client.get_pending_request(header.request_id.sequence_number)
        except KeyError:  # the request was cancelled
            return
        future._set_executor(self)
        future.set_result(response)

    def _take_request(self, srv: Any) -> None:
        taken = _take(srv, lambda handle: handle.service_take_request(srv.srv_type.Request))
        if taken is None or taken[1] is None:
            return
        request, header = taken
        if _is_coroutine(srv.callback):
            async def serve() -> None:
                srv.send_response(await srv.callback(request, srv.srv_type.Response()), header)
            self.create_task(serve)
        else:
            srv.send_response(srv.callback(request, srv.srv_type.Response()), header)

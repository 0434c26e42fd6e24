"""A generic scenario engine: a routine as an explicit state machine on an injected clock.

The engine owns a queue of timers and fires each at its *scheduled* time, whatever the
granularity of the calls that drive it: ``tick(now)`` runs every timer due up to ``now``
in time order, with :attr:`ScenarioEngine.now` set to the timer's time while it runs. So
the same session runs in real time (a ROS timer calls ``tick()`` every 100 ms), under ROS
sim time, or on a fake clock in one call, and every event carries the same times.

Order of things due at the same instant: periodic hooks first (they belong to the span
that is ending), then delayed actions, then transitions. Hooks of one *group* due at the
same instant do not pile up: only the one with the highest priority runs and the others
are reported as skipped (a rule update wins over a random behaviour in the same tick).

Periodic hooks run while a phase that lists them is active. A hook's schedule is anchored
at the start of a contiguous run of such phases and fires every period strictly before
the run ends, across phase and activity boundaries.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from hri_physio_coach.routine import Action, Activity, Phase, Routine

Event = dict[str, Any]
EventSink = Callable[[Event], None]
Clock = Callable[[], float]

# Order classes of things due at the same instant.
_HOOK, _DELAYED, _TRANSITION = 0, 1, 2
_SAME_TIME = 1e-9

IDLE, RUNNING, FINISHED, STOPPED = "idle", "running", "finished", "stopped"


@dataclass(frozen=True)
class Hook:
    """A periodic callback, active in the phases that list its ``name``."""

    name: str
    period: float
    callback: Callable[[float], None]
    priority: int = 0
    group: str = "periodic"

    def __post_init__(self) -> None:
        if not self.period > 0:
            raise ValueError(f"hook {self.name!r}: period must be > 0 s, got {self.period}")


@dataclass(frozen=True)
class ActionContext:
    """Where an action runs: the engine time, the phase and (if any) the activity."""

    t: float
    phase: Phase | None
    activity: Activity | None


@dataclass(order=True)
class _Timer:
    time: float
    order: int
    rank: int  # -priority for hooks
    seq: int
    callback: Callable[[], None] = field(compare=False)
    name: str = field(compare=False, default="")
    hook: Hook | None = field(compare=False, default=None)
    span_end: float = field(compare=False, default=0.0)  # hooks: the end of their run of phases
    cancelled: bool = field(compare=False, default=False)


#: What :meth:`ScenarioEngine.schedule` returns: keep it to cancel the timer.
Timer = _Timer


class Listener:
    """Override what you need: called as the engine enters phases and activities and ends."""

    def on_phase_start(self, phase: Phase, t: float) -> None: ...

    def on_phase_end(self, phase: Phase, t: float) -> None: ...

    def on_activity_start(self, phase: Phase, activity: Activity, t: float) -> None: ...

    def on_end(self, t: float) -> None: ...


class ScenarioEngine:
    """Runs a :class:`Routine`: phases, activities, delayed actions and periodic hooks."""

    def __init__(self, routine: Routine, clock: Clock, sink: EventSink,
                 on_action: Callable[[Action, ActionContext], None],
                 hooks: Mapping[str, Hook] | None = None, listener: Listener | None = None) -> None:
        self.routine = routine
        self.clock = clock
        self.sink = sink
        self.on_action = on_action
        self.hooks: dict[str, Hook] = dict(hooks or {})
        self.listener = listener or Listener()
        unknown = sorted({h for p in routine.phases for h in p.hooks} - set(self.hooks))
        if unknown:
            raise ValueError(f"routine {routine.name!r} uses hook(s) {unknown} that the scenario does not "
                             f"provide (provided: {sorted(self.hooks)})")
        self.state = IDLE
        self.now = 0.0
        self.start_time: float | None = None
        self.phase_index = -1
        self.activity_index = -1
        self.phase_start = 0.0
        self.activity_start = 0.0
        self._queue: list[_Timer] = []
        self._seq = itertools.count()
        self._activity_timers: list[_Timer] = []
        self._hook_timers: dict[str, _Timer] = {}
        #: Asked before the first thing due at an instant runs: None to go on, or the time up to which
        #: nothing at or after that instant may run yet (a scenario waiting for late input it needs
        #: there). Asked again on every tick until it says None or the time has come.
        self.gate: Callable[[float], float | None] | None = None
        self._gate_open_at = -math.inf  # the instant the gate last let through
        #: The instant the gate holds the engine at since the last tick (None: not held).
        self.held_at: float | None = None

    # --- state -------------------------------------------------------------------------------
    @property
    def phase(self) -> Phase | None:
        return self.routine.phases[self.phase_index] if 0 <= self.phase_index < len(self.routine.phases) \
            else None

    @property
    def activity(self) -> Activity | None:
        phase = self.phase
        if phase is None or not 0 <= self.activity_index < len(phase.activities):
            return None
        return phase.activities[self.activity_index]

    @property
    def phase_end(self) -> float:
        phase = self.phase
        return self.phase_start + (phase.duration if phase else 0.0)

    @property
    def activity_end(self) -> float:
        activity = self.activity
        return self.activity_start + (activity.duration if activity else 0.0)

    @property
    def end_time(self) -> float | None:
        return None if self.start_time is None else self.start_time + self.routine.duration

    @property
    def running(self) -> bool:
        return self.state == RUNNING

    def state_dict(self) -> Event:
        phase, activity = self.phase, self.activity
        return {
            "state": self.state,
            "phase": phase.name if phase else None,
            "phase_kind": phase.kind if phase else None,
            "activity": activity.name if activity else None,
            "phase_ends_at": self.phase_end if phase else None,
            "activity_ends_at": self.activity_end if activity else None,
        }

    # --- events and timers -------------------------------------------------------------------
    def emit(self, event: Event) -> None:
        """Send an event to the sink, stamped with the engine time unless it has a ``t``."""
        self.sink({"t": self.now, **event} if "t" not in event else event)

    def schedule(self, at: float, callback: Callable[[], None], name: str = "",
                 order: int = _DELAYED) -> _Timer:
        timer = _Timer(at, order, 0, next(self._seq), callback, name)
        heapq.heappush(self._queue, timer)
        return timer

    @staticmethod
    def cancel(timer: _Timer) -> None:
        timer.cancelled = True

    # --- running -----------------------------------------------------------------------------
    def start(self, now: float | None = None) -> None:
        if self.state != IDLE:
            raise RuntimeError(f"the scenario has already been started (state {self.state})")
        self.now = self.clock() if now is None else float(now)
        self.start_time = self.now
        self.state = RUNNING
        self.emit({"event": "session_start", "routine": self.routine.name,
                   "duration": self.routine.duration, "ends_at": self.end_time,
                   "phases": [p.name for p in self.routine.phases]})
        self._run_actions(self.routine.on_start, None, None)
        self._enter_phase(0)

    def tick(self, now: float | None = None) -> int:
        """Run everything due up to ``now`` (default: the clock); returns how many timers ran."""
        now = self.clock() if now is None else float(now)
        ran = 0
        self.held_at = None
        while self.state == RUNNING and self._queue and self._queue[0].time <= now + _SAME_TIME:
            if self._queue[0].cancelled:
                heapq.heappop(self._queue)
                continue
            at = self._queue[0].time
            held = self._held_until(at)
            if held is not None:
                if now < held - _SAME_TIME:
                    self.now = max(self.now, at)  # time stands at the held instant
                    self.held_at = at
                    return ran
                self._gate_open_at = at  # waited long enough: that instant runs as it is
            timer = heapq.heappop(self._queue)
            self.now = max(self.now, timer.time)
            if timer.hook is not None:
                ran += self._run_hooks(timer)
            else:
                timer.callback()
                ran += 1
        self.now = max(self.now, now)
        return ran

    def next_hook_due(self, name: str) -> float | None:
        """When hook ``name`` runs next (None: not scheduled in the phase under way)."""
        timer = self._hook_timers.get(name)
        return None if timer is None or timer.cancelled or self.state != RUNNING else timer.time

    def next_due(self) -> float | None:
        """When the next pending timer is due (None: nothing pending), for event-driven drivers."""
        while self._queue and self._queue[0].cancelled:
            heapq.heappop(self._queue)
        if self.state != RUNNING or not self._queue:
            return None
        due = self._queue[0].time
        held = self._held_until(due)
        return due if held is None else max(due, held)

    def _held_until(self, at: float) -> float | None:
        """The gate's answer for the instant ``at`` (None: go on), asked until it lets ``at`` through."""
        if self.gate is None or at <= self._gate_open_at + _SAME_TIME:
            return None
        held = self.gate(at)
        if held is None:
            self._gate_open_at = at
        return held

    def run_to_end(self, step: float = 1.0, before_tick: Callable[[float], None] | None = None) -> None:
        """Drive the whole session on a fake clock in ``step``-second ticks (tests, simulations)."""
        if self.state == IDLE:
            self.start()
        t = self.now
        while self.state == RUNNING:
            t += step
            if before_tick is not None:
                before_tick(t)
            self.tick(t)

    def stop(self, reason: str) -> None:
        """End the session early (SIGINT, operator): pending timers are dropped."""
        if self.state != RUNNING:
            return
        self.state = STOPPED
        self._queue.clear()
        self.emit({"event": "session_stopped", "reason": reason, **self.state_dict()})

    # --- internals ---------------------------------------------------------------------------
    def _ctx(self) -> ActionContext:
        return ActionContext(self.now, self.phase, self.activity)

    def _run_actions(self, actions: tuple[Action, ...], phase: Phase | None, activity: Activity | None,
                     track: bool = False) -> None:
        for action in actions:
            if action.after <= 0:
                self.on_action(action, ActionContext(self.now, phase, activity))
                continue

            def later(a: Action = action) -> None:
                self.on_action(a, ActionContext(self.now, phase, activity))

            timer = self.schedule(self.now + action.after, later, f"{action.kind}:{action.value}")
            if track:
                self._activity_timers.append(timer)

    def _enter_phase(self, index: int) -> None:
        previous = self.phase
        self.phase_index = index
        self.activity_index = -1
        self.phase_start = self.now
        phase = self.routine.phases[index]
        self.emit({"event": "phase", "phase": phase.name, "kind": phase.kind, "index": index,
                   "duration": phase.duration, "ends_at": self.phase_end,
                   "activities": [a.name for a in phase.activities]})
        self._start_hooks(phase, previous)
        self.listener.on_phase_start(phase, self.now)
        self._run_actions(phase.on_enter, phase, None)
        self._enter_activity(0)

    def _enter_activity(self, index: int) -> None:
        phase = self.phase
        assert phase is not None
        self.activity_index = index
        self.activity_start = self.now
        activity = phase.activities[index]
        self.emit({"event": "activity", "phase": phase.name, "activity": activity.name,
                   "label": activity.label, "index": index, "duration": activity.duration,
                   "ends_at": self.activity_end, **{k: v for k, v in activity.attrs.items()
                                                    if isinstance(v, str | int | float | bool)}})
        self.listener.on_activity_start(phase, activity, self.now)
        self._run_actions(activity.on_enter, phase, activity, track=True)
        self._run_actions(phase.activity_actions, phase, activity, track=True)
        self.schedule(self.activity_end, self._advance, "transition", order=_TRANSITION)

    def _advance(self) -> None:
        for timer in self._activity_timers:
            timer.cancelled = True  # an activity's delayed actions die with it
        self._activity_timers.clear()
        phase = self.phase
        assert phase is not None
        if self.activity_index + 1 < len(phase.activities):
            self._enter_activity(self.activity_index + 1)
            return
        self._run_actions(phase.on_exit, phase, None)
        self.listener.on_phase_end(phase, self.now)
        if self.state != RUNNING:
            return
        if self.phase_index + 1 < len(self.routine.phases):
            self._enter_phase(self.phase_index + 1)
            return
        self._finish()

    def _finish(self) -> None:
        for timer in self._hook_timers.values():
            timer.cancelled = True
        self._hook_timers.clear()
        self.phase_index = len(self.routine.phases)
        self._run_actions(tuple(a for a in self.routine.on_end if a.after <= 0), None, None)
        self.state = FINISHED
        self.emit({"event": "session_end", "duration": self.now - (self.start_time or 0.0)})
        self.listener.on_end(self.now)

    def _span_end(self, hook_name: str, from_index: int) -> float:
        """End of the contiguous run of phases, from ``from_index``, in which the hook is active."""
        end = self.now
        for phase in self.routine.phases[from_index:]:
            if hook_name not in phase.hooks:
                break
            end += phase.duration
        return end

    def _start_hooks(self, phase: Phase, previous: Phase | None) -> None:
        for name in list(self._hook_timers):
            if name not in phase.hooks:
                self._hook_timers.pop(name).cancelled = True
        for name in phase.hooks:
            if previous is not None and name in previous.hooks and name in self._hook_timers:
                continue  # the run of phases goes on: keep the schedule
            self._schedule_hook(self.hooks[name], self.now + self.hooks[name].period,
                                self._span_end(name, self.phase_index))

    def _schedule_hook(self, hook: Hook, at: float, span_end: float) -> None:
        if at >= span_end - _SAME_TIME:
            self._hook_timers.pop(hook.name, None)
            return
        timer = _Timer(at, _HOOK, -hook.priority, next(self._seq), lambda: None, hook.name, hook, span_end)
        self._hook_timers[hook.name] = timer
        heapq.heappush(self._queue, timer)

    def _run_hooks(self, first: _Timer) -> int:
        """Run the winning hook of ``first``'s group at this instant; report and reschedule the rest."""
        due = [first]
        while (self._queue and self._queue[0].hook is not None
               and abs(self._queue[0].time - first.time) <= _SAME_TIME):
            due.append(heapq.heappop(self._queue))
        due = [t for t in due if not t.cancelled]
        ran = 0
        winners: dict[str, Hook] = {}
        for timer in sorted(due):  # by priority (rank = -priority), then seniority
            hook = timer.hook
            assert hook is not None
            self._schedule_hook(hook, timer.time + hook.period, timer.span_end)
            winner = winners.get(hook.group)
            if winner is None:
                winners[hook.group] = hook
                hook.callback(self.now)
                ran += 1
            else:
                self.emit({"event": "hook_skipped", "hook": hook.name, "winner": winner.name,
                           "reason": f"{winner.name} has priority in the same tick"})
        return ran

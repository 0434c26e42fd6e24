"""The session's sim clock, and the guard that keeps it from running ahead of the loop (no rclpy).

:class:`SimClock` says which ``/clock`` values are due at ``speed`` x wall time, on an injected
wall clock. On a loaded machine the nodes may not keep up with a clock at 30x: heart rate would
reach the coach after its rule update has been decided, a robot command or a new music tempo would
reach the simulated person seconds (of sim time) late, and the session would differ from the one
an idle machine runs. :class:`ClockGuard` therefore slows sim time down to real time (never
faster than real life, where every node keeps up) while the loop lags behind it:

* the strap's heart rate: never more than ``hr_lag`` sim seconds beyond the newest sample that has
  come through LSL and the receiver (its source time mapped onto sim time);
* robot commands: never more than ``reply_lag`` past a command the controller has not answered yet;
* music: never more than ``reply_lag`` past an audio request the streamer has not settled yet (what
  the person follows is the streamer's status);
* the coach's rule updates: never up to the end of a rule update's wait for late heart rate
  (``hr_wait``) before the coach has decided it (its ``/coach/state`` says which one is next). Here
  the clock stops rather than slows: a coach process starved for a moment would otherwise handle a
  burst of ``/clock`` before the heart rate queued behind it, and decide without it.

A hold lasts at most ``max_hold`` wall seconds (a strap that stopped, a crashed controller): then
the clock goes on at full speed and the release is counted. Every hold is counted by its cause,
and the wall time the clock lost is summed, so ``summary.json`` says how much the machine slowed
the session down.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

#: Sim seconds per /clock message: no larger than any sim-time node's timer period
#: (coach tick, participant update and the mock's joint states), or timers skip periods.
CLOCK_STEP = 0.1
#: Causes of a hold (keys of :attr:`ClockGuard.holds` and :attr:`ClockGuard.released`).
HR, ROBOT, MEDIA, DECISION = "heart_rate", "robot_reply", "media_status", "coach_decision"


class SimClock:
    """Sim time advancing at ``speed`` x wall time, in steps of CLOCK_STEP sim seconds.

    Given a limit it goes no faster than real time beyond it: a loop that lags is never waited for
    with the clock standing still (a node that needs sim time to pass to answer, such as the audio
    streamer playing its next block, would wait for the clock as the clock waits for it), and never
    outrun at ``speed`` either.
    """

    def __init__(self, start: float, speed: float, monotonic: Callable[[], float] = time.monotonic,
                 creep: float = 1.0) -> None:
        self.t = start  # the last value published
        self.speed = speed
        self.creep = min(creep, speed)  # sim seconds per wall second beyond a limit
        self._monotonic = monotonic
        self._wall = monotonic()
        self._position = start  # continuous sim time; published in whole steps
        #: Wall seconds the clock lost to limits (what it would have run at ``speed``, less what it ran).
        self.held_wall = 0.0

    def next_step_in(self) -> float:
        """Wall seconds until the next clock value is due at ``speed`` (0: due now). With a limit in
        force it comes later, never sooner: a loop that sleeps this long misses no step."""
        elapsed = max(0.0, self._monotonic() - self._wall)
        ahead = self.t + CLOCK_STEP - (self._position + elapsed * self.speed)
        return max(0.0, ahead / self.speed)

    def due_steps(self, limit: float | None = None, hard: bool = False) -> list[float]:
        """The clock values to publish now to keep up with the wall clock: at real time past ``limit``,
        or (``hard``) not past it at all."""
        wall = self._monotonic()
        elapsed, self._wall = max(0.0, wall - self._wall), wall
        free = self._position + elapsed * self.speed
        if limit is not None and free > limit:
            slow = self._position if hard else self._position + elapsed * self.creep
            reached = max(min(free, limit), slow)
            self.held_wall += (free - reached) / self.speed
            free = reached
        self._position = max(self._position, free)
        steps = []
        while self.t + CLOCK_STEP <= self._position + 1e-9:
            self.t += CLOCK_STEP
            steps.append(self.t)
        return steps


class InFlight:
    """Requests sent and how many have been answered, whichever of the two is heard first.

    The launcher hears a request and its answer on different topics from different nodes, so an
    answer can come before the request itself: answers are counted, and a request whose answer is
    already counted is settled as soon as it is heard.
    """

    def __init__(self) -> None:
        self._sent: deque[float] = deque()  # sim times of the requests not settled yet
        self._answered = 0  # answers heard (a running total)
        self._settled = 0  # requests settled
        self._last_total = 0  # the last running total reported (answered(total=...))
        self._total_base = 0  # answers heard before the reporting node last restarted

    def sent(self, sim_now: float) -> None:
        self._sent.append(sim_now)
        self._drain()

    def answered(self, total: int | None = None) -> None:
        """One more answer, or (``total``) the running total of answers a status reports.

        A total smaller than the last one comes from a restarted node counting from zero again: its
        answers count on top of those heard before it restarted.
        """
        if total is None:
            self._answered += 1
        else:
            if total < self._last_total:
                self._total_base = self._answered
            self._last_total = total
            self._answered = max(self._answered, self._total_base + total)
        self._drain()

    def oldest(self) -> float | None:
        return self._sent[0] if self._sent else None

    def give_up(self) -> None:
        """An answer did not come in time: stop waiting for every request in flight, and count afresh.

        One lost answer (a reply sent before this watcher matched the controller, a node that died)
        would otherwise leave the count one short for good: every later request would look
        unanswered and hold the clock until given up, one at a time, for the rest of the session.
        """
        self._settled += len(self._sent)
        self._sent.clear()
        self._answered = max(self._answered, self._settled)

    def _drain(self) -> None:
        while self._sent and self._settled < self._answered:
            self._sent.popleft()
            self._settled += 1


@dataclass
class ClockGuard:
    """How far sim time may run now, from what the loop has done (see the module's docstring)."""

    hr_lag: float = 2.0
    reply_lag: float = 1.0
    max_hold: float = 5.0
    monotonic: Callable[[], float] = field(default=time.monotonic, repr=False)
    #: Holds that began, by cause; holds given up after ``max_hold``, by cause.
    holds: Counter[str] = field(default_factory=Counter)
    released: Counter[str] = field(default_factory=Counter)
    _offset: float = -math.inf  # source clock minus sim time (the largest seen: the least delayed value)
    _newest_source: float = -math.inf
    _hr_released: bool = False
    hr_wait: float = 3.0  # the coach's wait for late heart rate at a rule update (its option)
    _decision: float | None = None  # the coach's next rule update not decided yet
    _released_decision: float | None = None
    _commands: InFlight = field(default_factory=InFlight)  # robot commands and the controller's replies
    _media: InFlight = field(default_factory=InFlight)  # audio requests and the streamer's settled count
    _holding: str | None = None
    _since: float = 0.0
    _hard: bool = False

    # --- what the loop did ---------------------------------------------------------------------
    def hr_sample(self, source_t: float, sim_now: float) -> None:
        """A strap heart-rate sample came through, stamped ``source_t``, at sim time ``sim_now``."""
        if not (math.isfinite(source_t) and math.isfinite(sim_now)):
            return
        self._offset = max(self._offset, source_t - sim_now)
        self._newest_source = max(self._newest_source, source_t)
        self._hr_released = False

    def command_sent(self, sim_now: float) -> None:
        if math.isfinite(sim_now):
            self._commands.sent(sim_now)

    def command_answered(self) -> None:
        self._commands.answered()

    def media_requested(self, sim_now: float) -> None:
        if math.isfinite(sim_now):
            self._media.sent(sim_now)

    def coach_decision(self, next_decision: float | None) -> None:
        """The coach's state: the time of its next rule update not decided yet (None: none ahead)."""
        self._decision = next_decision

    def media_settled(self, settled: int) -> None:
        """The streamer's status: ``settled`` requests started, failed or superseded so far."""
        self._media.answered(total=settled)

    # --- the limit -----------------------------------------------------------------------------
    def _limits(self) -> dict[str, float]:
        out: dict[str, float] = {}
        if math.isfinite(self._newest_source) and not self._hr_released:
            out[HR] = self._newest_source - self._offset + self.hr_lag
        for cause, flight in ((ROBOT, self._commands), (MEDIA, self._media)):
            oldest = flight.oldest()
            if oldest is not None:
                out[cause] = oldest + self.reply_lag
        if self._decision is not None and self._decision != self._released_decision:
            out[DECISION] = self._decision + self.hr_wait - CLOCK_STEP
        return out

    @property
    def hard(self) -> bool:
        """Whether the limit :meth:`limit` last returned stops the clock (a coach decision) or slows it
        (once the clock reaches it)."""
        return self._hard

    def limit(self, clock_t: float) -> float | None:
        """How far the clock may run at full speed now (None: no limit), given it stands at ``clock_t``."""
        limits = self._limits()
        self._hard = False
        if not limits:
            self._holding = None
            return None
        cause = min(limits, key=limits.__getitem__)
        limit = limits[cause]
        self._hard = cause == DECISION
        if limit >= clock_t + CLOCK_STEP - 1e-9:  # the clock can take its next step: not held
            self._holding = None
            return limit
        wall = self.monotonic()
        if self._holding != cause:
            self._holding, self._since = cause, wall
            self.holds[cause] += 1
        elif wall - self._since > self.max_hold:
            self._release(cause)
            self._holding = None
            return self.limit(clock_t)
        return limit

    def _release(self, cause: str) -> None:
        """Give up waiting for ``cause``: the loop lost it (a strap gone quiet, a node that died)."""
        self.released[cause] += 1
        if cause == HR:
            self._hr_released = True  # until the next sample
        elif cause == DECISION:
            self._released_decision = self._decision  # the coach gives up on late heart rate itself
        else:
            (self._commands if cause == ROBOT else self._media).give_up()

    def report(self, clock: SimClock) -> dict[str, object]:
        """For summary.json: wall seconds held, holds and releases by cause."""
        return {"held_wall_s": round(clock.held_wall, 3), "holds": dict(self.holds),
                "released": dict(self.released)}

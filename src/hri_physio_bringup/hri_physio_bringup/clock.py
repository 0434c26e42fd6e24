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
* the coach's rule updates: never past a rule update's time before the coach has reached it, and
  never up to the end of its wait for late heart rate (``hr_wait``) before the coach has decided it
  (its ``/coach/state`` says which one is next and whether it waits for heart rate). Here
  the clock stops rather than slows: a coach process starved for a moment would otherwise handle a
  burst of ``/clock`` before the heart rate queued behind it, and decide without it;
* a simulated participant's uptake: a robot command or an audio status heard by the launcher after
  the coach's session start is taken up by the person on the next mark of ``reaction_period``
  (:func:`~hri_physio_coach.participant.physiology.takes_effect`), provided the person hears it
  ``TAKE_IN_TIME`` before that mark. The clock stops short of that moment until the participant
  confirms the message on ``/participant/heard`` (:func:`~hri_physio_coach.participant.perception.receipt`):
  a participant process starved for a moment would otherwise take the instruction up a mark late
  and run another session than the evaluation's. Confirmations that still came too late are
  counted (``late_uptakes``), and so are those stamped a mark early (``early_uptakes``: the
  participant's clock was behind the sender's when it heard the message; nothing to hold for).

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

from hri_physio_coach.participant.physiology import SAME_TIME as SAME_MARK
from hri_physio_coach.participant.physiology import TAKE_IN_TIME, takes_effect

#: Sim seconds per /clock message: no larger than any sim-time node's timer period
#: (coach tick, participant update and the mock's joint states), or timers skip periods.
CLOCK_STEP = 0.1
#: Causes of a hold (keys of :attr:`ClockGuard.holds` and :attr:`ClockGuard.released`).
HR, ROBOT, MEDIA, DECISION = "heart_rate", "robot_reply", "media_status", "coach_decision"
UPTAKE = "participant_uptake"
#: Causes that stop the clock rather than slow it.
STOPPING = frozenset({DECISION, UPTAKE})


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
        # Sim time is kept as seconds since ``start`` and published as start + steps * CLOCK_STEP: at
        # ~1.8e9 s every float sum rounds, and thousands of sums would move the clock off the whole
        # and half seconds the coach and the participant count on (1035 steps: 1e-4 s short).
        self._start = start
        self._steps = 0  # values published
        self.speed = speed
        self.creep = min(creep, speed)  # sim seconds per wall second beyond a limit
        self._monotonic = monotonic
        self._wall = monotonic()
        self._ran = 0.0  # continuous sim time since start; published in whole steps
        #: Wall seconds the clock lost to limits (what it would have run at ``speed``, less what it ran).
        self.held_wall = 0.0

    def next_step_in(self) -> float:
        """Wall seconds until the next clock value is due at ``speed`` (0: due now). With a limit in
        force it comes later, never sooner: a loop that sleeps this long misses no step."""
        elapsed = max(0.0, self._monotonic() - self._wall)
        ahead = (self._steps + 1) * CLOCK_STEP - (self._ran + elapsed * self.speed)
        return max(0.0, ahead / self.speed)

    def due_steps(self, limit: float | None = None, stop: float | None = None) -> list[float]:
        """The clock values to publish now to keep up with the wall clock: at real time past ``limit``,
        and never past ``stop``."""
        wall = self._monotonic()
        elapsed, self._wall = max(0.0, wall - self._wall), wall
        free = reached = self._ran + elapsed * self.speed
        if limit is not None and reached > limit - self._start:
            reached = max(limit - self._start, self._ran + elapsed * self.creep)
        if stop is not None and reached > stop - self._start:
            reached = max(stop - self._start, self._ran)
        reached = min(reached, free)
        self.held_wall += (free - reached) / self.speed
        self._ran = max(self._ran, reached)
        steps = []
        while (self._steps + 1) * CLOCK_STEP <= self._ran + 1e-9:
            self._steps += 1
            self.t = self._start + self._steps * CLOCK_STEP
            steps.append(self.t)
        return steps


class ClockHistory:
    """The /clock values published, by wall time: what sim time it was when a message was sent.

    A launcher that hears a message late (its own process busy) would otherwise date it by the clock
    it has run on to since; the message's source timestamp (wall time, from DDS) says which value
    was the newest when it went out.
    """

    def __init__(self, size: int = 4096) -> None:
        self._entries: deque[tuple[int, float]] = deque(maxlen=size)  # (wall ns, sim time), in order

    def published(self, wall_ns: int, t: float) -> None:
        self._entries.append((wall_ns, t))

    def at(self, wall_ns: int) -> float | None:
        """The last value published at or before ``wall_ns`` (None: before what is kept)."""
        for published, t in reversed(self._entries):
            if published <= wall_ns:
                return t
        return None


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
class _Instruction:
    sent: float  # sim time the launcher heard it go out
    wall: float  # monotonic time then
    topic: str
    key: int


class Uptakes:
    """Instructions a simulated participant follows, and its receipts for them, matched by topic and key
    in whichever order they are heard (they travel on different topics from different nodes).

    Before the session start the person follows an instruction at once: nothing to wait for, but the
    instruction is still matched with its receipt, or that receipt would later confirm another message
    with the same text. What is not matched within ``expiry`` wall seconds is dropped.
    """

    def __init__(self, period: float, expiry: float, monotonic: Callable[[], float]) -> None:
        self.period = period
        self.expiry = expiry
        self._monotonic = monotonic
        self.start: float | None = None
        self.late = 0  # receipts whose time puts the uptake on a later mark than the instruction's
        #: Receipts whose time puts it on an earlier mark: the participant's clock was behind the sender's.
        self.early = 0
        self.late_examples: list[dict[str, object]] = []  # the first few of both, for summary.json
        self._unconfirmed: list[_Instruction] = []
        self._early: deque[tuple[float, str, int, float]] = deque()  # (wall, topic, key, heard at)

    def session_started(self, t: float) -> None:
        if self.start is None and math.isfinite(t):
            self.start = t

    def mark(self, t: float) -> float | None:
        """When an instruction heard at ``t`` is taken up (None: at once, or no session yet)."""
        if self.period <= 0 or self.start is None or t < self.start:
            return None
        return takes_effect(t, self.start, self.period)

    def sent(self, topic: str, key: int, sim_now: float) -> None:
        if self.period <= 0 or not math.isfinite(sim_now):
            return
        wall = self._monotonic()
        self._expire(wall)
        for i, (_wall, e_topic, e_key, heard_at) in enumerate(self._early):
            if (e_topic, e_key) == (topic, key):
                del self._early[i]
                self._check(topic, sim_now, heard_at)
                return
        self._unconfirmed.append(_Instruction(sim_now, wall, topic, key))

    def heard(self, topic: str, key: int, heard_at: float) -> None:
        for i, item in enumerate(self._unconfirmed):
            if (item.topic, item.key) == (topic, key):
                del self._unconfirmed[i]
                self._check(topic, item.sent, heard_at)
                return
        self._early.append((self._monotonic(), topic, key, heard_at))

    def deadline(self) -> float | None:
        """How far the participant's clock may run before an instruction is heard too late (None: free):
        ``TAKE_IN_TIME`` short of its mark, with half a clock step to spare."""
        marks = [m for m in (self.mark(item.sent) for item in self._unconfirmed) if m is not None]
        return min(marks) - TAKE_IN_TIME - CLOCK_STEP / 2 if marks else None

    def give_up(self) -> None:
        self._unconfirmed.clear()

    def _check(self, topic: str, sent: float, heard_at: float) -> None:
        """Count a receipt that puts the uptake on another mark than the instruction's time does."""
        mark = self.mark(sent)
        if mark is None:
            return
        taken = self.mark(heard_at)
        if heard_at >= mark - TAKE_IN_TIME - SAME_MARK:
            self.late += 1
        elif taken is None or taken < mark - SAME_MARK:
            self.early += 1
        else:
            return
        if len(self.late_examples) < 5:
            assert self.start is not None
            self.late_examples.append({"topic": topic, "sent_s": round(sent - self.start, 3),
                                       "heard_s": round(heard_at - self.start, 3)})

    def _expire(self, wall: float) -> None:
        while self._early and wall - self._early[0][0] > self.expiry:
            self._early.popleft()
        self._unconfirmed = [item for item in self._unconfirmed
                             if self.mark(item.sent) is not None or wall - item.wall <= self.expiry]


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
    _decision_waiting: bool = True
    _commands: InFlight = field(default_factory=InFlight)  # robot commands and the controller's replies
    _media: InFlight = field(default_factory=InFlight)  # audio requests and the streamer's settled count
    #: The simulated participant's ``reaction_period`` (0: no participant to wait for, or one that
    #: takes instructions up at once, which no hold can make the same on every machine).
    reaction_period: float = 0.0
    _uptakes: Uptakes = field(init=False)
    _holding: str | None = None
    _since: float = 0.0
    _stop: float | None = None

    def __post_init__(self) -> None:
        self._uptakes = Uptakes(self.reaction_period, self.max_hold, self.monotonic)

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

    def coach_decision(self, next_decision: float | None, waiting: bool = True) -> None:
        """The coach's state: the time of its next rule update not decided yet (None: none ahead), and
        whether it has reached it and ``waiting`` for the heart rate taken before it."""
        self._decision = next_decision
        self._decision_waiting = waiting

    def media_settled(self, settled: int) -> None:
        """The streamer's status: ``settled`` requests started, failed or superseded so far."""
        self._media.answered(total=settled)

    @property
    def late_uptakes(self) -> int:
        """Instructions the participant took in too late to take them up on their mark."""
        return self._uptakes.late

    def session_started(self, t: float) -> None:
        """The coach's ``session_start`` (the participant's marks run from it)."""
        self._uptakes.session_started(t)

    def instruction(self, topic: str, key: int, sim_now: float) -> None:
        """A message the participant follows (``key``: its ``message_key``) went out at ``sim_now``."""
        self._uptakes.sent(topic, key, sim_now)

    def participant_heard(self, topic: str, key: int, heard_at: float) -> None:
        """The participant's receipt: it took the message ``key`` on ``topic`` in at ``heard_at``."""
        self._uptakes.heard(topic, key, heard_at)

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
            # Not reached yet: no further than the decision's own time, so a coach slowed down (say, by
            # the predictive policy's first plan, a second of CPU) decides there and sends what it
            # decides in time for the person's next mark; reached and waiting: up to the end of its wait.
            wait = self.hr_wait - CLOCK_STEP if self._decision_waiting else CLOCK_STEP / 2
            out[DECISION] = self._decision + wait
        deadline = self._uptakes.deadline()
        if deadline is not None:
            out[UPTAKE] = deadline
        return out

    @property
    def stop(self) -> float | None:
        """Where :meth:`limit`'s last call says the clock must stop (a coach decision, a participant's
        uptake) rather than slow down; None: nowhere."""
        return self._stop

    def limit(self, clock_t: float) -> float | None:
        """How far the clock may run at full speed now (None: no limit), given it stands at ``clock_t``."""
        limits = self._limits()
        stops = [v for cause, v in limits.items() if cause in STOPPING]
        self._stop = min(stops) if stops else None
        if not limits:
            self._holding = None
            return None
        cause = min(limits, key=limits.__getitem__)
        limit = limits[cause]
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
        elif cause == UPTAKE:
            self._uptakes.give_up()  # a participant that died, or never heard them
        else:
            (self._commands if cause == ROBOT else self._media).give_up()

    def report(self, clock: SimClock) -> dict[str, object]:
        """For summary.json: wall seconds held, holds and releases by cause."""
        return {"held_wall_s": round(clock.held_wall, 3), "holds": dict(self.holds),
                "released": dict(self.released), "late_uptakes": self.late_uptakes,
                **({"early_uptakes": self._uptakes.early} if self._uptakes.early else {}),
                **({"late_examples": self._uptakes.late_examples} if self._uptakes.late_examples else {})}

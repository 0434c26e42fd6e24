"""What the coach node does with its inputs, without ROS: control lines, heart-rate frames, the clock.

:class:`SessionControl` wraps an :class:`~hri_physio_coach.coach.ExerciseCoach` with the parts of
running it that do not depend on a transport:

* control lines (``start``, ``stop``/``exit``; anything else is counted as unknown);
* when the session starts: on ``start`` (or at once when not interactive), on the next whole
  second of the coach's clock (:func:`~hri_physio_coach.coach.session_start_time`), and never
  while the clock still reads 0 (sim time before the first ``/clock``);
* heart-rate frames: which column is the heart rate and which flags a sample
  (:func:`hr_samples`).

The node (``nodes/qt_physio_coach.py``) turns messages into calls of these methods, under its lock.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from enum import StrEnum

from hri_physio_bridge.frames import Frame
from hri_physio_coach.coach import ExerciseCoach, session_start_time

#: Channel names that hold the heart rate, by preference (else the first channel).
HR_CHANNELS = ("hr", "bpm", "heart_rate")
#: A channel of this name marks samples the source considers unreliable (non-zero = flagged).
FLAG_CHANNEL = "flag"
START_WORDS, STOP_WORDS = ("start",), ("stop", "exit")


class Control(StrEnum):
    """What a control line asked for."""

    START = "start"
    STOP = "stop"
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class HrSample:
    t: float  # the source's timestamp of the sample (s)
    bpm: float
    flagged: bool


def hr_samples(frame: Frame) -> list[HrSample]:
    """Every sample of a heart-rate frame: its source time, its heart rate and whether it is flagged.

    The heart rate is the channel named ``hr``, ``bpm`` or ``heart_rate`` (in that order of
    preference, any case), else the first; a channel named ``flag`` marks flagged samples.
    """
    names = [c.lower() for c in frame.channels]
    column = next((names.index(n) for n in HR_CHANNELS if n in names), 0)
    flag = names.index(FLAG_CHANNEL) if FLAG_CHANNEL in names else None
    values = frame.values
    return [HrSample(float(frame.timestamps[i]), float(values[i, column]),
                     flag is not None and float(values[i, flag]) != 0.0)
            for i in range(frame.num_samples)]


class SessionControl:
    """Starts, ticks and stops a coach from control lines and the clock; counts the control lines."""

    def __init__(self, coach: ExerciseCoach, interactive: bool) -> None:
        self.coach = coach
        self.interactive = interactive
        self.counts: Counter[str] = Counter(received=0, unknown=0)
        self.start_requested = False
        self.start_at: float | None = None  # the whole second the session starts at, once known
        self.stop_reason: str | None = None
        self.finished = False  # the node should end: the session ended, or a stop was asked for

    @staticmethod
    def classify(line: str) -> Control:
        word = line.strip().lower()
        if word in START_WORDS:
            return Control.START
        if word in STOP_WORDS:
            return Control.STOP
        return Control.UNKNOWN

    def request(self, line: str) -> Control:
        """One control line: ``start`` asks for the session, ``stop`` or ``exit`` ends it (even unstarted)."""
        control = self.classify(line)
        self.counts["received"] += 1
        if control is Control.START:
            self.start_requested = True
        elif control is Control.STOP:
            self.stop(f"{line.strip().lower()} requested")
        else:
            self.counts["unknown"] += 1
        return control

    def stop(self, reason: str) -> None:
        """End the session (if it runs) and the node; the first reason given is kept."""
        self.stop_reason = self.stop_reason or reason
        self.coach.stop(self.stop_reason)  # nothing to stop before the start
        self.finished = True

    def on_hr(self, frame: Frame, now: float) -> None:
        for s in hr_samples(frame):
            self.coach.on_hr(s.bpm, now=now, flagged=s.flagged, source_t=s.t)

    def tick(self, now: float) -> None:
        """Start the session when it is due, run its timers, notice its end. Nothing at clock 0."""
        coach = self.coach
        if now <= 0.0 or self.finished:  # sim time without /clock yet: wait
            return
        if not coach.started and (self.start_requested or not self.interactive):
            if self.start_at is None:
                self.start_at = session_start_time(now)
            if now >= self.start_at:
                coach.start(self.start_at)
        if coach.started:
            coach.tick(now)
        if coach.finished:
            self.finished = True

    def end(self) -> str:
        """At the node's exit: stop a session still running; how it ended (``finished``, ``idle``, ...)."""
        if self.coach.started and not self.coach.finished:
            self.coach.stop(self.stop_reason or "signal")
        return self.coach.engine.state

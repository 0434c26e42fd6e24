"""One session, discrete-event: the nodes' coach and participant model on one injected clock.

The closed loop runs ``qt_physio_coach`` (an :class:`~hri_physio_coach.coach.ExerciseCoach`)
and ``simulated_participant`` (a :class:`~hri_physio_coach.participant.cardiac.ParticipantSimulator`
that follows the robot's command lines through a
:class:`~hri_physio_coach.participant.perception.RobotObserver`), joined by ROS 2 and LSL.
Here the same three objects are joined directly: every command line the coach sends goes to
the observer (the person takes a change up on the next mark of ``reaction_period``, as the node's
participant does), every 1 Hz heart rate the strap reports reaches the coach ``hr_latency``
seconds later, and time jumps from one due thing (a coach timer, a heart-rate sample) to the
next. No second implementation: only the transport is left out.

The participant's model starts with the session (kinetics at rest, its seed's session random
stream from the first draw): the closed loop's participant rests on another stream until the
coach's ``session_start`` and then runs this same :func:`~hri_physio_coach.participant.stream.session_model`
(docs/PARTICIPANT_MODEL.md, "Before the session").
"""

from __future__ import annotations

import functools
import heapq
import itertools
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from hri_physio_coach.coach import ExerciseCoach, load_coach_routine
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.participant.perception import RobotObserver
from hri_physio_coach.participant.physiology import ParticipantParams, takes_effect
from hri_physio_coach.participant.stream import session_model
from hri_physio_coach.routine import Routine
from qt_controller.commands import ParseError, SetAudio, parse_command

#: Heart-rate samples travel strap -> LSL -> receiver -> coach; this is their delay (s) here.
DEFAULT_HR_LATENCY = 0.1


@dataclass(frozen=True)
class SessionSpec:
    """One participant under one policy: everything that decides the session's outcome."""

    policy: str
    participant: int  # index in the cohort
    params: ParticipantParams
    participant_seed: int  # the participant's noise (RR variability, strap artefacts)
    coach_seed: int  # the coach's draws (fuzzy rule, behaviours)
    variant: str = "main"  # sensitivity variant the params come from
    hr_latency: float = DEFAULT_HR_LATENCY
    #: Transport stalls, ``(start, end)`` s of session time: the samples taken in one arrive together at
    #: its end (plus ``hr_latency``), as from a loaded machine.
    hr_stalls: tuple[tuple[float, float], ...] = ()
    #: Robot commands reach the participant this long (s) after the coach sent them.
    command_latency: float = 0.0
    #: A new music tempo is heard this much (s) later still (the audio streamer's cross-fade).
    tempo_latency: float = 0.0
    #: The participant's seeded model starts this long (s) after the coach's ``session_start`` (a closed
    #: loop hands over on the strap's next fitting second: docs/PARTICIPANT_MODEL.md).
    model_start: float = 0.0
    coach_options: tuple[tuple[str, Any], ...] = ()  # extra coach options, e.g. (("speed_idx", 2),)


@dataclass
class SessionRun:
    """What happened: the coach's events and decisions, and per-second traces."""

    spec: SessionSpec
    events: list[dict[str, Any]]
    decisions: list[dict[str, Any]]
    t: np.ndarray  # s, the strap's 1 Hz heart-rate times
    hr: np.ndarray  # bpm, the strap's heart rate (what the coach receives)
    model_hr: np.ndarray  # bpm, the model's true heart rate at the same times
    ladder: np.ndarray  # ladder index at those times
    mets: np.ndarray  # cost of the activity performed at those times (nan: seated or unstated)
    activity: list[str] = field(default_factory=list)  # the gesture performed at those times

    def of(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e.get("event") == kind]


@lru_cache(maxsize=8)
def _routine(routine_file: str, calib_time: float, video_time: float, rule_period: float,
             behaviour_period: float) -> Routine:
    cfg = CoachConfig(routine_file=routine_file, calib_time=calib_time, video_time=video_time,
                      rule_period=rule_period, behaviour_period=behaviour_period)
    return load_coach_routine(cfg)


def session_routine(cfg: CoachConfig) -> Routine:
    """The coach's routine, loaded once per process (it is the same file for every session)."""
    return _routine(cfg.routine_file, cfg.calib_time, cfg.video_time, cfg.rule_period, cfg.behaviour_period)


def coach_config(spec: SessionSpec, base: CoachConfig | None = None) -> CoachConfig:
    """The coach's options for a session: the base (default: the packaged defaults) for this person."""
    values = {**(base.as_dict() if base is not None else {}), **dict(spec.coach_options),
              "policy": spec.policy, "seed": spec.coach_seed, "part_age": float(spec.params.age)}
    return CoachConfig.from_mapping(values, f"session {spec.policy}/{spec.participant}")


@functools.lru_cache(maxsize=256)
def _is_audio(line: str) -> bool:
    try:
        return isinstance(parse_command(line), SetAudio)
    except ParseError:
        return False


def simulate_session(spec: SessionSpec, base: CoachConfig | None = None) -> SessionRun:
    """Run one whole session; returns its events, decisions and per-second traces."""
    cfg = coach_config(spec, base)
    routine = session_routine(cfg)
    sim = session_model(spec.params, spec.participant_seed, spec.model_start, ecg=False)
    observer = RobotObserver()
    clock = [0.0]
    commands: list[tuple[float, int, str]] = []  # heap: (when the participant sees it, order, line)
    sent = itertools.count()

    def see(line: str) -> None:
        if observer.observe(line):  # taken up on the person's next mark from the session start (0)
            sim.set_activity(observer.activity, takes_effect(clock[0], 0.0, spec.params.reaction_period))

    def send(line: str) -> None:
        delay = spec.command_latency + (spec.tempo_latency if _is_audio(line) else 0.0)
        if delay > 0:
            heapq.heappush(commands, (clock[0] + delay, next(sent), line))
        else:
            see(line)

    events: list[dict[str, Any]] = []
    coach = ExerciseCoach(cfg, lambda: clock[0], send, events.append, routine=routine)
    coach.start(0.0)
    latency = spec.hr_latency

    def delivered(t_hr: float) -> float:
        stalled = [end for start, end in spec.hr_stalls if start <= t_hr < end]
        return max([t_hr, *stalled]) + latency

    arrivals: deque[tuple[float, float, float, float]] = deque()  # (arrival, source time, bpm, model bpm)
    ts: list[float] = []
    hrs: list[float] = []
    model: list[float] = []
    ladder: list[int] = []
    mets: list[float] = []
    acts: list[str] = []
    next_sample = spec.model_start + 1.0  # the strap reports HR every whole second of model time
    while not coach.finished:
        wake = (coach.engine.next_due(), next_sample + latency, arrivals[0][0] if arrivals else None,
                commands[0][0] if commands else None)
        now = min(t for t in wake if t is not None)
        for t_hr, bpm, true_bpm in sim.advance_hr(now):
            arrivals.append((delivered(t_hr), t_hr, bpm, true_bpm))
        next_sample = sim.next_report  # a strap dropout skips a second
        clock[0] = now
        while commands and commands[0][0] <= now + 1e-9:
            see(heapq.heappop(commands)[2])
        while arrivals and arrivals[0][0] <= now + 1e-9:
            arrival, source, bpm, true_bpm = arrivals.popleft()
            coach.on_hr(bpm, now=arrival, source_t=source)
            ts.append(source)
            hrs.append(bpm)
            model.append(true_bpm)
            ladder.append(coach.ladder.index)
            doing = coach.choice.current
            mets.append(doing.mets if doing is not None and doing.mets is not None else np.nan)
            acts.append(sim.activity.name)
        coach.tick(now)
    return SessionRun(
        spec=spec, events=events, decisions=[d.as_dict() for d in coach.decisions],
        t=np.array(ts), hr=np.array(hrs), model_hr=np.array(model), ladder=np.array(ladder),
        mets=np.array(mets), activity=acts,
    )

"""The QT cardio-aware exercise coach on top of the scenario engine (no rclpy).

The routine file says what happens when (phases, activities, media, speech); this module
gives the scenario its exercise-specific parts: the calibration of HR_rest and the zone,
the HR buffer, the rule update (an :class:`~hri_physio_coach.policies.adapter.Adapter` on the speed
ladder, gated on signal quality), the random behaviours, the calibration reminders, and
the robot commands (typed :mod:`qt_controller.commands`, written with ``to_line()``). Every
decision becomes a JSON-able event with its inputs and outputs and the participant id (never
the name); a rule update that did not adapt says why with a :mod:`~hri_physio_coach.gates` code.
"""

from __future__ import annotations

import functools
import math
import random
import string
from collections import deque
from collections.abc import Callable, Mapping
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path
from typing import Any

from hri_physio_coach import gates
from hri_physio_coach.activity_choice import ActivityChoice
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.engine import (
    FINISHED,
    STOPPED,
    ActionContext,
    Event,
    Hook,
    Listener,
    ScenarioEngine,
    Timer,
)
from hri_physio_coach.hr_input import HeartRateMonitor
from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.media_names import tempo_from_name
from hri_physio_coach.paths import default_routine_file
from hri_physio_coach.policies import types as act
from hri_physio_coach.policies.adapter import Adapter
from hri_physio_coach.policies.registry import make_policy
from hri_physio_coach.policies.types import Controls, Decision, RuleInput
from hri_physio_coach.routine import Action, Activity, Phase, Routine, load_routine
from hri_physio_coach.zones import HeartRateZone, tanaka_hr_max
from qt_controller.commands import (
    Command,
    ParseError,
    SetAudio,
    SetEmotion,
    SetGesture,
    SetSpeech,
    SetVideo,
    SetVolume,
)
from qt_controller.gestures import GestureError, GestureLibrary, default_gesture_dir

CALIBRATION = "calibration"
RULE_UPDATE, BEHAVIOUR, REMINDER, FACE = "rule_update", "behaviour", "reminder", "encouragement"
BEHAVIOURS = ("motivation", "emotion", "hr_report")
#: Two engine times this close (s) are one instant.
SAME_INSTANT = 1e-6

_STRING_VARS = ("name", "video", "gesture", "label", "routine_label", "activity", "phase", "splash", "music",
                "relaxing_audio", "relaxing_video", "relaxing_gesture", "minutes_word")
_NUMBER_VARS = ("speed", "tempo", "relaxing_speed", "calib_minutes", "minutes_left", "hr_rest", "hr_max",
                "zone_low", "zone_high", "zone_target", "hr")


def _gesture(name: str, speed: float) -> SetGesture:
    """A gesture at ``speed`` to 0.01, as the coach has always sent it (``set gesture marching 0.95``)."""
    return SetGesture(name, round(speed, 2))


class CoachError(ValueError):
    """The routine and the coach do not fit together (unknown placeholder, hook or call)."""


@functools.cache
def shipped_gesture_durations() -> Mapping[str, float]:
    """Recorded duration (s at speed 1) of each gesture qt_controller ships, by lower-case name."""
    try:
        library = GestureLibrary.from_dirs([default_gesture_dir()])
    except (GestureError, OSError, ModuleNotFoundError):
        return {}
    return {name.lower(): library.get(name).duration for name in library.names}


def _spoken(bpm: float) -> float:
    """A heart rate as people round it, half up to 0.1 bpm (155.05 -> 155.1, as in the thesis).

    ``format(155.05, ".1f")`` gives 155.0 because the binary value is a hair below; speech
    templates get the half-up value so the announcement matches a hand calculation.
    """
    return float(Decimal(repr(round(bpm, 6))).quantize(Decimal("0.1"), rounding=ROUND_HALF_UP))


def routine_variables(config: CoachConfig) -> dict[str, float]:
    """Names a routine file may use for durations and delays."""
    return {"calib_time": config.calib_time, "video_time": config.video_time,
            "rule_period": config.rule_period, "behaviour_period": config.behaviour_period}


def load_coach_routine(config: CoachConfig) -> Routine:
    path = Path(config.routine_file) if config.routine_file else default_routine_file()
    return load_routine(path, routine_variables(config))


def session_start_time(now: float) -> float:
    """When a session asked to start at ``now`` starts: the next whole second of the coach's clock.

    Every scheduled time (activity starts, rule updates) is then a whole second: readable in the
    logs, and a simulated strap's half-second samples keep clear of the windows' edges.
    """
    return float(math.ceil(now - 1e-6))


class ExerciseCoach(Listener):
    """Runs the exercise session: feed it HR samples and command replies, tick it with time."""

    def __init__(self, config: CoachConfig, clock: Callable[[], float], send: Callable[[str], None],
                 sink: Callable[[Event], None], routine: Routine | None = None) -> None:
        self.cfg = config
        self.clock = clock
        self._send = send
        self._sink = sink
        self.participant = config.participant
        routine = routine if routine is not None else load_coach_routine(config)
        if config.calib_skip:
            routine = routine.without([CALIBRATION])
        self.hr_max = tanaka_hr_max(config.part_age)
        self.ladder = SpeedLadder(config.speed_modifier, config.audio_suffix, config.speed_idx)
        self.adapter = Adapter(make_policy(config.policy, config.seed), self.ladder, config.adapter_options)
        self.rng = random.Random(f"behaviour:{config.seed}")
        self.monitor = HeartRateMonitor(
            config.hr_valid_min, config.hr_valid_max, config.hr_timeout, config.min_valid_samples,
            config.max_invalid_fraction, config.buffer, config.hr_report_window,
        )
        self.zone: HeartRateZone | None = None
        self.hr_rest_source: str | None = None
        self._calibrated_in_phase = False
        self._calibration_start = 0.0
        self._gesture: tuple[str, bool] | None = None  # (name, follows the ladder)
        # An exercise gesture is played again each time it ends, until its activity ends.
        self._gesture_durations = shipped_gesture_durations() if config.gesture_repeat else {}
        self._gesture_next: float | None = None  # when the gesture playing now ends
        self._faces = 0
        self._audio_follows_ladder = False
        # Policies that pick activities: what runs in each slot, where the HR buffer starts, notices said.
        self.choice = ActivityChoice(routine)
        self._routine_costs = tuple(
            (p.kind, tuple((a.duration, a.mets) for a in p.activities if a.mets is not None))
            for p in routine.phases)
        self._tempos = tuple(tempo_from_name(s) for s in self.ladder.suffixes)
        self._buffer_since = 0.0
        self._pending_rule: tuple[float, Timer] | None = None  # (rule time, its deadline timer)
        #: Commands sent and not answered yet by qt_controller: (session time sent, line), oldest first.
        #: Kept once a reply has been seen: a coach driven without a controller (the offline
        #: evaluation, a bare test) gets no replies and expects none.
        self._awaiting: deque[tuple[float, str]] = deque()
        self._replies_seen = False
        #: A calibration waiting for its last heart rate: (end of the phase, its deadline timer).
        self._pending_calibration: tuple[float, Timer] | None = None
        #: The plan of a phase that started while the calibration before it still waited: (phase, start).
        self._deferred_plan: tuple[Phase, float] | None = None
        self._noticed: set[str] = set()
        self._calls: dict[str, Callable[[ActionContext], None]] = {"calibrate": self._call_calibrate}
        hooks = {
            RULE_UPDATE: Hook(RULE_UPDATE, config.rule_period, self._rule_update, priority=10),
            BEHAVIOUR: Hook(BEHAVIOUR, config.behaviour_period, self._behaviour, priority=0),
            REMINDER: Hook(REMINDER, config.calib_reminder_period, self._reminder, priority=5),
            FACE: Hook(FACE, config.calib_face_period, self._encouraging_face, group="face"),
        }
        self._check_routine(routine)
        try:
            self.engine = ScenarioEngine(routine, clock, self._emit, self._on_action, hooks, listener=self)
        except ValueError as exc:
            raise CoachError(str(exc)) from None
        self.engine.gate = self._hold_for_late_heart_rate
        self._held_at: float | None = None  # a rule update the routine is held at (late heart rate)
        self._held_wait: tuple[float, float] = (math.nan, 0.0)  # (that rule update, how long it was held)
        self.decisions: list[Decision] = []

    # --- public API --------------------------------------------------------------------------
    @property
    def routine(self) -> Routine:
        return self.engine.routine

    @property
    def started(self) -> bool:
        return self.engine.state != "idle"

    @property
    def finished(self) -> bool:
        return self.engine.state in (FINISHED, STOPPED)

    def start(self, now: float | None = None) -> None:
        self.engine.start(now)

    def warm_up(self) -> None:
        """Load what the policy's first decision needs (see :meth:`Policy.warm_up`)."""
        self.adapter.policy.warm_up()

    def tick(self, now: float | None = None) -> None:
        now = self.clock() if now is None else float(now)
        if self.engine.running:
            self._check_hr_timeout(now)
            self._check_pending(now)
            self._check_unanswered(now)
        self.engine.tick(now)
        # A routine held at an instant plays nothing due from then on before it goes on (the transition
        # due then may change the gesture).
        due = now if self.engine.held_at is None else min(now, self.engine.held_at - 1e-9)
        if self.engine.running and self._gesture_next is not None and due >= self._gesture_next:
            assert self._gesture is not None  # set with _gesture_next
            self._play_gesture(self._gesture[0], self.ladder.speed, True, "gesture repeat")

    def stop(self, reason: str) -> None:
        self.engine.stop(reason)

    def on_hr(self, hr: float, now: float | None = None, flagged: bool = False,
              source_t: float | None = None) -> None:
        """One HR sample (bpm) received at ``now`` on the coach's clock; ``source_t`` is its own stamp."""
        now = self.clock() if now is None else float(now)
        self.monitor.add(now, float(hr), flagged, source_t)
        if self.engine.running:
            self._check_hr_timeout(now)
            self._check_pending(now)

    def on_reply(self, reply: Mapping[str, Any]) -> None:
        """A reply of qt_controller; failures are logged as events and the session goes on."""
        self._replies_seen = True
        line = str(reply.get("command", "")).strip()
        # The newest command with this text: after an outage, older ones went to a controller that
        # was down (replies come in order, so a pair both answered is settled either way).
        for i in range(len(self._awaiting) - 1, -1, -1):
            if self._awaiting[i][1] == line:
                del self._awaiting[i]
                break
        if not reply.get("ok", True):
            self._emit({"t": self.engine.now, "event": "command_failed",
                        "command": self._redact(str(reply.get("command", ""))),
                        "message": self._redact(str(reply.get("message", ""))), "source": "robot"})

    def state(self) -> Event:
        """A snapshot for /coach/state."""
        return {
            "t": self.engine.now, "participant": self.participant, "policy": self.cfg.policy,
            **self.engine.state_dict(), **{f"ladder_{k}": v for k, v in self.ladder.state().items()},
            "zone": self.zone.as_dict() if self.zone else None,
            "adaptation": "paused" if self.monitor.lost else "active", "last_hr": self.monitor.last_hr,
            "performing": self.choice.current.name if self.choice.current else None,
            "activity_level": self.adapter.level,
            "next_decision": self.next_decision(),
            "waiting_for_hr": self.waiting_for_heart_rate(),
        }

    def waiting_for_heart_rate(self) -> bool:
        """Whether the next decision's time has come and it waits for heart rate taken before it."""
        return (self._pending_rule is not None or self._pending_calibration is not None
                or self.engine.held_at is not None)

    def next_decision(self) -> float | None:
        """The time of the next calibration or rule update not decided yet (one waiting for late heart
        rate first).

        It is decided at that time, or up to ``hr_wait`` later once the heart rate taken before it has
        come; a launcher driving sim time reads it from /coach/state so as never to run the clock past
        that deadline before the coach, maybe slowed by a busy machine, has decided.
        """
        if self._pending_calibration is not None:
            return self._pending_calibration[0]
        if self._pending_rule is not None:
            return self._pending_rule[0]
        return self.engine.next_hook_due(RULE_UPDATE)

    # --- events and commands -----------------------------------------------------------------
    def _emit(self, event: Event) -> None:
        self._sink({"t": event.get("t", self.engine.now), "participant": self.participant, **event})

    def _redact(self, text: str) -> str:
        name = self.cfg.part_name.strip()
        return text.replace(name, "<name>") if name else text

    def command(self, command: Command, why: str) -> bool:
        """Send one robot command; a failure to build or send it is logged and the session goes on."""
        try:
            line = command.to_line()
        except ParseError as exc:
            self._build_failed(repr(command), str(exc), why)
            return False
        self._emit({"event": "command", "command": self._redact(line), "why": why})
        awaited = (self.engine.now, line.strip())
        if self._replies_seen:  # before sending: a reply may come before _send returns
            self._awaiting.append(awaited)
        try:
            self._send(line)
        except Exception as exc:  # any transport failure must not end the session
            if awaited in self._awaiting:
                self._awaiting.remove(awaited)
            self._emit({"event": "command_failed", "command": self._redact(line),
                        "message": f"{type(exc).__name__}: {exc}", "source": "send"})
            return False
        return True

    def _check_unanswered(self, now: float) -> None:
        """Commands qt_controller has not answered within ``reply_timeout`` (it was down, say): each is
        recorded once as a ``command_unanswered`` event, never sent again."""
        while self._awaiting and now - self._awaiting[0][0] > self.cfg.reply_timeout:
            sent, line = self._awaiting.popleft()
            self._emit({"t": now, "event": "command_unanswered", "command": self._redact(line),
                        "sent_t": sent, "waited": round(now - sent, 3)})

    def _build_failed(self, what: str, message: str, why: str) -> None:
        """A command the routine or configuration asked for that the protocol cannot carry."""
        self._emit({"event": "command_failed", "command": self._redact(what),
                    "message": self._redact(message), "source": "build", "why": why})

    def say(self, text: str, why: str) -> None:
        self.command(SetSpeech(text.strip()), why)

    # --- template variables ------------------------------------------------------------------
    def _variables(self, ctx: ActionContext | None = None, **extra: Any) -> dict[str, Any]:
        cfg = self.cfg
        phase = ctx.phase if ctx else self.engine.phase
        activity = ctx.activity if ctx else self.engine.activity
        now = ctx.t if ctx else self.engine.now
        minutes_left = max(0, math.ceil((self.engine.phase_end - now) / 60.0 - 1e-9)) if phase else 0
        values: dict[str, Any] = {
            "name": cfg.part_name if cfg.address_by_name else "friend",
            "splash": cfg.video_default,
            "music": cfg.audio_exercise_base.format(self.ladder.suffix),
            "relaxing_audio": cfg.audio_relaxing, "relaxing_video": cfg.video_relaxing,
            "relaxing_gesture": cfg.gesture_relaxing, "relaxing_speed": cfg.gesture_relaxing_speed,
            "speed": self.ladder.speed, "tempo": self.ladder.tempo or 0.0,
            "calib_minutes": round(cfg.calib_time / 60.0),
            "minutes_left": minutes_left, "minutes_word": "minute" if minutes_left == 1 else "minutes",
            "phase": phase.name if phase else "", "activity": activity.name if activity else "",
            "label": activity.label if activity else "", "video": "", "gesture": "",
            "hr_max": self.hr_max, "hr": self.monitor.last_hr or 0.0,
        }
        if self.zone is not None:
            values.update(hr_rest=_spoken(self.zone.hr_rest), zone_low=_spoken(self.zone.low),
                          zone_high=_spoken(self.zone.high), zone_target=_spoken(self.zone.target))
        if activity is not None:
            values.update({k: v for k, v in activity.attrs.items() if isinstance(v, str | int | float)})
            running = self.choice.running if activity is self.engine.activity else None
            if running is not None:  # another activity runs in this slot: its gesture, video and label
                values.update({k: v for k, v in running.attrs.items() if isinstance(v, str | int | float)})
                values.update(label=running.label, routine_label=activity.label)
        values.update(extra)
        return values

    def _check_routine(self, routine: Routine) -> None:
        """Fail at start-up, not mid-session, on placeholders, calls or hooks the coach lacks."""
        dummy: dict[str, Any] = {k: "x" for k in _STRING_VARS} | {k: 1.0 for k in _NUMBER_VARS}
        templates = [("speech_hr_report", self.cfg.speech_hr_report), ("speech_zone", self.cfg.speech_zone),
                     ("speech_calib_reminder", self.cfg.speech_calib_reminder),
                     ("speech_out_of_reach_below", self.cfg.speech_out_of_reach_below),
                     ("speech_out_of_reach_above", self.cfg.speech_out_of_reach_above),
                     *(("speech_activity_switch", text) for text in self.cfg.speech_activity_switch)]
        for phase in routine.phases:
            actions = [*phase.on_enter, *phase.on_exit, *phase.activity_actions]
            for activity in phase.activities:
                extra = {k: "x" for k in activity.attrs}
                for action in (*actions, *activity.on_enter):
                    where = f"phase {phase.name!r}, activity {activity.name!r}"
                    self._check_action(action, dummy | extra, where)
        for action in (*routine.on_start, *routine.on_end):
            self._check_action(action, dummy, "routine start/end")
        for key, text in templates:
            self._check_template(text, dummy, f"configuration {key}")
        names = [t for _, t, _, _ in string.Formatter().parse(self.cfg.audio_exercise_base) if t]
        if names:
            raise CoachError(f"audio_exercise_base must use '{{}}' for the tempo suffix, not {names}")

    def _check_action(self, action: Action, dummy: Mapping[str, Any], where: str) -> None:
        if action.kind == "call":
            if action.value not in self._calls:
                raise CoachError(f"{where}: unknown call {action.value!r} (known: {sorted(self._calls)})")
            return
        self._check_template(action.value, dummy, f"{where}, {action.kind} action")
        speed = action.params.get("speed")
        if speed is not None and speed != "current" and not isinstance(speed, int | float):
            self._check_template(str(speed), dummy, f"{where}, gesture speed")

    @staticmethod
    def _check_template(text: str, dummy: Mapping[str, Any], where: str) -> None:
        try:
            text.format_map(dummy)
        except KeyError as exc:
            raise CoachError(f"{where}: unknown placeholder {{{exc.args[0]}}} in {text!r}") from None
        except (ValueError, IndexError) as exc:
            raise CoachError(f"{where}: bad template {text!r}: {exc}") from None

    # --- routine actions ---------------------------------------------------------------------
    def _on_action(self, action: Action, ctx: ActionContext) -> None:
        if action.kind == "call":
            self._calls[action.value](ctx)
            return
        variables = self._variables(ctx)
        value = action.value.format_map(variables)
        why = f"{ctx.phase.name if ctx.phase else 'routine'}/{ctx.activity.name if ctx.activity else '-'}"
        if action.kind == "say" and self._speaks_for_replaced_slot(action, ctx):
            value = self.rng.choice(self.cfg.speech_activity_switch).format_map(variables)
        if action.kind == "say":
            self.say(value, why)
        elif action.kind == "emotion":
            self.command(SetEmotion(value), why)
        elif action.kind == "volume":
            try:
                percent = int(value)
            except ValueError:
                self._build_failed(f"volume {value!r}", "volume must be a whole number", why)
                return
            self.command(SetVolume(percent), why)
        elif action.kind == "video":
            self.command(SetVideo(self.cfg.video_path.format(value)), why)
        elif action.kind == "audio":
            self._audio_follows_ladder = "{music}" in action.value
            self.command(SetAudio(self.cfg.audio_path.format(value)), why)
        elif action.kind == "gesture":
            raw_speed = action.params.get("speed", "current")
            follows = raw_speed == "current"
            try:
                speed = self.ladder.speed if follows else float(str(raw_speed).format_map(variables))
            except ValueError:
                self._build_failed(f"gesture {value!r} at speed {raw_speed!r}",
                                   "gesture speed must be a number", why)
                return
            self._play_gesture(value, speed, follows, why)

    def _play_gesture(self, name: str, speed: float, follows: bool, why: str) -> None:
        """Send a gesture; one that follows the ladder is played again when it ends (see :meth:`tick`)."""
        self._gesture = (name, follows)
        self.command(_gesture(name, speed), why)
        duration = self._gesture_durations.get(name.lower()) if follows else None
        self._gesture_next = None if duration is None else self.engine.now + duration / speed

    def _resend_pace(self, why: str, gesture: bool = True) -> None:
        """After a ladder change: the gesture at the new speed, the music at the new tempo."""
        if gesture and self._gesture is not None and self._gesture[1]:
            self._play_gesture(self._gesture[0], self.ladder.speed, True, why)
        if self._audio_follows_ladder:
            music = self.cfg.audio_exercise_base.format(self.ladder.suffix)
            self.command(SetAudio(self.cfg.audio_path.format(music)), why)

    # --- listener ----------------------------------------------------------------------------
    def on_phase_start(self, phase: Phase, t: float) -> None:
        if phase.kind == CALIBRATION:
            self._calibrated_in_phase = False
            self._calibration_start = t
            self.monitor.start_calibration()
            return
        if self._pending_calibration is not None:
            self._deferred_plan = (phase, t)  # planned once the zone is known (within hr_wait)
            return
        if self.zone is None:
            self._set_zone(self.cfg.resting_default, "default", "calibration skipped", 0, t)
        self._plan_phase(phase, t)

    def on_phase_end(self, phase: Phase, t: float) -> None:
        if phase.kind == CALIBRATION and not self._calibrated_in_phase:
            self._calibrate(t)

    def on_activity_start(self, phase: Phase, activity: Activity, t: float) -> None:
        self.monitor.clear(before=t)
        self._buffer_since = t
        running = self.choice.slot_started(phase, activity, self.adapter.level)
        if running is not None:
            self._emit({"event": "activity_choice", "phase": phase.name, "slot": activity.name,
                        "activity": running.name, "mets": running.mets, "level": self.adapter.level,
                        "reason": "the policy holds another activity cost than the slot's"})
        self._gesture_next = None  # the last activity's gesture is not repeated into this one
        if phase.kind != CALIBRATION:
            self._gesture = None  # the activity's own actions set its gesture
            self.adapter.observe(t, self._controls(t))

    def on_end(self, t: float) -> None:
        self._gesture_next = None
        self._emit({"event": "summary", "decisions": len(self.decisions),
                    "adaptations": sum(1 for d in self.decisions if d.changed),
                    "final_ladder_index": self.ladder.index})

    # --- calibration -------------------------------------------------------------------------
    def _call_calibrate(self, ctx: ActionContext) -> None:
        self._calibrate(ctx.t)

    def _calibrate(self, t: float) -> None:
        """HR_rest from the heart rate taken in the phase, once the last of it has come.

        As a rule update does: at once when every sample taken before ``t`` has arrived, else when it
        has, ``hr_wait`` after ``t`` at the latest (the next phase starts meanwhile; its plan waits
        for the zone).
        """
        self._calibrated_in_phase = True
        if self.monitor.window_complete(t):
            self._finish_calibration(t)
            return
        timer = self.engine.schedule(t + self.cfg.hr_wait, self._finish_pending_calibration,
                                     "calibration: heart rate late")
        self._pending_calibration = (t, timer)

    def _finish_pending_calibration(self) -> None:
        assert self._pending_calibration is not None  # scheduled with it
        t, _ = self._pending_calibration
        self._pending_calibration = None
        self._finish_calibration(t)
        if self._deferred_plan is not None:
            phase, start = self._deferred_plan
            self._deferred_plan = None
            self._plan_late(phase, start)

    def _finish_calibration(self, t: float) -> None:
        """HR_rest: the mean of the valid heart rate taken from ``calib_settle`` after the phase start (the
        person has just sat down) until ``t``; at most a quarter of the phase is left out at the start."""
        duration = max(t - self._calibration_start, 0.0)
        start = self._calibration_start + min(self.cfg.calib_settle, 0.25 * duration)
        samples = self.monitor.finish_calibration(start, t)
        if len(samples) >= self.cfg.calib_min_samples:
            hr_rest = sum(samples) / len(samples)
            if hr_rest < self.hr_max:
                self._set_zone(hr_rest, "measured", "mean HR over calibration", len(samples), t,
                               window=(start, t))
                return
            reason = f"measured HR_rest {hr_rest:.1f} is not below HR_max {self.hr_max:.1f}"
        else:
            reason = (f"too few valid HR samples during calibration: {len(samples)} < "
                      f"{self.cfg.calib_min_samples}")
        self._set_zone(self.cfg.resting_default, "default", reason, len(samples), t)

    def _set_zone(self, hr_rest: float, source: str, reason: str, n: int, t: float,
                  window: tuple[float, float] | None = None) -> None:
        self.zone = HeartRateZone(hr_rest, self.hr_max, self.cfg.zone_low, self.cfg.zone_high)
        self.hr_rest_source = source
        self._emit({"t": t, "event": "calibration", "hr_rest": hr_rest, "source": source, "reason": reason,
                    "n_samples": n, "window": list(window) if window else None, "age": self.cfg.part_age})
        self._emit({"t": t, "event": "zone", **self.zone.as_dict()})
        self.say(self.cfg.speech_zone.format_map(self._variables()), "zone announcement")

    # --- hooks -------------------------------------------------------------------------------
    def _reminder(self, t: float) -> None:
        text = self.cfg.speech_calib_reminder.format_map(self._variables())
        self._emit({"event": "behaviour", "kind": "reminder", "text": self._redact(text)})
        self.say(text, "calibration reminder")

    def _encouraging_face(self, t: float) -> None:
        """Calibration: the robot's faces in turn, to keep the seated participant at ease."""
        emotion = self.cfg.emotion_calibration[self._faces % len(self.cfg.emotion_calibration)]
        self._faces += 1
        self._emit({"event": "behaviour", "kind": "encouragement", "emotion": emotion})
        self.command(SetEmotion(emotion), "calibration encouragement")

    def _behaviour(self, t: float) -> None:
        kind = self.rng.choice(BEHAVIOURS)
        fallback_from = None
        recent = self.monitor.recent_mean(t, self.cfg.hr_report_window)
        if kind == "hr_report" and recent is None:
            fallback_from = kind
            kind = self.rng.choice(BEHAVIOURS[:2])
        event: Event = {"event": "behaviour", "kind": kind}
        if fallback_from:
            event["fallback_from"] = fallback_from
            event["reason"] = f"no valid HR in the last {self.cfg.hr_report_window:g} s"
        if kind == "motivation":
            text = self.rng.choice(self.cfg.speech_motivation)
            event["text"] = text
            self._emit(event)
            self.say(text, "behaviour: motivation")
        elif kind == "emotion":
            emotion = self.rng.choice(self.cfg.emotion_motivation)
            event["emotion"] = emotion
            self._emit(event)
            self.command(SetEmotion(emotion), "behaviour: emotion")
        else:
            text = self.cfg.speech_hr_report.format_map(self._variables(hr=recent))
            event.update(text=text, hr=recent, window=self.cfg.hr_report_window)
            self._emit(event)
            self.say(text, "behaviour: heart-rate report")

    def _hold_for_late_heart_rate(self, t: float) -> float | None:
        """Hold the routine at a rule update that cannot wait on its own for late heart rate.

        A rule update decides on the heart rate taken before ``t`` and waits for it (``hr_wait``) while
        the routine goes on, except at the end of the activity: there it must be decided before the
        transition due at the same instant. So the routine waits there instead (nothing at or after
        ``t`` runs) until that heart rate has come, ``hr_wait`` at most; the decision and the transition
        then carry the time ``t``, as they do when the heart rate is on time.
        """
        due = self.engine.next_hook_due(RULE_UPDATE)
        # Sums of seconds at epoch times: equal to a few float steps (2.4e-7 s at 1.8e9 s).
        if due is None or abs(due - t) > SAME_INSTANT or self.engine.activity_end > t + SAME_INSTANT:
            return None
        if not self.monitor.window_complete(t) and self.clock() < t + self.cfg.hr_wait:
            self._held_at = t
            return t + self.cfg.hr_wait
        if self._held_at == t:
            self._held_wait = (t, self.clock() - t)  # for the decision's "waited"
        return None

    def _waited(self, t: float) -> float:
        """How long the rule update at ``t`` waited for late heart rate (the routine held, or not)."""
        held_t, held = self._held_wait
        return max(self.engine.now - t, held if held_t == t else 0.0)

    def _rule_update(self, t: float) -> None:
        """Decide now, or once the heart rate taken before ``t`` has arrived (``hr_wait``).

        The wait ends at the activity's end at the latest, so a decision is always about the
        activity that ran in its window (hooks run before the transition due at the same instant);
        at the activity's end itself the routine has waited for the heart rate instead
        (:meth:`_hold_for_late_heart_rate`).
        """
        deadline = min(t + self.cfg.hr_wait, self.engine.activity_end)
        if deadline <= t or self.monitor.window_complete(t):
            self._decide(t)
            return
        timer = self.engine.schedule(deadline, self._decide_pending, "rule update: heart rate late")
        self._pending_rule = (t, timer)

    def _check_pending(self, now: float) -> None:
        """The samples a waiting calibration or rule update needs have arrived (or stopped): decide at
        ``now``."""
        waiting = self._pending_calibration
        if waiting is not None and self.monitor.window_complete(waiting[0]):
            t, timer = waiting
            self.engine.cancel(timer)
            at = min(max(now, self.engine.now), timer.time)
            self._pending_calibration = (t, self.engine.schedule(at, self._finish_pending_calibration,
                                                                 "calibration"))
        if self._pending_rule is None or not self.monitor.window_complete(self._pending_rule[0]):
            return
        t, timer = self._pending_rule
        self.engine.cancel(timer)
        at = min(max(now, self.engine.now), timer.time)
        self._pending_rule = (t, self.engine.schedule(at, self._decide_pending, "rule update"))

    def _decide_pending(self) -> None:
        assert self._pending_rule is not None  # scheduled with it
        t, _ = self._pending_rule
        self._pending_rule = None
        self._decide(t)

    def _decide(self, t: float) -> None:
        stats = self.monitor.take(self._buffer_since, t)
        phase = self.engine.phase
        activity = self.engine.activity
        inputs = {**stats.as_dict(), "window": [self._buffer_since, t],
                  "waited": round(self._waited(t), 6), "newest_sample": self.monitor.newest_sample,
                  "hr_clock_offset": self.monitor.clock_offset, "phase": phase.name if phase else None,
                  "phase_kind": phase.kind if phase else None,
                  "activity": activity.name if activity else None,
                  # what the person does now: the slot's own activity, or the one run in its place
                  "performed": self.choice.current.name if self.choice.current else None,
                  "zone": [self.zone.low, self.zone.high] if self.zone else None,
                  "ladder_index": self.ladder.index}
        gate = (gates.Gate(gates.NO_ZONE, "no heart-rate zone yet") if self.zone is None
                else self.monitor.gate(stats, t))
        if gate is not None:
            decision = self.adapter.gated(t, gate.reason, stats.mean, gate=gate.code)
        else:
            assert self.zone is not None and stats.mean is not None and phase is not None  # gate and engine
            decision = self.adapter.update(RuleInput(
                t=t, hr=stats.mean, zone=self.zone, phase=phase.kind,
                phase_start=self.engine.phase_start, phase_end=self.engine.phase_end,
                controls=self._controls(self._buffer_since),
            ))
        self._buffer_since = t
        self.decisions.append(decision)
        self._emit({"t": t, "event": RULE_UPDATE, "inputs": inputs, "decision": decision.as_dict(),
                    "ladder": self.ladder.state()})
        if decision.notice == act.ZONE_GAP:
            self._emit({"t": t, "event": act.ZONE_GAP, "hr": decision.hr, "reason": decision.reason,
                        "ladder_index": decision.index_after, "activity_level": decision.level_after})
        switched = self._apply_level(decision)
        if not switched:
            self._speak_decision(decision)
        if decision.changed:
            self._resend_pace(f"rule update: {decision.action}", gesture=not switched)
            self.adapter.observe(t, self._controls(t))

    def _speak_decision(self, decision: Decision) -> None:
        cfg, action = self.cfg, decision.action
        if action == act.GATED:
            return  # nothing about pace without a trustworthy heart rate
        if action == act.SPEED_UP:
            lines = cfg.speech_faster
        elif action in (act.SLOW_DOWN,) or (action == act.AT_LIMIT and decision.proposed < 0):
            lines = cfg.speech_slower
        elif action == act.SCHEDULED_SLOW_DOWN:
            lines = cfg.speech_cooldown
        elif (action in (act.ENCOURAGE, act.HOLD, act.AT_LIMIT)
              or (action == act.CHANGE_ACTIVITY and decision.delta == 0)):
            lines = cfg.speech_motivation
        elif action == act.CHANGE_ACTIVITY:
            lines = cfg.speech_faster if decision.delta > 0 else cfg.speech_slower
        elif action == act.OUT_OF_REACH:
            self._say_out_of_reach(decision)
            return
        else:
            raise AssertionError(f"unhandled decision action {action}")
        self.say(self.rng.choice(lines), f"rule update: {action}")

    # --- policies that pick activities ---------------------------------------------------------
    def _controls(self, window_start: float) -> Controls:
        """What is performed now and what the coach may change, for the policy."""
        doing = self.choice.current if self.choice.current is not None else self.engine.activity
        return Controls(
            activity=doing.name if doing else None, mets=doing.mets if doing else None,
            chosen=self.adapter.level,
            levels=self.choice.levels(self.engine.phase) if self.adapter.chooses_activity else (),
            speeds=self.ladder.speeds, tempos=self._tempos, index=self.ladder.index,
            window_start=window_start,
            routine_costs=self._routine_costs if self.adapter.chooses_activity else (),
            runs_at=self.choice.runs_at(self.engine.phase) if self.adapter.chooses_activity else (),
        )

    def _plan_phase(self, phase: Phase, t: float) -> None:
        """A policy that plans phases sets this one up before its first activity's actions run."""
        decision = self._plan(phase, t)
        if decision is not None:
            self._speak_decision(decision)  # the first activity's own actions carry the new pace

    def _plan_late(self, phase: Phase, t: float) -> None:
        """The plan of a phase whose first activity already runs (the calibration before it waited for
        its last heart rate): applied as a rule update's decision is."""
        if self.engine.phase is not phase:
            return  # that phase is over already
        decision = self._plan(phase, t)
        if decision is None:
            return
        switched = self._apply_level(decision)
        if not switched:
            self._speak_decision(decision)
        if decision.changed:
            self._resend_pace(f"plan: {decision.action}", gesture=not switched)
            self.adapter.observe(self.engine.now, self._controls(self.engine.now))

    def _plan(self, phase: Phase, t: float) -> Decision | None:
        if self.zone is None:
            return None
        hr = self.monitor.last_hr if self.monitor.last_hr is not None else self.zone.target
        decision = self.adapter.plan(RuleInput(
            t=t, hr=hr, zone=self.zone, phase=phase.kind, phase_start=t, phase_end=t + phase.duration,
            controls=self._controls(self._buffer_since)))
        if decision is None:
            return None
        self.decisions.append(decision)
        self._emit({"event": "plan", "phase": phase.name, "decision": decision.as_dict(),
                    "ladder": self.ladder.state()})
        return decision

    def _speaks_for_replaced_slot(self, action: Action, ctx: ActionContext) -> bool:
        """A slot's own lines ("Back to marching") are not said while another activity runs in it."""
        slot = ctx.activity
        return (self.choice.running is not None and slot is not None and slot is self.engine.activity
                and any(action is a for a in slot.on_enter))

    def _apply_level(self, decision: Decision) -> bool:
        """The policy now holds another activity cost: switch the running activity if needed."""
        phase, slot = self.engine.phase, self.engine.activity
        if decision.level_after == decision.level_before or phase is None or slot is None:
            return False
        to = self.choice.switch(phase, slot, self.adapter.level)
        if to is None:
            return False
        why = f"rule update: {decision.action}"
        self._emit({"event": "activity_choice", "phase": phase.name, "slot": slot.name, "activity": to.name,
                    "mets": to.mets, "level": self.adapter.level, "reason": decision.reason})
        variables = self._variables(ActionContext(self.engine.now, phase, slot))
        video, gesture = to.attrs.get("video"), to.attrs.get("gesture")
        if video:
            self.command(SetVideo(self.cfg.video_path.format(video)), why)
            slot_start = self.engine.activity_start

            def splash() -> None:
                if self.engine.activity_start == slot_start:  # the same slot is still on
                    self.command(SetVideo(self.cfg.video_path.format(self.cfg.video_default)), why)

            self.engine.schedule(self.engine.now + self.cfg.video_time, splash, "video:splash")
        self.say(self.rng.choice(self.cfg.speech_activity_switch).format_map(variables), why)
        if gesture:
            self._play_gesture(str(gesture), self.ladder.speed, True, why)
        return True

    def _say_out_of_reach(self, decision: Decision) -> None:
        """Once per kind: the zone cannot be reached with the controls at hand (event + a line)."""
        notice = decision.notice or act.OUT_OF_REACH
        if notice in self._noticed:
            return
        self._noticed.add(notice)
        below = notice.endswith("below")
        text = self.cfg.speech_out_of_reach_below if below else self.cfg.speech_out_of_reach_above
        self._emit({"event": "zone_out_of_reach", "notice": notice,
                    "direction": "below" if below else "above", "hr": decision.hr,
                    "ladder_index": self.ladder.index, "activity_level": self.adapter.level,
                    "reason": decision.reason, "text": text})
        self.say(text, "zone out of reach")

    def _check_hr_timeout(self, now: float) -> None:
        start = self.engine.start_time if self.engine.start_time is not None else now
        change = self.monitor.check_timeout(now, start)
        if change == "lost":
            self._emit({"t": now, "event": "hr_lost", "silent_since": self.monitor.silent_since,
                        "timeout": self.cfg.hr_timeout,
                        "reason": f"no HR sample for more than {self.cfg.hr_timeout:g} s: adaptation paused, "
                                  "routine continues"})
        elif change == "resumed":
            self._emit({"t": now, "event": "hr_resumed", "reason": "HR samples are back: adaptation resumes"})

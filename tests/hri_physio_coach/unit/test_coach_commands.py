"""The coach's typed robot commands and the gate codes of its rule updates (fake clock, no ROS)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from hri_physio_coach import gates
from hri_physio_coach.coach import ExerciseCoach
from hri_physio_coach.config import CoachConfig
from hri_physio_coach.routine import parse_routine
from qt_controller.commands import SetAudio, SetGesture, SetSpeech, parse_command

WARM = 180.0


class Run:
    """A coach on a fake clock with one HR sample a second from ``hr(t)`` (None: no sample)."""

    def __init__(self, hr: Callable[[float], float | None], routine: dict | None = None,
                 **config: Any) -> None:
        self.now = 0.0
        self.events: list[dict[str, Any]] = []
        self.lines: list[str] = []
        self.hr = hr
        cfg = CoachConfig(**{"part_age": 33.0, **config})
        self.coach = ExerciseCoach(cfg, lambda: self.now, self.lines.append, self.events.append,
                                   parse_routine(routine) if routine is not None else None)

    def run(self, until: float | None = None) -> Run:
        if not self.coach.started:
            self.coach.start(0.0)
        while not self.coach.finished and (until is None or self.now < until):
            self.now += 1.0
            value = self.hr(self.now - 0.5)
            if value is not None:
                self.coach.on_hr(value, now=self.now - 0.5)
            self.coach.tick(self.now)
        return self

    def of(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e["event"] == kind]

    def decisions(self) -> list[dict[str, Any]]:
        return [e["decision"] for e in self.of("rule_update")]


def steady(t: float) -> float:
    return 85.0 if t < WARM else 140.0


def test_every_line_sent_is_a_typed_command_written_by_to_line() -> None:
    run = Run(lambda t: 85.0 if t < WARM else 110.0).run()  # below the zone: the ladder climbs
    assert run.coach.engine.state == "finished" and run.lines
    logged = [e["command"] for e in run.of("command")]
    assert run.lines == logged
    for line in run.lines:
        assert parse_command(line).to_line() == line  # canonical: what to_line writes
    gestures = [parse_command(line) for line in run.lines if line.startswith("set gesture")]
    assert SetGesture("base", 0.5) in gestures and SetGesture("marching", 1.0) in gestures
    audio = {parse_command(line) for line in run.lines if line.startswith("set audio")}
    assert SetAudio("beat:135") in audio  # the top of the ladder, the audio streamer's built-in beat
    assert not run.of("command_failed")


def test_commands_the_protocol_cannot_carry_are_reported_and_the_session_goes_on() -> None:
    routine = {"phases": [{"name": "p", "activities": [{"name": "a", "duration": 10, "on_enter": [
        {"volume": "loud"}, {"emotion": "very happy"}, {"gesture": "wave", "speed": "fast"},
        {"gesture": "wave", "speed": 9}, {"say": "   "}, {"say": "  Hello there  "}, {"emotion": "happy"},
    ]}]}]}
    run = Run(steady, routine, part_name="Jane").run()
    assert run.coach.engine.state == "finished"
    failed = run.of("command_failed")
    assert [e["source"] for e in failed] == ["build"] * 5
    assert [e["why"] for e in failed] == ["p/a"] * 5
    assert "whole number" in failed[0]["message"] and "takes 1 argument(s)" in failed[1]["message"]
    assert "gesture speed must be a number" in failed[2]["message"] and "out of range" in failed[3]["message"]
    assert "needs the text" in failed[4]["message"]
    routine_lines = [line for line in run.lines if "calibrations are complete" not in line]  # zone: default
    assert routine_lines == ["set speech Hello there", "set emotion happy"]  # stripped, as the protocol reads
    assert parse_command(routine_lines[0]) == SetSpeech("Hello there")


def test_build_failures_do_not_leak_the_name() -> None:
    routine = {"phases": [{"name": "p", "activities": [{"name": "a", "duration": 10, "on_enter": [
        {"emotion": "{name} smiles"}]}]}]}
    run = Run(steady, routine, part_name="Jane", address_by_name=True).run()
    (failed,) = run.of("command_failed")
    assert "Jane" not in str(failed) and "<name>" in failed["command"]


@pytest.mark.parametrize(
    "hr,code,reason",
    [
        (lambda t: 85.0 if t < WARM else float("nan"), gates.TOO_FEW_SAMPLES, "too few valid HR samples"),
        (lambda t: 85.0 if t < WARM else (250.0 if int(t) % 3 else 140.0), gates.SIGNAL_FLAGGED,
         "signal flagged"),
        (lambda t: 85.0 if t < WARM else None, gates.NO_HR_DATA, "no heart-rate data"),
    ],
    ids=["nan", "implausible", "silent"],
)
def test_gated_rule_updates_carry_their_gate_code(hr: Callable[[float], float | None], code: str,
                                                  reason: str) -> None:
    run = Run(hr).run(until=WARM + 100)
    decisions = run.decisions()
    assert decisions and all(d["action"] == "gated" for d in decisions)
    assert {d["gate"] for d in decisions} == {code} and all(reason in d["reason"] for d in decisions)
    assert code in gates.LABELS


def test_no_zone_gate_in_a_phase_before_calibration() -> None:
    routine = {"phases": [
        {"name": "calibration", "kind": "calibration", "hooks": ["rule_update"],
         "activities": [{"name": "sit", "duration": 70}], "on_exit": [{"call": "calibrate"}]},
        {"name": "warm_up", "hooks": ["rule_update"], "activities": [{"name": "march", "duration": 40}]},
    ]}
    run = Run(steady, routine).run()
    decisions = run.decisions()
    assert [d["gate"] for d in decisions[:2]] == [gates.NO_ZONE, gates.NO_ZONE]
    assert decisions[-1]["action"] != "gated" and decisions[-1]["gate"] is None


@pytest.mark.parametrize(
    "options,code",
    [
        ({"adapt_refractory": True, "adapt_refractory_period": 60.0}, gates.REFRACTORY),
        ({"adapt_conditioning_only": True}, gates.CONDITIONING_ONLY),
        ({"adapt_warmup_max_speedups": 1}, gates.WARMUP_CAP),
        ({"adapt_cooldown_schedule": True}, gates.COOLDOWN_SCHEDULE),
    ],
)
def test_held_rule_updates_carry_their_gate_code(options: dict[str, Any], code: str) -> None:
    run = Run(lambda t: 85.0 if t < WARM else 110.0, **options).run()  # below the zone all along
    held = [d for d in run.decisions() if d["action"] == "hold"]
    assert held and {d["gate"] for d in held} == {code}
    adapted = [d for d in run.decisions() if d["action"] in ("speed_up", "slow_down", "encourage")]
    assert all(d["gate"] is None for d in adapted)

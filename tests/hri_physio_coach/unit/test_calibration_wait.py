"""The calibration waits for the heart rate taken before its end, as a rule update does (``hr_wait``)."""

from __future__ import annotations

from typing import Any

import pytest

from hri_physio_coach.coach import ExerciseCoach, load_coach_routine
from hri_physio_coach.config import CoachConfig

CALIB = 60.0
#: The strap's own clock (LSL) runs this far ahead of the coach's.
AHEAD = 1000.0


class Run:
    """A coach on a fake clock; 1-Hz heart rate taken at k + 0.5, delivered ``delay(taken)`` later."""

    def __init__(self, delay, bpm=lambda taken: 70.0, stop_at: float = float("inf"),
                 skip: tuple[str, ...] = (), **config: Any) -> None:
        self.now = 0.0
        self.events: list[dict[str, Any]] = []
        self.commands: list[tuple[float, str]] = []
        cfg = CoachConfig(part_age=33.0, calib_time=CALIB, **config)
        routine = load_coach_routine(cfg).without(list(skip))
        self.coach = ExerciseCoach(cfg, lambda: self.now, lambda c: self.commands.append((self.now, c)),
                                   self.events.append, routine=routine)
        arrivals = [(k + 0.5 + delay(k + 0.5), k + 0.5) for k in range(400) if k + 0.5 < stop_at]
        self.arrivals = sorted(arrivals)
        self.bpm = bpm
        self.coach.start(0.0)

    def run(self, until: float, step: float = 0.1) -> Run:
        while self.now < until - 1e-9:
            self.now = round(self.now + step, 6)
            while self.arrivals and self.arrivals[0][0] <= self.now:
                arrival, taken = self.arrivals.pop(0)
                self.coach.on_hr(self.bpm(taken), now=arrival, source_t=taken + AHEAD)
            self.coach.tick(self.now)
        return self

    def of(self, event: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e["event"] == event]


def late_at_the_end(taken: float) -> float:
    """Delivered 0.05 s after it was taken, but the transport stalls from 3 s before the calibration's
    end until 2 s after it, then delivers what it held, in order."""
    return max(0.05, CALIB + 2.0 - taken) if taken >= CALIB - 3 else 0.05


def test_heart_rate_late_at_the_end_of_the_calibration_is_waited_for_and_averaged() -> None:
    # The last three samples of the calibration read 100 bpm: they move HR_rest only if they count.
    run = Run(late_at_the_end, bpm=lambda taken: 100.0 if CALIB - 3 <= taken < CALIB else 70.0)
    run.run(CALIB + 1.0)
    assert run.of("calibration") == [] and run.coach.next_decision() == CALIB  # waiting, the warm-up runs
    assert run.coach.engine.phase is not None and run.coach.engine.phase.kind == "warm_up"
    run.run(CALIB + 3.0)
    (calib,) = run.of("calibration")
    # Every sample taken from calib_settle (15 s) to the end: 45, three of them late.
    assert (calib["t"], calib["source"], calib["n_samples"]) == (CALIB, "measured", 45)
    assert calib["hr_rest"] == pytest.approx((42 * 70.0 + 3 * 100.0) / 45)
    assert calib["window"] == [15.0, CALIB]
    # Decided as the late samples came (at 62.0), not at the deadline (63).
    zone_said = [t for t, c in run.commands if "resting heart rate" in c]
    assert zone_said and CALIB + 2.0 <= zone_said[0] < CALIB + 2.2, run.commands
    assert not [e for e in run.of("calibration") if e["source"] == "default"]


def test_a_calibration_whose_heart_rate_stops_decides_at_its_deadline_on_what_came() -> None:
    run = Run(lambda taken: 0.05, stop_at=CALIB - 3.0).run(CALIB + 2.9)
    assert run.of("calibration") == []
    run.run(CALIB + 3.2)
    (calib,) = run.of("calibration")
    assert calib["n_samples"] == 42 and calib["source"] == "measured"
    assert len(run.of("zone")) == 1


def test_prompt_heart_rate_decides_at_the_end_of_the_phase() -> None:
    run = Run(lambda taken: 0.05).run(CALIB + 0.1)
    (calib,) = run.of("calibration")
    assert calib["n_samples"] == 45 and calib["t"] == CALIB
    assert run.coach.next_decision() != CALIB


def test_a_phase_planned_at_its_start_is_planned_once_the_zone_is_known() -> None:
    """Calibration straight into the cool-down: the predictive policy plans it the slowest step."""
    options = {"skip": ("warm_up", "conditioning"), "policy": "predictive", "speed_idx": 2}
    waited = Run(late_at_the_end, **options).run(CALIB + 5.0)
    prompt = Run(lambda taken: 0.05, **options).run(CALIB + 5.0)
    (plan,), (prompt_plan,) = waited.of("plan"), prompt.of("plan")
    assert plan["phase"] == "cool_down" and plan["decision"]["action"] == prompt_plan["decision"]["action"]
    assert plan["decision"]["index_after"] == prompt_plan["decision"]["index_after"] == 0
    order = [e["event"] for e in waited.events if e["event"] in ("calibration", "zone", "plan")]
    assert order == ["calibration", "zone", "plan"]
    # Applied when made: the music and the gesture follow the new pace after the zone is known.
    assert waited.coach.ladder.state() == prompt.coach.ladder.state()
    audio = [(t, c) for t, c in waited.commands if c.startswith("set audio") and t > CALIB]
    assert audio and audio[-1][0] >= CALIB + 2.0 and audio[-1][1] == [c for _, c in prompt.commands
                                                                        if c.startswith("set audio")][-1]

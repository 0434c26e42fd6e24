"""A simulated exercise participant: demand -> heart-rate kinetics (docs/PARTICIPANT_MODEL.md).

Demand comes from what the robot asks for (activity, music tempo, gesture
speed) through the ACSM stepping equation; heart rate follows it with a fast
(neural) and a slow component with dead time, plus cardiac drift. Parameters
marked "assumed" in docs/PARTICIPANT_MODEL.md are fields here so studies can sweep them.
No clock is read: the caller advances the model by explicit time steps.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields, replace
from typing import ClassVar

import numpy as np

REST_VO2 = 3.5  # ml/kg/min, one MET

#: Activities of the exercise routine, by the gesture name the robot plays.
STEPPING = {"step_up", "lateral", "arms_forward"}
MARCHING = {"marching"}
SEATED = {"base", "rest", "seated", ""}
#: Times (s) this close count as the same: absolute ROS times carry rounding of ~1e-7 s.
SAME_TIME = 1e-6
#: Shortest time (s) a person takes to take in an instruction before following it (``takes_effect``).
TAKE_IN_TIME = 1.5


@dataclass(frozen=True)
class ParticipantParams:
    age: float = 33.0
    female: bool = False
    hr_rest: float = 82.0
    hr_max_true: float = 185.0
    vo2max: float = 38.0  # ml/kg/min
    step_height: float = 0.15  # m (H)
    tempo_compliance: float = 0.6  # rho in [0.3, 1]
    gesture_gain: float = 0.25  # gamma in [0, 0.5] (assumed)
    marching_mets: float = 3.5  # at 120 BPM (assumed)
    arm_work: float = 0.10  # extra effort with both arms forward (Olson 1991)
    tau_fast: float = 10.0  # s
    tau_on: float = 60.0  # s
    tau_off: float = 75.0  # s
    dead_time: float = 8.0  # s
    drift_amplitude: float = 0.06  # A_d, fraction of HRR
    tau_drift: float = 1500.0  # s
    calibration_offset: float = 3.0  # bpm, seated anticipation (assumed)
    sdnn_rest: float = 0.045  # s
    artefact_rate: float = 0.005  # missed or extra beats in the reported RR
    #: The person takes up a new instruction at the next multiple of this period (s) from the session
    #: start (0: at once), docs/PARTICIPANT_MODEL.md "Reaction to instructions".
    reaction_period: float = 5.0
    #: The strap's 1-Hz heart rate: Gaussian jitter (SD, bpm) and the share of seconds with no report
    #: (0: none; the standard model has neither and draws no number for them).
    strap_jitter: float = 0.0
    dropout_rate: float = 0.0

    #: The participant model these parameters belong to (``hri_physio_evaluate --model``).
    model: ClassVar[str] = "standard"

    def make_kinetics(self, dt: float) -> HeartRateKinetics:
        """The heart-rate model of these parameters, stepped every ``dt`` s."""
        return HeartRateKinetics(self, dt)

    def settled_hr(self, activity: Activity) -> float:
        """Where heart rate settles (bpm) doing ``activity`` for long, cardiac drift left out."""
        u = demand(self, activity)
        return self.hr_rest + min(max(u, 0.0), 1.0) * (self.hr_max_true - self.hr_rest)

    def validate(self) -> None:
        problems = []
        for f in fields(self):  # every number finite (a NaN or inf ran as a NaN heart rate, or crashed)
            value = getattr(self, f.name)
            if isinstance(value, int | float) and not isinstance(value, bool) and not math.isfinite(value):
                problems.append(f"{f.name} must be a finite number, got {value}")
            elif f.name.startswith("tau") and isinstance(value, int | float) and value <= 0:
                problems.append(f"{f.name} must be > 0 s, got {value}")
        if problems:
            raise ValueError("invalid participant: " + "; ".join(problems))
        if self.step_height <= 0:
            problems.append(f"step_height must be > 0 m, got {self.step_height}")
        if self.marching_mets < 1:
            problems.append(f"marching_mets must be >= 1 (rest is 1 MET), got {self.marching_mets}")
        for name in ("arm_work", "gesture_gain", "drift_amplitude", "sdnn_rest"):
            if getattr(self, name) < 0:
                problems.append(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0 <= self.artefact_rate <= 1:
            problems.append(f"artefact_rate must be in [0, 1], got {self.artefact_rate}")
        if not 0 < self.age <= 120:
            problems.append(f"age must be in (0, 120], got {self.age}")
        if not 30 <= self.hr_rest < self.hr_max_true:
            problems.append(f"need 30 <= hr_rest < hr_max_true, got {self.hr_rest} / {self.hr_max_true}")
        if self.vo2max <= REST_VO2:
            problems.append(f"vo2max must exceed {REST_VO2} ml/kg/min, got {self.vo2max}")
        if self.dead_time < 0:
            problems.append("dead_time must be >= 0 s")
        if not 0 <= self.reaction_period < math.inf:
            problems.append(f"reaction_period must be >= 0 s, got {self.reaction_period}")
        if not 0 <= self.tempo_compliance <= 1:
            problems.append(f"tempo_compliance must be in [0, 1], got {self.tempo_compliance}")
        if self.strap_jitter < 0 or not 0 <= self.dropout_rate < 1:
            problems.append("need strap_jitter >= 0 bpm and dropout_rate in [0, 1)")
        if problems:
            raise ValueError("invalid participant: " + "; ".join(problems))


def sample_population(n: int, seed: int, age_range: tuple[float, float] = (20.0, 50.0)
                      ) -> list[ParticipantParams]:
    """A seeded cohort drawn from the distributions of docs/PARTICIPANT_MODEL.md."""
    rng = np.random.default_rng(seed)
    people = []
    for _ in range(n):
        age = rng.uniform(*age_range)
        female = bool(rng.random() < 0.5)
        fitness = rng.uniform(0.75, 1.3)
        hr_max = 208.0 - 0.7 * age + rng.normal(0.0, 7.0)
        # Fitter people rest lower: shift the resting HR by fitness.
        hr_rest = float(np.clip(rng.normal(72.0, 9.0) - 10.0 * (fitness - 1.0), 50.0, 100.0))
        vo2max = (47.0 - 0.35 * (age - 20.0)) * (0.82 if female else 1.0) * fitness
        people.append(ParticipantParams(
            age=age, female=female, hr_rest=hr_rest, hr_max_true=hr_max, vo2max=vo2max,
            step_height=rng.uniform(0.10, 0.20), tempo_compliance=rng.uniform(0.3, 1.0),
            gesture_gain=rng.uniform(0.0, 0.5),
            tau_on=float(np.clip(rng.normal(60.0, 20.0), 20.0, 120.0)),
            tau_off=float(np.clip(rng.normal(75.0, 20.0), 25.0, 140.0)),
            drift_amplitude=rng.uniform(0.03, 0.12),
            sdnn_rest=float(np.clip(rng.normal(0.045, 0.015), 0.015, 0.09)),
            calibration_offset=rng.normal(3.0, 3.0),
        ))
    return people


@dataclass(frozen=True)
class Activity:
    """What the participant is doing: the robot's gesture, its speed, the music tempo."""

    name: str = "rest"
    tempo_bpm: float = 120.0
    gesture_speed: float = 1.0

    def with_(self, **changes: object) -> Activity:
        return replace(self, **changes)  # type: ignore[arg-type]


def net_vo2(p: ParticipantParams, activity: Activity) -> float:
    """Oxygen cost above rest (ml/kg/min) of an activity for this participant."""
    if activity.name in SEATED:
        return 0.0
    cadence = 120.0 + p.tempo_compliance * (activity.tempo_bpm - 120.0)
    if activity.name in MARCHING:
        net = (p.marching_mets - 1.0) * REST_VO2 * cadence / 120.0
    elif activity.name in STEPPING:
        f = cadence / 4.0  # one cycle (up-up-down-down) = 4 beats
        net = 0.2 * f + 1.33 * 1.8 * p.step_height * f
        if activity.name == "arms_forward":
            net *= 1.0 + p.arm_work
    else:
        raise ValueError(f"unknown activity {activity.name!r}")
    return net * max(0.0, 1.0 + p.gesture_gain * (activity.gesture_speed - 1.0))


def demand(p: ParticipantParams, activity: Activity) -> float:
    """Demand u as a fraction of the oxygen-uptake reserve (~ fraction of HRR, ACSM)."""
    return net_vo2(p, activity) / (p.vo2max - REST_VO2)


def takes_effect(heard: float, session_start: float | None, period: float) -> float | None:
    """When a person who heard an instruction at ``heard`` starts following it (None: at once).

    The person takes :data:`TAKE_IN_TIME` to take the instruction in, then changes on the next
    multiple of ``period`` counted from the session start: the change happens at the same moment
    whether the instruction took a millisecond or a few seconds to arrive (or the listener's clock
    was a moment behind the sender's), so the evaluation and a closed loop on a busy machine run the
    same physiology. Before the session start is known, or with ``period`` 0, at once.
    """
    if session_start is None or period <= 0:
        return None
    marks = math.floor((heard + TAKE_IN_TIME - session_start + SAME_TIME) / period) + 1
    return session_start + marks * period


class HeartRateKinetics:
    """Two parallel first-order components (fast neural, slow with dead time) plus drift."""

    def __init__(self, params: ParticipantParams, dt: float = 0.1) -> None:
        params.validate()
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.p = params
        self.dt = dt
        self.x_fast = 0.0
        self.x_slow = 0.0
        self.x_drift = 0.0
        self.u = 0.0
        self.seated = True
        # Demand history for the slow component's dead time.
        self._delay: deque[float] = deque([0.0] * (round(params.dead_time / dt) + 1))

    @property
    def fraction_hrr(self) -> float:
        return self.x_fast + self.x_slow + self.x_drift

    @property
    def hr(self) -> float:
        p = self.p
        hr = p.hr_rest + self.fraction_hrr * (p.hr_max_true - p.hr_rest)
        if self.seated:
            hr += p.calibration_offset
        return min(hr, p.hr_max_true)

    def set_activity(self, p_activity: Activity) -> None:
        self.u = demand(self.p, p_activity)
        self.seated = p_activity.name in SEATED

    def step(self) -> float:
        """Advance by dt; returns the heart rate (bpm) at the end of the step."""
        return self.run(1)[0][0]

    def run(self, n: int) -> tuple[list[float], list[float]]:
        """Advance ``n`` steps of an unchanged activity: the heart rate (bpm) and the fraction of HRR
        at the end of each. One loop over local names, the same arithmetic as n single steps: the model
        steps ten times a model second, and a method call per step was a third of an evaluation's time."""
        p, dt, u, delay = self.p, self.dt, self.u, self._delay
        fast_in, tau_fast, tau_on, tau_off, tau_drift = 0.35 * u, p.tau_fast, p.tau_on, p.tau_off, p.tau_drift
        drive = p.drift_amplitude * max(0.0, (u - 0.3) / 0.4)
        hr_rest, hr_max = p.hr_rest, p.hr_max_true
        hrr = hr_max - hr_rest
        offset = p.calibration_offset if self.seated else 0.0
        x_fast, x_slow, x_drift = self.x_fast, self.x_slow, self.x_drift
        hrs: list[float] = []
        fractions: list[float] = []
        for _ in range(n):
            delay.append(u)
            u_delayed = delay.popleft()
            x_fast += dt * (fast_in - x_fast) / tau_fast
            target = 0.65 * u_delayed
            x_slow += dt * (target - x_slow) / (tau_on if target > x_slow else tau_off)
            x_drift += dt * (drive - x_drift) / tau_drift
            fraction = x_fast + x_slow + x_drift
            hr = hr_rest + fraction * hrr
            if offset:
                hr += offset
            hrs.append(hr_max if hr_max < hr else hr)  # min(hr, hr_max)
            fractions.append(fraction)
        self.x_fast, self.x_slow, self.x_drift = x_fast, x_slow, x_drift
        return hrs, fractions


def breathing_rate(fraction_hrr: float) -> float:
    """Breathing frequency (Hz): about 0.25 at rest rising to about 0.6 at high intensity."""
    return 0.25 + 0.35 * min(max(fraction_hrr, 0.0), 1.0)


def rr_sd(p: ParticipantParams, hr: float) -> float:
    """SD of RR (s): halves for every +20 bpm above rest (Mongin 2022)."""
    return p.sdnn_rest * math.pow(2.0, -(hr - p.hr_rest) / 20.0)

"""Alternative participant models, written independently of the standard one (docs/PARTICIPANT_MODEL.md).

The coach, the routine, the perception of robot commands and the strap's beats stay as they are;
each model replaces the *heart*: how an activity's oxygen cost becomes a heart rate and how fast
heart rate gets there. A model is a :class:`~hri_physio_coach.participant.physiology.ParticipantParams`
subclass (its ``model`` name, its own fields, ``make_kinetics`` and ``settled_hr``) plus a population
sampler, so a :class:`~hri_physio_coach.participant.cardiac.ParticipantSimulator` runs any of them and
the evaluation (``--model``) and the ``simulated_participant`` node (``model`` option) run the same code.

``vagal`` (:class:`VagalParams`, :class:`VagalKinetics`): HR-VO2 steady state (%HRR = %VO2R, ACSM;
Swain & Leutholtz 1997) with the ACSM stepping equation, partial tempo adherence and a personal cadence
cap; a per-person spread of each activity's cost around its MET label (Byrne et al. 2005; lateral knee
lifts and step-ups share a label but not a cost); arm work
raising HR more per unit of oxygen than leg work (Astrand & Saltin 1961); an on-response whose fast
(vagal-withdrawal) part is capped at the intrinsic heart rate (Jose & Collison 1970) and whose slow
part (tau 40-90 s, dead time 2-10 s) carries the rest; an off-response 1.2-2x slower; linear
cardiovascular drift 0.1-0.3 bpm/min (Coyle & Gonzalez-Alonso 2001); an arrival 0-10 bpm above rest
that fades; HRmax from Tanaka et al. 2001 (SD 10 bpm); strap jitter and dropouts.

``vo2drive`` (:class:`Vo2Params`, :class:`Vo2Kinetics`): oxygen uptake is the state. VO2 follows the
demand with a cardiodynamic phase I and a phase II time constant that grows with intensity and falls with
fitness, plus a slow component above the ventilatory threshold (Gaesser & Poole 1996; Jones & Poole 2005);
heart rate is %HRmax = 0.64 %VO2max + 37 (Swain et al. 1994), anchored at the person's rest, reached
through a short cardiac lag; the cadence is entrained only partly from the person's own preferred
cadence; marching costs the leg-lift work of its knee height (the ACSM vertical-work constant) plus a
walking-in-place term; drift grows with the work done above 30 % VO2max (thermal, Coyle &
Gonzalez-Alonso 2001); HRmax from Gellish et al. 2007.

No clock is read: the caller steps the kinetics.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hri_physio_coach.participant.physiology import (
    MARCHING,
    REST_VO2,
    SEATED,
    STEPPING,
    Activity,
    HeartRateKinetics,
    ParticipantParams,
    sample_population,
)

#: Activities with arm work (both arms forward while stepping).
ARM_ACTIVITIES = {"arms_forward"}
#: Stepping sideways with a knee lift: labelled as costly as a step-up, but another movement.
LATERAL = {"lateral"}
#: ACSM: oxygen cost of raising 1 kg by 1 m (ml O2), of a step cycle's horizontal part per cycle (ml/kg).
VERTICAL_COST = 1.8
STEP_HORIZONTAL = 0.2
#: Lowering is cheaper than raising: the ACSM stepping equation counts it as a third of the raising.
LOWERING_SHARE = 0.33
#: Oxygen cost per step of marching in place beyond lifting the leg (ml/kg): swinging and balancing; with a
#: 0.13 m knee lift at 120 steps/min marching then costs about 3.5 METs (Compendium of Physical Activities).
WALK_IN_PLACE = 0.02


def intrinsic_hr(age: float) -> float:
    """Heart rate with both autonomic branches blocked (bpm): 118.1 - 0.57 age (Jose & Collison 1970)."""
    return 118.1 - 0.57 * age


def tanaka_hr_max(age: float) -> float:
    """Age-predicted HRmax (bpm), Tanaka, Monahan & Seals 2001: 208 - 0.7 age."""
    return 208.0 - 0.7 * age


def gellish_hr_max(age: float) -> float:
    """Age-predicted HRmax (bpm), Gellish et al. 2007: 207 - 0.7 age."""
    return 207.0 - 0.7 * age


def acsm_stepping_vo2(step_height: float, cycles_per_min: float) -> float:
    """Gross VO2 (ml/kg/min) of stepping, ACSM: 0.2 f + 1.33 (1.8 H f) + 3.5."""
    return (STEP_HORIZONTAL * cycles_per_min + (1.0 + LOWERING_SHARE) * VERTICAL_COST * step_height
            * cycles_per_min + REST_VO2)


# --- model "vagal" ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VagalParams(ParticipantParams):
    """A person of the ``vagal`` model (the inherited fields keep their meaning where used)."""

    cadence_cap: float = 132.0  # beats/min the person can step to at most
    marching_cost: float = 1.0  # the person's cost of marching / its MET label
    stepping_cost: float = 1.0  # the person's cost of stepping / the ACSM equation
    lateral_cost: float = 1.0  # the person's cost of lateral knee lifts / of their step-ups (the same label)
    arm_hr_gain: float = 1.3  # HR per unit of oxygen of arm work / of leg work
    tau_vagal: float = 4.0  # s, the fast (vagal) part
    off_factor: float = 1.5  # off-response time constants / on-response ones
    drift_rate: float = 0.2  # bpm/min while exercising at >= 40 % VO2R
    arrival_offset: float = 5.0  # bpm above rest on arrival, fading with the off time constant

    model: ClassVar[str] = "vagal"

    def cadence(self, tempo: float) -> float:
        """Step cadence (beats/min): a share of the tempo change from 120, at most the personal cap."""
        return min(120.0 + self.tempo_compliance * (tempo - 120.0), self.cadence_cap)

    def costs(self, activity: Activity) -> tuple[float, float]:
        """(leg, arm) net VO2 (ml/kg/min) of ``activity`` for this person."""
        if activity.name in SEATED:
            return 0.0, 0.0
        cadence = self.cadence(activity.tempo_bpm)
        pace = max(0.0, 1.0 + self.gesture_gain * (activity.gesture_speed - 1.0))
        if activity.name in MARCHING:
            return (self.marching_mets - 1.0) * REST_VO2 * cadence / 120.0 * self.marching_cost * pace, 0.0
        if activity.name in STEPPING:
            legs = (acsm_stepping_vo2(self.step_height, cadence / 4.0) - REST_VO2) * self.stepping_cost * pace
            if activity.name in LATERAL:
                legs *= self.lateral_cost
            arms = legs * self.arm_work if activity.name in ARM_ACTIVITIES else 0.0
            return legs, arms
        raise ValueError(f"unknown activity {activity.name!r}")

    def target_rise(self, activity: Activity) -> float:
        """Steady-state rise above rest (bpm): %HRR = %VO2R, arm oxygen counted ``arm_hr_gain`` times."""
        legs, arms = self.costs(activity)
        share = (legs + self.arm_hr_gain * arms) / (self.vo2max - REST_VO2)
        return min(max(share, 0.0), 1.0) * (self.hr_max_true - self.hr_rest)

    def settled_hr(self, activity: Activity) -> float:
        return self.hr_rest + self.target_rise(activity)

    def make_kinetics(self, dt: float) -> HeartRateKinetics:
        return VagalKinetics(self, dt)  # type: ignore[return-value]


class VagalKinetics:
    """Fast vagal part up to the intrinsic heart rate, slow part with dead time for the rest, and drift."""

    def __init__(self, params: VagalParams, dt: float = 0.1) -> None:
        params.validate()
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.p = params
        self.dt = dt
        self.vagal_room = max(intrinsic_hr(params.age) - params.hr_rest, 0.0)
        self.fast = 0.0  # bpm above rest
        self.slow = 0.0
        self.drift = 0.0
        self.arrival = params.arrival_offset
        self.rise = 0.0
        self.intensity = 0.0  # fraction of VO2R
        self.seated = True
        self._delay: deque[float] = deque([0.0] * (round(params.dead_time / dt) + 1))

    @property
    def hrr(self) -> float:
        return self.p.hr_max_true - self.p.hr_rest

    @property
    def hr(self) -> float:
        p = self.p
        return min(p.hr_rest + self.fast + self.slow + self.drift + self.arrival, p.hr_max_true)

    @property
    def fraction_hrr(self) -> float:
        return (self.hr - self.p.hr_rest) / self.hrr

    def set_activity(self, activity: Activity) -> None:
        self.rise = self.p.target_rise(activity)
        self.intensity = self.rise / self.hrr
        self.seated = activity.name in SEATED

    def step(self) -> float:
        return self.run(1)[0][0]

    def run(self, n: int) -> tuple[list[float], list[float]]:
        """Advance ``n`` steps of an unchanged activity: heart rate and fraction of HRR after each
        (as :meth:`HeartRateKinetics.run`, one loop over local names)."""
        p, dt, delay = self.p, self.dt, self._delay
        fast_target = min(self.rise, self.vagal_room)
        slow_in = self.rise - fast_target
        tau_fast_on, tau_fast_off = p.tau_vagal, p.tau_vagal * p.off_factor
        tau_on, tau_off = p.tau_on, p.tau_on * p.off_factor
        drift_step = dt / 60.0 * p.drift_rate * min(self.intensity / 0.4, 1.0) if not self.seated else None
        hr_rest, hr_max = p.hr_rest, p.hr_max_true
        hrr = hr_max - hr_rest
        fast, slow, drift, arrival = self.fast, self.slow, self.drift, self.arrival
        hrs: list[float] = []
        fractions: list[float] = []
        for _ in range(n):
            fast += dt * (fast_target - fast) / (tau_fast_on if fast_target >= fast else tau_fast_off)
            delay.append(slow_in)
            slow_target = delay.popleft()
            slow += dt * (slow_target - slow) / (tau_on if slow_target >= slow else tau_off)
            if drift_step is not None:
                drift += drift_step
            else:
                drift -= dt * drift / tau_off
            arrival -= dt * arrival / tau_off
            hr = hr_rest + fast + slow + drift + arrival
            if hr_max < hr:  # min(hr, hr_max)
                hr = hr_max
            hrs.append(hr)
            fractions.append((hr - hr_rest) / hrr)
        self.fast, self.slow, self.drift, self.arrival = fast, slow, drift, arrival
        return hrs, fractions


def sample_vagal(n: int, seed: int, age_range: tuple[float, float] = (20.0, 50.0)) -> list[VagalParams]:
    """A seeded cohort of the ``vagal`` model (docs/PARTICIPANT_MODEL.md, "Alternative models")."""
    rng = np.random.default_rng([seed, 0xA6A1])
    own = np.random.default_rng([seed, 0xA6A2])  # per-activity spread; the other draws stay as they were
    people = []
    for _ in range(n):
        age = float(rng.uniform(*age_range))
        female = bool(rng.random() < 0.5)
        # VO2max (ml/kg/min) falls ~0.4/yr; women ~15 % lower; wide spread of fitness (ACSM norms).
        vo2max = float(np.clip(rng.normal(48.0 - 0.4 * (age - 20.0), 7.0) * (0.85 if female else 1.0),
                               22.0, 65.0))
        hr_rest = float(np.clip(rng.normal(70.0, 9.0) - 0.3 * (vo2max - 40.0), 48.0, 100.0))
        hr_max = float(np.clip(tanaka_hr_max(age) + rng.normal(0.0, 10.0), hr_rest + 60.0, 220.0))
        tau_on = float(rng.uniform(40.0, 90.0))
        people.append(VagalParams(
            age=age, female=female, hr_rest=hr_rest, hr_max_true=hr_max, vo2max=vo2max,
            step_height=float(rng.uniform(0.10, 0.20)), tempo_compliance=float(rng.uniform(0.2, 0.9)),
            gesture_gain=float(rng.uniform(0.0, 0.3)), marching_mets=3.5,
            arm_work=float(rng.uniform(0.05, 0.2)),
            tau_on=tau_on, tau_off=tau_on, dead_time=float(rng.uniform(2.0, 10.0)),
            calibration_offset=0.0, sdnn_rest=float(np.clip(rng.normal(0.045, 0.015), 0.015, 0.09)),
            strap_jitter=float(rng.uniform(0.5, 2.0)), dropout_rate=float(rng.uniform(0.0, 0.03)),
            cadence_cap=float(rng.uniform(118.0, 140.0)),
            marching_cost=float(np.clip(rng.normal(1.0, 0.2), 0.6, 1.5)),
            stepping_cost=float(np.clip(rng.normal(1.0, 0.15), 0.7, 1.4)),
            arm_hr_gain=float(rng.uniform(1.1, 1.5)), tau_vagal=float(rng.uniform(2.0, 6.0)),
            off_factor=float(rng.uniform(1.2, 2.0)), drift_rate=float(rng.uniform(0.1, 0.3)),
            arrival_offset=float(rng.uniform(0.0, 10.0)),
            lateral_cost=float(np.clip(own.normal(1.0, 0.1), 0.8, 1.2)),
        ))
    return people


# --- model "vo2drive" ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Vo2Params(ParticipantParams):
    """A person of the ``vo2drive`` model (the inherited fields keep their meaning where used)."""

    preferred_cadence: float = 115.0  # beats/min the person steps to unprompted
    knee_lift: float = 0.13  # m each knee is raised when marching
    leg_mass: float = 0.17  # fraction of body mass in one leg
    efficiency: float = 1.0  # the person's oxygen cost / the equations' (movement economy)
    tau_vo2: float = 30.0  # s, phase II at moderate intensity
    phase1_share: float = 0.2  # cardiodynamic phase I: this share of the change at once
    vt_fraction: float = 0.55  # ventilatory threshold, fraction of VO2max
    slow_gain: float = 0.12  # extra VO2 above VT, share of the supra-threshold amplitude
    tau_heart: float = 8.0  # s, heart rate following oxygen uptake
    drift_gain: float = 0.5  # bpm/min per unit of VO2max fraction above 0.3
    arm_hr_extra: float = 10.0  # bpm more with both arms forward at the same VO2

    model: ClassVar[str] = "vo2drive"

    def cadence(self, tempo: float) -> float:
        """The person's cadence: entrained only partly, from their own preferred cadence."""
        return self.preferred_cadence + self.tempo_compliance * (tempo - self.preferred_cadence)

    def net_vo2(self, activity: Activity) -> float:
        """Net VO2 (ml/kg/min) of ``activity``; gesture speed scales the range of motion."""
        if activity.name in SEATED:
            return 0.0
        cadence = self.cadence(activity.tempo_bpm)
        motion = max(0.0, 1.0 + self.gesture_gain * (activity.gesture_speed - 1.0))
        if activity.name in MARCHING:
            lift = (1.0 + LOWERING_SHARE) * VERTICAL_COST * self.leg_mass * self.knee_lift * motion
            net = cadence * (lift + WALK_IN_PLACE)  # ml/kg per step: leg lift plus walking in place
        elif activity.name in STEPPING:
            net = (acsm_stepping_vo2(self.step_height, cadence / 4.0) - REST_VO2) * motion
            if activity.name in ARM_ACTIVITIES:
                net *= 1.0 + self.arm_work
        else:
            raise ValueError(f"unknown activity {activity.name!r}")
        return net * self.efficiency

    def steady_vo2(self, activity: Activity) -> float:
        """Gross VO2 after the slow component has developed (ml/kg/min), at most VO2max."""
        vo2 = REST_VO2 + self.net_vo2(activity)
        vt = self.vt_fraction * self.vo2max
        if vo2 > vt:
            vo2 += self.slow_gain * (vo2 - vt)
        return min(vo2, self.vo2max)

    def hr_of_vo2(self, vo2: float) -> float:
        """%HRmax = 0.64 %VO2max + 37 (Swain 1994), anchored at this person's resting heart rate."""
        return self.hr_rest + 0.64 * self.hr_max_true * (vo2 - REST_VO2) / self.vo2max

    def settled_hr(self, activity: Activity) -> float:
        extra = self.arm_hr_extra if activity.name in ARM_ACTIVITIES else 0.0
        return min(self.hr_of_vo2(self.steady_vo2(activity)) + extra, self.hr_max_true)

    def make_kinetics(self, dt: float) -> HeartRateKinetics:
        return Vo2Kinetics(self, dt)  # type: ignore[return-value]


class Vo2Kinetics:
    """VO2 (phase I, phase II, slow component) -> heart rate (Swain) through a short lag, plus drift."""

    PHASE1_DELAY = 15.0  # s: phase II starts after the cardiodynamic phase
    SLOW_DELAY = 90.0  # s: the slow component emerges after this much time above VT
    TAU_SLOW = 240.0  # s

    def __init__(self, params: Vo2Params, dt: float = 0.1) -> None:
        params.validate()
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.p = params
        self.dt = dt
        self.target = 0.0  # net VO2 asked for (ml/kg/min), without the slow component
        self.phase1 = 0.0
        self.phase2 = 0.0
        self.slow = 0.0
        self.above_vt_for = 0.0
        self.heart = params.hr_rest
        self.drift = 0.0
        self.arm = 0.0
        self.arm_target = 0.0
        self.seated = True
        self._delay: deque[float] = deque([0.0] * (round(self.PHASE1_DELAY / dt) + 1))

    @property
    def vo2(self) -> float:
        return REST_VO2 + self.phase1 + self.phase2 + self.slow

    @property
    def hr(self) -> float:
        hr = self.heart + self.drift + self.arm
        if self.seated:
            hr += self.p.calibration_offset
        return min(hr, self.p.hr_max_true)

    @property
    def fraction_hrr(self) -> float:
        return (self.hr - self.p.hr_rest) / (self.p.hr_max_true - self.p.hr_rest)

    def set_activity(self, activity: Activity) -> None:
        self.target = self.p.net_vo2(activity)
        self.arm_target = self.p.arm_hr_extra if activity.name in ARM_ACTIVITIES else 0.0
        self.seated = activity.name in SEATED

    def step(self) -> float:
        return self.run(1)[0][0]

    def run(self, n: int) -> tuple[list[float], list[float]]:
        """Advance ``n`` steps of an unchanged activity: heart rate and fraction of HRR after each
        (as :meth:`HeartRateKinetics.run`, one loop over local names)."""
        p, dt, delay, target = self.p, self.dt, self._delay, self.target
        share = p.phase1_share
        phase1_in, phase2_in = share * target, (1.0 - share) * target
        intensity = (REST_VO2 + target) / p.vo2max
        # Phase II is slower at higher intensity (above VT) and for less fit people; recovery slightly slower.
        tau_up = p.tau_vo2 * (1.0 + 0.5 * max(0.0, intensity - p.vt_fraction) / (1.0 - p.vt_fraction))
        tau_down = tau_up * 1.2
        vt, vo2max, slow_gain = p.vt_fraction * p.vo2max, p.vo2max, p.slow_gain
        reserve = vo2max - REST_VO2
        hr_rest, hr_max, tau_heart, arm_target = p.hr_rest, p.hr_max_true, p.tau_heart, self.arm_target
        swain = 0.64 * p.hr_max_true  # p.hr_of_vo2, spelled out
        drift_step = dt / 60.0 * p.drift_gain
        seated, offset = self.seated, p.calibration_offset
        hrr = hr_max - hr_rest
        slow_delay, tau_slow = self.SLOW_DELAY, self.TAU_SLOW
        phase1, phase2, slow, above_vt_for = self.phase1, self.phase2, self.slow, self.above_vt_for
        heart, arm, drift = self.heart, self.arm, self.drift
        hrs: list[float] = []
        fractions: list[float] = []
        for _ in range(n):
            phase1 += dt * (phase1_in - phase1) / 5.0
            delay.append(phase2_in)
            delayed = delay.popleft()
            phase2 += dt * (delayed - phase2) / (tau_down if delayed < phase2 else tau_up)
            excess = REST_VO2 + phase1 + phase2 - vt
            above_vt_for = above_vt_for + dt if excess > 0 else 0.0
            slow_target = slow_gain * excess if excess > 0 and above_vt_for > slow_delay else 0.0
            slow += dt * (slow_target - slow) / tau_slow
            room = reserve - phase1 - phase2
            cap = 0.0 if room < 0.0 else room  # max(room, 0.0)
            if cap < slow:  # min(slow, cap)
                slow = cap
            vo2 = REST_VO2 + phase1 + phase2 + slow
            heart += dt * (hr_rest + swain * (vo2 - REST_VO2) / vo2max - heart) / tau_heart
            arm += dt * (arm_target - arm) / tau_heart
            work = vo2 / vo2max - 0.3
            drift += drift_step * (work if work > 0.0 else 0.0)  # max(0.0, work)
            if seated:
                drift -= dt * drift / 300.0
            hr = heart + drift + arm
            if seated:
                hr += offset
            if hr_max < hr:  # min(hr, hr_max)
                hr = hr_max
            hrs.append(hr)
            fractions.append((hr - hr_rest) / hrr)
        self.phase1, self.phase2, self.slow, self.above_vt_for = phase1, phase2, slow, above_vt_for
        self.heart, self.arm, self.drift = heart, arm, drift
        return hrs, fractions


def sample_vo2drive(n: int, seed: int, age_range: tuple[float, float] = (20.0, 50.0)) -> list[Vo2Params]:
    """A seeded cohort of the ``vo2drive`` model (docs/PARTICIPANT_MODEL.md, "Alternative models")."""
    rng = np.random.default_rng([seed, 0x0702])
    people = []
    for _ in range(n):
        age = float(rng.uniform(*age_range))
        female = bool(rng.random() < 0.5)
        vo2max = float(np.clip(rng.normal(45.0 - 0.35 * (age - 20.0), 8.0) * (0.82 if female else 1.0),
                               20.0, 65.0))
        fit = (vo2max - 38.0) / 10.0
        hr_rest = float(np.clip(rng.normal(72.0, 8.0) - 4.0 * fit, 48.0, 100.0))
        hr_max = float(np.clip(gellish_hr_max(age) + rng.normal(0.0, 7.0), hr_rest + 60.0, 220.0))
        people.append(Vo2Params(
            age=age, female=female, hr_rest=hr_rest, hr_max_true=hr_max, vo2max=vo2max,
            step_height=float(rng.uniform(0.10, 0.20)), tempo_compliance=float(rng.uniform(0.3, 0.9)),
            gesture_gain=float(rng.uniform(0.0, 0.4)), arm_work=float(rng.uniform(0.05, 0.2)),
            calibration_offset=float(rng.normal(2.0, 2.0)),
            sdnn_rest=float(np.clip(rng.normal(0.045, 0.015), 0.015, 0.09)),
            strap_jitter=float(rng.uniform(0.3, 1.5)), dropout_rate=float(rng.uniform(0.0, 0.02)),
            preferred_cadence=float(rng.normal(114.0, 8.0)), knee_lift=float(rng.uniform(0.08, 0.18)),
            leg_mass=float(rng.uniform(0.15, 0.19)),
            efficiency=float(np.clip(rng.normal(1.0, 0.12), 0.75, 1.3)),
            tau_vo2=float(np.clip(rng.normal(45.0 - 8.0 * fit, 8.0), 18.0, 75.0)),
            phase1_share=float(rng.uniform(0.1, 0.3)), vt_fraction=float(rng.uniform(0.45, 0.65)),
            slow_gain=float(rng.uniform(0.05, 0.2)), tau_heart=float(rng.uniform(4.0, 15.0)),
            drift_gain=float(rng.uniform(0.3, 0.9)), arm_hr_extra=float(rng.uniform(4.0, 15.0)),
        ))
    return people


# --- the registry -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ModelInfo:
    name: str
    params: type[ParticipantParams]
    sample: Callable[[int, int, tuple[float, float]], list[ParticipantParams]]
    about: str
    #: The fields of the sensitivity table's assumptions the model's heart uses; None: all of them. A
    #: sensitivity sweep moves only these (moving a field the model ignores would show nothing).
    uses: frozenset[str] | None = None


MODELS: dict[str, ModelInfo] = {
    "standard": ModelInfo("standard", ParticipantParams, sample_population,  # type: ignore[arg-type]
                          "the project's model: fast 35 % + slow part, ACSM stepping"),
    "vagal": ModelInfo("vagal", VagalParams, sample_vagal,  # type: ignore[arg-type]
                       "fast vagal part capped at the intrinsic HR, slow part, linear drift, cadence cap",
                       frozenset({"tempo_compliance", "gesture_gain", "tau_on", "dead_time", "marching_mets",
                                  "arm_work", "step_height", "lateral_cost"})),
    "vo2drive": ModelInfo("vo2drive", Vo2Params, sample_vo2drive,  # type: ignore[arg-type]
                          "VO2 kinetics (phase I/II, slow component) -> HR by Swain's %HRmax-%VO2max",
                          frozenset({"tempo_compliance", "gesture_gain", "calibration_offset", "arm_work",
                                     "step_height"})),
}
MODEL_NAMES = tuple(MODELS)


def model_info(name: str) -> ModelInfo:
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown participant model {name!r}; choose one of "
                         f"{', '.join(MODEL_NAMES)}") from None


def as_model(params: ParticipantParams, name: str) -> ParticipantParams:
    """``params`` as a person of model ``name``: the shared fields kept, the model's own at their defaults."""
    cls = model_info(name).params
    if type(params) is cls:
        return params
    shared = {f.name: getattr(params, f.name) for f in dataclasses.fields(ParticipantParams)}
    return cls(**shared)

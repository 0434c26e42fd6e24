"""Beats and ECG from the simulated heart rate (docs/PARTICIPANT_MODEL.md, "Beat-to-beat RR and ECG").

NeuroKit2's ``ecg_simulate`` only takes a constant heart rate, so the ECG is
synthesised from the beat series itself, ECGSYN-style: the cardiac phase
advances by 2*pi per RR interval (R peak at phase 0) and the P, Q, R, S, T waves
are Gaussians in phase whose widths scale with sqrt(HR/60).

:class:`ParticipantSimulator` streams everything a Polar H10 would send: ECG at
130 Hz, RR intervals (with the strap's occasional missed or extra beat) and HR
at 1 Hz. Time is advanced explicitly by the caller.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from hri_physio_coach.participant.physiology import (
    SAME_TIME,
    Activity,
    ParticipantParams,
    breathing_rate,
    rr_sd,
)

TWO_PI = 2.0 * math.pi
#: Random streams of one seed: the session's (what the evaluation draws) and the one before it.
SESSION_STREAM = 0
PRE_SESSION_STREAM = 0x5E55
# (phase of the wave centre in rad, width in rad at 60 bpm, amplitude in mV) for P, Q, R, S, T.
WAVES = np.array([
    (-math.pi / 3.0, 0.25, 0.15),
    (-math.pi / 12.0, 0.10, -0.15),
    (0.0, 0.10, 1.20),
    (math.pi / 12.0, 0.10, -0.25),
    (math.pi / 2.0, 0.40, 0.30),
])


def ecg_waveform(t: np.ndarray, beat_start: float, rr: float) -> np.ndarray:
    """ECG (mV) at times ``t`` inside the interval [beat_start, beat_start + rr).

    The second half of the interval shows the P and Q waves of the next beat
    (phase wrapped to (-pi, pi]), so consecutive intervals join smoothly.
    """
    theta = TWO_PI * (t - beat_start) / rr
    theta = np.where(theta > math.pi, theta - TWO_PI, theta)
    scale = math.sqrt((60.0 / rr) / 60.0)
    d = theta[:, None] - WAVES[None, :, 0]
    d = (d + math.pi) % TWO_PI - math.pi
    widths = WAVES[:, 1] * scale
    return (WAVES[:, 2] * np.exp(-0.5 * (d / widths) ** 2)).sum(axis=1)


@dataclass
class SimulatorOutput:
    """Samples produced by one :meth:`ParticipantSimulator.advance` call (times in seconds)."""

    ecg_t: np.ndarray
    ecg_mv: np.ndarray
    beat_t: np.ndarray  # true R-peak times (what the ECG shows)
    rr_t: np.ndarray  # when the strap reports an RR interval
    rr_s: np.ndarray  # reported RR (s), including missed/extra-beat artefacts
    hr_t: np.ndarray
    hr_bpm: np.ndarray  # 1 Hz heart rate as the strap reports it
    model_hr: list[tuple[float, float]] = field(default_factory=list)


class ParticipantSimulator:
    """The participant's heart, beats and strap on an explicitly advanced clock.

    ``ecg=False`` leaves the ECG out (evaluations only need the strap's HR and RR). The ECG
    noise has its own random stream, so the beats, RR and HR of a seed are the same with or
    without ECG and however the time is cut into :meth:`advance` calls.

    ``stream`` picks another random stream of the same seed (0, the default, is the session's;
    :data:`PRE_SESSION_STREAM` is the one a participant rests on before the session starts).
    ``previous_beat`` (ECG only) is the last beat already shown when this model takes over from
    another one: the ECG runs from it to this model's first beat instead of an invented one.
    Neither changes which numbers the model draws, so the session's beats stay those of the seed.
    """

    def __init__(self, params: ParticipantParams, seed: int = 0, ecg_rate: float = 130.0,
                 dt: float = 0.1, t0: float = 0.0, noise_mv: float = 0.01, ecg: bool = True,
                 stream: int = SESSION_STREAM, previous_beat: float | None = None) -> None:
        if ecg_rate <= 0:
            raise ValueError(f"ecg_rate must be > 0, got {ecg_rate}")
        self.p = params
        self.seed = seed
        self.kinetics = params.make_kinetics(dt)
        self.rng = np.random.default_rng(seed if stream == SESSION_STREAM else [seed, stream])
        self._ecg_rng = np.random.default_rng([seed, 0xEC6] if stream == SESSION_STREAM
                                              else [seed, 0xEC6, stream])
        self.ecg = ecg
        self.ecg_rate = ecg_rate
        self.noise_mv = noise_mv
        self.t0 = t0
        self._steps = 0  # model time is t0 + steps * dt (no accumulated rounding)
        self.activity = Activity()
        self._ecg_index = 0  # next ECG sample: t0 + index / ecg_rate
        self._hr_second = 1  # next 1 Hz HR report at t0 + _hr_second
        rr0 = 60.0 / params.hr_rest
        self._next_beat = t0 + float(self.rng.uniform(0.0, rr0))
        self._interval = (self._next_beat - rr0, rr0)  # the beat interval the ECG is in
        self._first_beat = self._next_beat
        if previous_beat is not None and previous_beat < self._next_beat:
            self._interval = (previous_beat, self._next_beat - previous_beat)
        self._have_beat = False  # the first beat has no RR interval to report
        self._lf_phase = float(self.rng.uniform(0, TWO_PI))
        self._hf_phase = float(self.rng.uniform(0, TWO_PI))
        self._pending_rr = 0.0  # a missed beat carries its interval into the next report
        self._recent_rr: deque[tuple[float, float]] = deque()
        self._pending: list[tuple[float, Activity]] = []  # (from when, activity), in the order they start
        # The strap's jitter and dropouts draw from their own stream (a model without them draws nothing).
        self._strap_rng = np.random.default_rng([seed, 0x57A9, stream])
        self._dropout_left = 0  # seconds of an ongoing dropout still to go

    @property
    def t(self) -> float:
        return self.t0 + self._steps * self.kinetics.dt

    @property
    def hr(self) -> float:
        return self.kinetics.hr

    @property
    def next_report(self) -> float:
        """When the strap's next 1-Hz heart-rate report is due (it may be dropped)."""
        return self.t0 + self._hr_second

    @property
    def first_beat(self) -> float:
        """When this model's first beat falls (drawn at creation, from the seed)."""
        return self._first_beat

    @property
    def last_beat(self) -> float:
        """The latest beat the model has reached (its ECG is in the interval that starts there)."""
        return self._interval[0]

    @property
    def rr_in_progress(self) -> float:
        """The interval the heart is in: from :attr:`last_beat` to the next beat it has drawn."""
        return self._interval[1]

    @property
    def pending(self) -> list[tuple[float, Activity]]:
        """Activities set to start later, as ``(from when, activity)`` in the order they start."""
        return list(self._pending)

    def set_activity(self, activity: Activity, at: float | None = None) -> None:
        """Do ``activity`` from now on, or (``at``) from the first model step that starts at or after it.

        From now on, it also replaces the changes still waiting: it was heard after them.
        """
        if at is None or at <= self.t + SAME_TIME:
            self._pending.clear()
            self._start(activity)
            return
        bisect.insort(self._pending, (at, activity), key=lambda change: change[0])  # after equal times

    def _start(self, activity: Activity) -> None:
        self.kinetics.set_activity(activity)
        self.activity = activity

    def _start_due(self) -> None:
        while self._pending and self._pending[0][0] <= self.t + SAME_TIME:
            self._start(self._pending.pop(0)[1])

    def _next_rr(self, hr: float, rr_mean: float, x: float) -> float:
        """The next beat interval at heart rate ``hr`` and fraction of HRR ``x``."""
        lf_share = 0.2 if x >= 0.7 else 0.5 + 0.3 * min(x / 0.5, 1.0)
        hf_share = (1.0 - lf_share) * 0.8
        noise_share = max(0.0, 1.0 - lf_share - hf_share)
        self._lf_phase += TWO_PI * 0.1 * rr_mean
        self._hf_phase += TWO_PI * breathing_rate(x) * rr_mean
        wobble = (math.sqrt(2 * lf_share) * math.sin(self._lf_phase)
                  + math.sqrt(2 * hf_share) * math.sin(self._hf_phase)
                  + math.sqrt(noise_share) * float(self.rng.standard_normal()))
        return max(0.25, rr_mean + rr_sd(self.p, hr) * wobble)

    def advance(self, t_end: float) -> SimulatorOutput:
        """Run the model up to ``t_end`` and return every sample that became due."""
        beats: list[float] = []
        intervals: list[tuple[float, float]] = [self._interval]
        rr_t: list[float] = []
        rr_s: list[float] = []
        reports: list[tuple[float, float, float]] = []
        model_hr: list[tuple[float, float]] = []
        self._run(t_end, reports, rr_t, rr_s, beats, intervals, model_hr)
        if self.ecg:
            ecg_t, ecg_v = self._ecg_until(self.t, intervals)
        else:
            ecg_t = ecg_v = np.empty(0)
        return SimulatorOutput(ecg_t, ecg_v, np.array(beats), np.array(rr_t), np.array(rr_s),
                               np.array([r[0] for r in reports]), np.array([r[1] for r in reports]), model_hr)

    def advance_hr(self, t_end: float) -> list[tuple[float, float, float]]:
        """The same run as :meth:`advance`, keeping only the 1 Hz reports: (time, strap bpm, model bpm).

        For evaluations that need the heart rate alone (no arrays, no ECG: a fraction of the cost).
        """
        reports: list[tuple[float, float, float]] = []
        self._run(t_end, reports, [], [])
        return reports

    def _run(self, t_end: float, reports: list[tuple[float, float, float]], rr_t: list[float],
             rr_s: list[float], beats: list[float] | None = None,
             intervals: list[tuple[float, float]] | None = None,
             model_hr: list[tuple[float, float]] | None = None) -> None:
        """Step the model to ``t_end``, appending what became due to the given lists.

        The kinetics run in batches (up to the next activity change or ``t_end``); the beats and the
        1-Hz reports then fall on the steps they would have fallen on stepping one by one: at each
        step, its beats first, then its report, each with that step's heart rate.
        """
        dt, t0, run = self.kinetics.dt, self.t0, self.kinetics.run
        limit = t_end + 1e-9
        last = max(self._steps, math.floor((limit - t0) / dt))  # the last step: t0 + last * dt <= limit
        while last > self._steps and t0 + last * dt > limit:
            last -= 1
        while t0 + (last + 1) * dt <= limit:
            last += 1
        while self._steps < last:
            first = self._steps
            if self._pending:
                self._start_due()
            end = last
            if self._pending:  # the batch ends where the next change is due before a step
                end = min(end, self._change_due(self._pending[0][0], first + 1))
            hrs, fractions = run(end - first)
            if model_hr is not None:
                model_hr.extend(zip([t0 + s * dt for s in range(first + 1, end + 1)], hrs, strict=True))
            beat_step = self._step_reaching(self._next_beat, first + 1)
            report_step = self._step_reaching(t0 + self._hr_second, first + 1)
            while beat_step <= end or report_step <= end:
                if beat_step <= report_step:  # a step's beats come before its report
                    hr = hrs[beat_step - first - 1]
                    beat = self._next_beat
                    if beats is not None:
                        beats.append(beat)
                    if self._have_beat:
                        self._report_rr(beat, beat - self._interval[0], rr_t, rr_s)
                    self._have_beat = True
                    rr = self._next_rr(hr, 60.0 / hr, fractions[beat_step - first - 1])
                    self._next_beat = beat + rr
                    self._interval = (beat, rr)
                    if intervals is not None:
                        intervals.append(self._interval)
                    beat_step = self._step_reaching(self._next_beat, beat_step)
                else:
                    hr = hrs[report_step - first - 1]
                    when = t0 + self._hr_second
                    if not self._dropped():
                        reports.append((when, self._reported_hr(when, hr), hr))
                    self._hr_second += 1
                    report_step = self._step_reaching(t0 + self._hr_second, report_step)
            self._steps = end

    def _change_due(self, at: float, lowest: int) -> int:
        """The first step count from ``lowest`` on at which a change set for ``at`` starts (as
        :meth:`_start_due` decides it)."""
        t0, dt = self.t0, self.kinetics.dt
        step = self._step_reaching(at - SAME_TIME, lowest)
        while step > lowest and at <= t0 + (step - 1) * dt + SAME_TIME:
            step -= 1
        while not at <= t0 + step * dt + SAME_TIME:
            step += 1
        return step

    def _step_reaching(self, when: float, lowest: int) -> int:
        """The first step from ``lowest`` on that ends at or after ``when`` (``t0 + step * dt``, as the
        model counts its time)."""
        t0, dt = self.t0, self.kinetics.dt
        step = max(lowest, math.ceil((when - t0) / dt))
        while step > lowest and t0 + (step - 1) * dt >= when:
            step -= 1
        while t0 + step * dt < when:
            step += 1
        return step

    def _report_rr(self, when: float, rr: float, rr_t: list[float], rr_s: list[float]) -> None:
        """What the strap reports: mostly the true interval, sometimes a missed or extra beat."""
        u = float(self.rng.random())
        total = self._pending_rr + rr
        if u < self.p.artefact_rate / 2 and self._pending_rr == 0.0:
            self._pending_rr = total  # missed: merged into the next report
            return
        self._pending_rr = 0.0
        # An extra beat splits the interval in two.
        reports = [total / 2.0, total / 2.0] if u < self.p.artefact_rate else [total]
        for r in reports:
            rr_t.append(when)
            rr_s.append(r)
            self._recent_rr.append((when, r))
        while self._recent_rr and self._recent_rr[0][0] <= when - 5.0:
            self._recent_rr.popleft()

    def _dropped(self) -> bool:
        """The strap sends no heart rate this second (dropouts last 1-5 s; none without ``dropout_rate``)."""
        rate = self.p.dropout_rate
        if rate <= 0:
            return False
        if self._dropout_left > 0:
            self._dropout_left -= 1
            return True
        # A dropout of mean length 3 s starts with probability rate / 3: about ``rate`` of seconds are lost.
        if float(self._strap_rng.random()) < rate / 3.0:
            self._dropout_left = int(self._strap_rng.integers(0, 5))
            return True
        return False

    def _reported_hr(self, when: float, model_hr: float) -> float:
        recent = [r for w, r in self._recent_rr if w > when - 3.0]
        bpm = 60.0 * len(recent) / math.fsum(recent) if recent else model_hr
        if self.p.strap_jitter > 0:
            bpm += self.p.strap_jitter * float(self._strap_rng.standard_normal())
        return bpm

    def _ecg_until(self, t_end: float, intervals: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
        last = math.floor((t_end - self.t0) * self.ecg_rate + 1e-9)
        idx = np.arange(self._ecg_index, last + 1)
        self._ecg_index = last + 1
        t = self.t0 + idx / self.ecg_rate
        out = np.empty_like(t)
        starts = np.array([s for s, _ in intervals])
        which = np.searchsorted(starts, t, side="right") - 1
        for k in np.unique(which):
            mask = which == k
            start, rr = intervals[max(int(k), 0)]
            out[mask] = ecg_waveform(t[mask], start, rr)
        x = self.kinetics.fraction_hrr
        out += 0.05 * np.sin(TWO_PI * breathing_rate(x) * t)  # respiratory baseline wander
        out += self._ecg_rng.normal(0.0, self.noise_mv, size=t.shape)
        return t, out

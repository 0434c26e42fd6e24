"""The strap's streams across the session start: a resting person first, the seeded session model after.

The evaluation (:mod:`hri_physio_coach.evaluate.simulation`) starts the participant's model with the
coach's ``session_start``: its kinetics at rest and its seed's random stream from the first draw.
A closed loop's participant streams long before that (the session's start-up takes minutes), so
:class:`StrapStream` streams a resting person from another random stream of the same seed
(:data:`~hri_physio_coach.participant.cardiac.PRE_SESSION_STREAM`) until :meth:`StrapStream.start_session`,
then hands over to a fresh :func:`session_model` on the streams' own grid (docs/PARTICIPANT_MODEL.md,
"Before the session"). The session part is then what the evaluation draws, whatever came before.

The hand-over keeps every stream continuous: it happens on a whole second of the streams' timeline
(the 1 Hz HR and the ECG samples keep their spacing, no sample twice), at a second where the session
model's first beat falls where the resting heart's next beat was due (within
:data:`BEAT_TOLERANCE` of its interval, at most :data:`MAX_HANDOVER_WAIT` s later), so the ECG shows
no extra or missing beat, and the RR stream reports that bridging interval.
No clock is read: the caller advances the stream.
"""

from __future__ import annotations

import math

import numpy as np

from hri_physio_coach.participant.cardiac import PRE_SESSION_STREAM, ParticipantSimulator, SimulatorOutput
from hri_physio_coach.participant.physiology import Activity, ParticipantParams

#: How far (fraction of the resting heart's interval in progress) the session model's first beat may
#: fall from the beat the resting heart had due, for a hand-over on that second.
BEAT_TOLERANCE = 0.25
#: At most this many seconds after the session start the hand-over happens, bridging beat or not.
MAX_HANDOVER_WAIT = 8
#: A session start more than this far (s) ahead of the stream is taken as a clock mismatch: now.
MAX_START_AHEAD = 10.0


def strap_start(now: float) -> float:
    """Where a strap switched on at ``now`` starts its timeline: the next half second of the clock.

    Its heart-rate reports then fall on half seconds, midway between the whole seconds on which a
    coach's session starts and its rule-update windows end, so a few tenths of a second of transport
    never move a sample into another window.
    """
    start = math.floor(now) + 0.5
    return start if start >= now else start + 1.0


def session_model(params: ParticipantParams, seed: int, t0: float = 0.0, *, ecg: bool = True,
                  ecg_rate: float = 130.0, previous_beat: float | None = None) -> ParticipantSimulator:
    """The participant's model from the session start ``t0``: what the evaluation and the node both run."""
    return ParticipantSimulator(params, seed=seed, ecg_rate=ecg_rate, t0=t0, ecg=ecg,
                                previous_beat=previous_beat)


class StrapStream:
    """What the simulated strap streams from ``t0`` on: rest (pre-session stream), then the session model.

    ``sim`` is the model running now; ``session_t0`` is when the session model took over (None
    before). :meth:`advance` returns the samples of both models in time order.
    """

    def __init__(self, params: ParticipantParams, seed: int, t0: float, *, ecg: bool = True,
                 ecg_rate: float = 130.0) -> None:
        self.params = params
        self.seed = seed
        self.ecg = ecg
        self.ecg_rate = ecg_rate
        self.t0 = t0
        self.sim = ParticipantSimulator(params, seed=seed, ecg_rate=ecg_rate, t0=t0, ecg=ecg,
                                        stream=PRE_SESSION_STREAM)
        self.session_t0: float | None = None
        self.session_requested: float | None = None  # the session start asked for
        self.bridged = False  # the hand-over found a bridging beat (else it waited MAX_HANDOVER_WAIT)
        self._candidate: int | None = None  # next whole second (from t0) at which to try the hand-over
        self._last_candidate = 0
        self._last_ecg_t = -math.inf
        self._pending_bridge: tuple[float, float] | None = None  # (first session beat, bridging RR)

    @property
    def t(self) -> float:
        return self.sim.t

    @property
    def in_session(self) -> bool:
        return self.session_t0 is not None

    def set_activity(self, activity: Activity, at: float | None = None) -> None:
        """Do ``activity`` from now on, or from ``at`` (see :meth:`ParticipantSimulator.set_activity`)."""
        self.sim.set_activity(activity, at)

    def start_session(self, t_start: float) -> bool:
        """The coach's session started at ``t_start``: hand over at the first fitting second from then.

        False (nothing changes) when a session start was already taken: one participant, one session.
        """
        if self.session_requested is not None:
            return False
        if t_start > self.sim.t + MAX_START_AHEAD:
            t_start = self.sim.t
        self.session_requested = t_start
        first = max(math.ceil(max(t_start, self.sim.t) - self.t0 - 1e-9), 1)
        self._candidate, self._last_candidate = first, first + MAX_HANDOVER_WAIT
        return True

    def advance(self, t_end: float) -> SimulatorOutput:
        """Run up to ``t_end``; every sample that became due, from whichever model produced it."""
        parts: list[SimulatorOutput] = []
        while self._candidate is not None and self.t0 + self._candidate <= t_end + 1e-9:
            at = self.t0 + self._candidate
            parts.append(self.sim.advance(at))
            self._try_handover(at)
        parts.append(self.sim.advance(t_end))
        return self._joined(parts)

    def _try_handover(self, at: float) -> None:
        resting = self.sim
        fresh = session_model(self.params, self.seed, at, ecg=self.ecg, ecg_rate=self.ecg_rate,
                              previous_beat=resting.last_beat)
        bridge = fresh.first_beat - resting.last_beat
        due = resting.rr_in_progress
        fits = abs(bridge - due) <= BEAT_TOLERANCE * due
        assert self._candidate is not None
        if not fits and self._candidate < self._last_candidate:
            self._candidate += 1
            return
        self._candidate = None
        self.bridged = fits
        fresh.set_activity(resting.activity)
        for due, activity in resting.pending:  # instructions heard but not taken up yet
            fresh.set_activity(activity, due)
        self.sim = fresh
        self.session_t0 = at
        # The strap reports the bridging interval at the session model's first beat (which has none).
        self._pending_bridge = (fresh.first_beat, bridge)

    def _joined(self, parts: list[SimulatorOutput]) -> SimulatorOutput:
        ecg_ts, ecg_mvs = [], []
        for p in parts:  # the session model's sample at its t0 is the resting one's last: once only
            keep = p.ecg_t > self._last_ecg_t
            ecg_ts.append(p.ecg_t[keep])
            ecg_mvs.append(p.ecg_mv[keep])
            if keep.any():
                self._last_ecg_t = float(p.ecg_t[keep][-1])
        ecg_t, ecg_mv = np.concatenate(ecg_ts), np.concatenate(ecg_mvs)
        rr_t = np.concatenate([p.rr_t for p in parts])
        rr_s = np.concatenate([p.rr_s for p in parts])
        beat_t = np.concatenate([p.beat_t for p in parts])
        pending = self._pending_bridge
        if pending is not None and pending[0] <= self.sim.t:
            self._pending_bridge = None
            where = int(np.searchsorted(rr_t, pending[0], side="right"))
            rr_t = np.insert(rr_t, where, pending[0])
            rr_s = np.insert(rr_s, where, pending[1])
        return SimulatorOutput(
            ecg_t, ecg_mv, beat_t, rr_t, rr_s,
            np.concatenate([p.hr_t for p in parts]), np.concatenate([p.hr_bpm for p in parts]),
            [x for p in parts for x in p.model_hr],
        )

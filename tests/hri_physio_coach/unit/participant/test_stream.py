"""The strap across the session start: the seeded model starts with the session, the streams stay whole."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hri_physio_coach.participant.cardiac import SimulatorOutput
from hri_physio_coach.participant.physiology import Activity, ParticipantParams
from hri_physio_coach.participant.stream import (
    BEAT_TOLERANCE,
    MAX_HANDOVER_WAIT,
    MAX_START_AHEAD,
    StrapStream,
    session_model,
)

PERSON = ParticipantParams()
T0 = 1000.0  # the streams' first tick (ROS time)
ECG_RATE = 130.0


def run(stream: StrapStream, until: float, tick: float, start_at: float | None = None,
        activity_at: tuple[float, Activity] | None = None) -> SimulatorOutput:
    """Advance in ``tick`` steps; ``start_session(start_at)`` once the stream has passed it."""
    outs: list[SimulatorOutput] = []
    t = stream.t
    while t < until:
        t = min(t + tick, until)
        if activity_at is not None and t >= activity_at[0]:
            stream.set_activity(activity_at[1])
            activity_at = None
        if start_at is not None and t >= start_at:
            stream.start_session(start_at)
            start_at = None
        outs.append(stream.advance(t))
    return SimulatorOutput(*(np.concatenate([getattr(o, f) for o in outs]) for f in
                             ("ecg_t", "ecg_mv", "beat_t", "rr_t", "rr_s", "hr_t", "hr_bpm")),
                           [x for o in outs for x in o.model_hr])


def session_part(stream: StrapStream, out: SimulatorOutput) -> tuple[np.ndarray, ...]:
    """HR and RR after the hand-over, times from the hand-over (the bridging RR left out)."""
    s = stream.session_t0
    assert s is not None
    hr = out.hr_t > s
    rr = out.rr_t > s
    return out.hr_t[hr] - s, out.hr_bpm[hr], out.rr_t[rr][1:] - s, out.rr_s[rr][1:]


@pytest.mark.parametrize("seed", [1, 7])
def test_the_session_part_is_the_seeds_whatever_came_before(seed: int) -> None:
    """Same seed: the same HR and RR from the session start on, after 5 s or 15 min of rest."""
    session = 300.0
    parts = []
    for pre, tick in ((5.0, 0.1), (61.3, 0.37), (900.0, 1.3)):
        stream = StrapStream(PERSON, seed, T0)
        out = run(stream, T0 + pre + session, tick, start_at=T0 + pre)
        parts.append(session_part(stream, out))
        # What the evaluation runs: the session model alone, from the same start.
        alone = session_model(PERSON, seed, 0.0, ecg=False).advance(session - 10.0)
        hr_t, hr, rr_t, rr = parts[-1]
        n_hr, n_rr = len(alone.hr_t), len(alone.rr_t)
        np.testing.assert_allclose(hr_t[:n_hr], alone.hr_t, atol=1e-6)
        np.testing.assert_allclose(hr[:n_hr], alone.hr_bpm, rtol=1e-12)
        np.testing.assert_allclose(rr_t[:n_rr], alone.rr_t, atol=1e-6)
        np.testing.assert_allclose(rr[:n_rr], alone.rr_s, rtol=1e-12)
    n = min(len(p[1]) for p in parts)
    for other in parts[1:]:
        np.testing.assert_allclose(other[1][:n], parts[0][1][:n], rtol=1e-12)


def test_the_rest_before_the_session_is_another_random_stream() -> None:
    stream = StrapStream(PERSON, 3, 0.0, ecg=False)
    before = run(stream, 120.0, 0.5)
    alone = session_model(PERSON, 3, 0.0, ecg=False).advance(120.0)
    assert len(before.rr_s) > 100 and not np.allclose(before.rr_s[:100], alone.rr_s[:100])


@pytest.mark.parametrize("seed", range(6))
def test_the_streams_stay_continuous_across_the_handover(seed: int) -> None:
    stream = StrapStream(PERSON, seed, T0, ecg_rate=ECG_RATE)
    start = T0 + 42.25
    out = run(stream, T0 + 120.0, 0.37, start_at=start)
    s = stream.session_t0
    assert s is not None
    # On a whole second of the streams, at or after the session start, at most MAX_HANDOVER_WAIT later.
    assert (s - T0) == pytest.approx(round(s - T0), abs=1e-9)
    assert start <= s <= math.ceil(start - T0) + T0 + MAX_HANDOVER_WAIT
    # ECG: every sample once, one period apart (no gap, no repeat); 1 Hz HR likewise.
    steps = np.diff(out.ecg_t) * ECG_RATE
    assert steps.min() == pytest.approx(1.0, abs=1e-6) and steps.max() == pytest.approx(1.0, abs=1e-6)
    assert out.ecg_t[0] == T0 and out.ecg_t[-1] == pytest.approx(T0 + 120.0)
    np.testing.assert_allclose(np.diff(out.hr_t), 1.0, atol=1e-6)
    assert out.hr_t[0] == pytest.approx(T0 + 1.0) and out.hr_t[-1] == pytest.approx(T0 + 120.0)
    # RR: in time order, and the beat bridging the two models is reported where it falls.
    assert np.all(np.diff(out.rr_t) >= 0)
    first = int(np.searchsorted(out.beat_t, s, side="right"))
    bridge = out.beat_t[first] - out.beat_t[first - 1]
    at = np.flatnonzero(out.rr_t == out.beat_t[first])
    assert len(at) == 1 and out.rr_s[at[0]] == pytest.approx(bridge)
    # The ECG around the hand-over has no step bigger than anywhere else (the beat continues).
    around = np.abs(np.diff(out.ecg_mv[(out.ecg_t > s - 2.0) & (out.ecg_t < s + 2.0)]))
    assert around.max() <= np.abs(np.diff(out.ecg_mv)).max()
    # No beat doubled or left out: the bridging interval is an ordinary resting one (these seeds find one).
    assert stream.bridged
    usual = float(np.median(out.rr_s))
    assert (1 - 2 * BEAT_TOLERANCE) * usual <= bridge <= (1 + 2 * BEAT_TOLERANCE) * usual


def test_a_session_start_heard_late_or_far_ahead() -> None:
    late = StrapStream(PERSON, 1, T0, ecg=False)
    late.advance(T0 + 100.0)
    assert late.start_session(T0 + 30.0)  # heard 70 s late: from the next second of the stream on
    late.advance(T0 + 120.0)
    assert late.session_t0 is not None and T0 + 100.0 <= late.session_t0 <= T0 + 101.0 + MAX_HANDOVER_WAIT
    assert not late.start_session(T0 + 110.0)  # one session per participant
    ahead = StrapStream(PERSON, 1, T0, ecg=False)
    ahead.advance(T0 + 10.0)
    ahead.start_session(T0 + 10.0 + MAX_START_AHEAD + 3600.0)  # another clock: taken as now
    ahead.advance(T0 + 30.0)
    assert ahead.session_t0 is not None and ahead.session_t0 <= T0 + 11.0 + MAX_HANDOVER_WAIT


def test_a_session_start_not_yet_reached_waits_for_its_time() -> None:
    stream = StrapStream(PERSON, 1, T0, ecg=False)
    stream.start_session(T0 + 5.5)
    stream.advance(T0 + 5.0)
    assert not stream.in_session
    stream.advance(T0 + 20.0)
    assert stream.session_t0 is not None and stream.session_t0 >= T0 + 6.0


def test_the_activity_carries_over_to_the_session_model() -> None:
    stream = StrapStream(PERSON, 1, T0, ecg=False)
    marching = Activity("marching", 130.0, 1.0)
    run(stream, T0 + 60.0, 0.5, start_at=T0 + 30.0, activity_at=(T0 + 29.0, marching))
    assert stream.in_session and stream.sim.activity == marching
    assert stream.sim.kinetics.u > 0

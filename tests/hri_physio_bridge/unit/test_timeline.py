"""Gaps, clock jumps and the measured rate, judged on timestamps alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hri_physio_bridge.timeline import ClockOffsetTrack, RateMeter, TimelineCheck


def feed(check: TimelineCheck, stamps: np.ndarray, chunk: int) -> tuple[list, list]:
    gaps, jumps = [], []
    for i in range(0, len(stamps), chunk):
        g, j = check.check(stamps[i:i + chunk])
        gaps += g
        jumps += j
    return gaps, jumps


@pytest.mark.parametrize("chunk", [1, 7, 1000])
def test_a_gap_inside_a_chunk_or_between_chunks_is_found_once(chunk: int) -> None:
    t = np.r_[0:100, 130:200] / 100.0
    gaps, jumps = feed(TimelineCheck(100.0), t, chunk)
    assert jumps == [] and [(g.count, g.t_before, g.t_after) for g in gaps] == [(30, 0.99, 1.3)]
    assert gaps[0].first_t == pytest.approx(1.0) and gaps[0].last_t == pytest.approx(1.29)


@pytest.mark.parametrize("chunk", [1, 13, 5000])
def test_backward_jump_and_return_are_two_jumps_and_nothing_missing(chunk: int) -> None:
    t = np.arange(3900) / 130.0
    t[1300:2600] -= 5.0
    gaps, jumps = feed(TimelineCheck(130.0), t, chunk)
    assert gaps == [] and [j.kind for j in jumps] == ["backward", "returned"]
    assert jumps[0].size == pytest.approx(-5.0 + 1 / 130.0)


def test_a_return_in_two_steps_is_not_a_gap() -> None:
    t = np.r_[0:100, 40:80, 90:120, 130:160] / 10.0  # 6 s back, then forward 1 s and 5 s (= back on time)
    gaps, jumps = feed(TimelineCheck(10.0), t, 5)
    assert gaps == [] and [j.kind for j in jumps] == ["backward", "returned", "returned"]


def test_the_earlier_timeline_is_forgotten_after_jump_memory() -> None:
    """Long after a backward jump, a forward step is a real gap again, of its full size."""
    t = np.r_[0:100, 50:400, 420:430] / 10.0  # 5 s back, 35 s on, then 2 s (20 samples) missing
    gaps, jumps = feed(TimelineCheck(10.0, jump_memory=30.0), t, 10)
    assert [j.kind for j in jumps] == ["backward"] and [g.count for g in gaps] == [20]


def test_repeated_stamps_are_jumps_and_shift_nothing() -> None:
    t = np.r_[0:50, 49:60, 70:80] / 10.0  # sample 49 stamped twice, later a real gap of 10
    gaps, jumps = feed(TimelineCheck(10.0), t, 4)
    assert [j.kind for j in jumps] == ["repeated"] and [g.count for g in gaps] == [10]


def test_irregular_streams_only_have_backward_jumps() -> None:
    gaps, jumps = feed(TimelineCheck(0.0), np.array([1.0, 1.0, 5.0, 100.0, 99.0, 120.0]), 2)
    assert gaps == [] and [(j.t_before, j.t_after) for j in jumps] == [(100.0, 99.0)]


@pytest.mark.parametrize("true_rate", [100.0, 130.0, 500.0])
def test_rate_meter_finds_the_true_rate_through_jitter_and_gaps(true_rate: float) -> None:
    rng = np.random.default_rng(1)
    t = np.arange(int(true_rate * 20)) / true_rate + rng.normal(0, 0.05 / true_rate, int(true_rate * 20))
    t = np.delete(t, np.s_[int(true_rate * 5):int(true_rate * 7)])  # 2 s missing
    meter = RateMeter(window=10.0, min_span=5.0)
    for i in range(0, len(t), 13):
        meter.add(t[i:i + 13])
    assert meter.rate == pytest.approx(true_rate, rel=0.01)
    assert meter.span == pytest.approx(10.0, abs=0.5)  # only the last window counts


def test_rate_meter_waits_for_min_span_and_resets() -> None:
    meter = RateMeter(window=10.0, min_span=5.0)
    meter.add(np.arange(400) / 100.0)
    assert meter.rate is None
    meter.add(np.arange(400, 600) / 100.0)
    assert meter.rate == pytest.approx(100.0)
    meter.reset()
    assert meter.rate is None and meter.span == 0.0
    with pytest.raises(ValueError):
        RateMeter(window=1.0, min_span=2.0)


def test_clock_offsets_are_summed_up_for_a_status() -> None:
    track = ClockOffsetTrack(applied=True)
    assert track.as_dict() == {"applied": True, "measurements": 0, "offset_s": None, "first_s": None,
                               "min_s": None, "max_s": None, "span_s": None}
    for offset in (None, 2.5, math.nan, 2.4999, 2.5003, 2.5001):
        track.add(offset)
    assert track.as_dict() == {"applied": True, "measurements": 4, "offset_s": 2.5001, "first_s": 2.5,
                               "min_s": 2.4999, "max_s": 2.5003, "span_s": 0.0004}

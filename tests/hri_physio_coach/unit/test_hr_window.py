"""A rule update's window holds the heart rate *taken* in it, however late the transport delivers it."""

from __future__ import annotations

import math

import pytest

from hri_physio_coach.hr_input import CLOCK_RESET, HeartRateMonitor

#: The strap's clock runs this far ahead of the coach's (another clock: LSL).
AHEAD = 5000.0


def fed(monitor: HeartRateMonitor, samples: list[tuple[float, float, float]]) -> None:
    """``(taken, delay, bpm)`` on the coach's clock, delivered in order of arrival."""
    for taken, delay, bpm in sorted(samples, key=lambda s: s[0] + s[1]):
        monitor.add(taken + delay, bpm, source_t=taken + AHEAD)


def test_late_samples_count_in_the_window_they_were_taken_in() -> None:
    monitor = HeartRateMonitor(min_valid=1)
    # 1 Hz from 0.5 s; most arrive 0.05 s later, those taken in [27, 30) arrive 3.5 s late.
    samples = [(k + 0.5, 3.5 if 27 <= k + 0.5 < 30 else 0.05, 100.0 + k) for k in range(40)]
    fed(monitor, samples)
    assert monitor.clock_offset == pytest.approx(AHEAD - 0.05)
    stats = monitor.take(0.0, 30.0)
    assert stats.n_valid == 30 and stats.mean == pytest.approx(100.0 + 14.5)
    # What was taken from 30 s on is the next window's, though part of it arrived before the samples above.
    assert monitor.take(30.0, 40.0).n_valid == 10


def test_the_window_is_complete_once_its_last_sample_has_come() -> None:
    monitor = HeartRateMonitor()
    for k in range(10):  # 1 Hz, taken at k + 0.5, delivered promptly
        monitor.add(k + 0.55, 80.0, source_t=k + 0.5 + AHEAD)
    assert monitor.sample_interval == pytest.approx(1.0)
    assert monitor.window_complete(10.0)  # the next sample is due at 10.5
    assert not monitor.window_complete(10.6)  # the one taken at 10.5 has not come
    monitor.add(13.0, 80.0, source_t=10.5 + AHEAD)  # 2.5 s late
    assert monitor.window_complete(10.6) and monitor.window_complete(11.4)
    assert not monitor.window_complete(11.6)


def test_nothing_to_wait_for_without_samples_or_with_the_signal_lost() -> None:
    monitor = HeartRateMonitor(timeout=5.0)
    assert monitor.window_complete(30.0)
    monitor.add(1.0, 80.0, source_t=1.0 + AHEAD)
    monitor.add(2.0, 80.0, source_t=2.0 + AHEAD)
    assert not monitor.window_complete(30.0)
    assert monitor.check_timeout(10.0, 0.0) == "lost"
    assert monitor.window_complete(30.0)


def test_a_source_clock_that_restarts_maps_afresh() -> None:
    monitor = HeartRateMonitor(min_valid=1)
    for k in range(5):
        monitor.add(k + 0.1, 70.0, source_t=k + AHEAD)
    # The strap reconnects with its clock 100 s back: its samples are still taken "now".
    for k in range(5, 10):
        monitor.add(k + 0.1, 90.0, source_t=k + AHEAD - 100.0)
    assert monitor.clock_offset == pytest.approx(AHEAD - 100.0 - 0.1)
    assert monitor.take(5.0, 10.0 + 1e-6).mean == pytest.approx(90.0)
    assert CLOCK_RESET < 100.0


def test_samples_without_a_stamp_are_placed_at_their_arrival() -> None:
    monitor = HeartRateMonitor(min_valid=1)
    monitor.add(3.0, 75.0)
    monitor.add(4.0, 77.0, source_t=math.nan)
    assert monitor.newest_sample == 4.0
    assert monitor.take(0.0, 3.5).mean == 75.0
    assert monitor.take(3.5, 5.0).mean == 77.0


def test_invalid_and_flagged_samples_are_counted_in_their_window() -> None:
    monitor = HeartRateMonitor(min_valid=1)
    monitor.add(1.0, 80.0, source_t=1.0)
    monitor.add(2.0, 500.0, source_t=2.0)
    monitor.add(3.0, 80.0, flagged=True, source_t=3.0)
    monitor.add(4.0, 82.0, source_t=4.0)
    stats = monitor.take(0.0, 3.5)
    assert (stats.n_valid, stats.n_invalid, stats.n_flagged) == (1, 1, 1)
    assert monitor.stats().n_valid == 1  # the 4-s sample stays for the next window


def test_the_calibration_holds_the_heart_rate_taken_in_it_whenever_it_arrives() -> None:
    monitor = HeartRateMonitor()
    fed(monitor, [(k - 9.5, 0.05, 120.0) for k in range(8)])  # the strap streamed before the session
    monitor.start_calibration()
    monitor.add(0.2, 120.0, source_t=-0.5 + AHEAD)  # taken before the session start, arrives after it
    # 1 Hz from 0.5 s, delivered 0.05 s later, except the ones taken in [170, 177): 2 s late.
    samples = [(k + 0.5, 2.0 if 170 <= k + 0.5 < 177 else 0.05, 60.0 + k % 2) for k in range(180)]
    fed(monitor, samples)
    kept = monitor.finish_calibration(0.0, 177.0)
    assert len(kept) == 177 and sum(kept) / len(kept) == pytest.approx(60.0 + 88 / 177)
    assert monitor.finish_calibration() == []  # finished: collected no more


def test_a_stalled_transport_catching_up_is_not_a_restarted_clock() -> None:
    """10 s of samples arrive together (a loaded machine): each still belongs where it was taken."""
    monitor = HeartRateMonitor(min_valid=1)
    samples = [(k + 0.5, (20.0 - k) if 8 <= k < 20 else 0.05, 60.0 + k) for k in range(40)]
    fed(monitor, samples)
    assert monitor.clock_offset == pytest.approx(AHEAD - 0.05)
    assert monitor.take(0.0, 10.0).n_valid == 10
    stats = monitor.take(10.0, 30.0)
    assert stats.n_valid == 20 and stats.mean == pytest.approx(60.0 + 19.5)


def test_samples_received_before_the_coachs_clock_started_do_not_displace_the_rest() -> None:
    """Under sim time the coach's clock reads 0 until the first /clock message; then it jumps."""
    monitor = HeartRateMonitor(min_valid=1)
    epoch = 1.8e9
    for k in range(3):
        monitor.add(0.0, 70.0, source_t=k + AHEAD)  # received at "0"
    for k in range(3, 40):  # the clock runs: the same source timeline, received promptly
        monitor.add(epoch + k + 0.05, 80.0, source_t=k + AHEAD)
    assert monitor.clock_offset == pytest.approx(AHEAD - epoch - 0.05)
    stats = monitor.take(epoch + 10.0, epoch + 30.0)
    assert stats.n_valid == 20 and stats.mean == 80.0

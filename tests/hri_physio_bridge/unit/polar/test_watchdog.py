"""The per-stream watchdog on its own: start and stall timeouts, restart first, then reconnect."""

from __future__ import annotations

import pytest

from hri_physio_bridge.polar.watchdog import RECONNECT, RESTART, START, STREAMING, Alarm, StreamWatchdog


def test_first_data_within_the_start_timeout_is_quiet() -> None:
    dog = StreamWatchdog()
    dog.watch("ecg", 0.0, start_timeout=40.0, stall_timeout=5.0)
    assert dog.check(39.9) == [] and dog.next_due() == 40.0
    assert dog.data("ecg", 25.0) == pytest.approx(25.0)  # a late start, but within its timeout
    assert dog.data("ecg", 25.5) is None and dog.next_due() == pytest.approx(30.5)
    assert dog.check(30.4) == []


def test_no_first_data_asks_for_a_restart_then_a_reconnect() -> None:
    dog = StreamWatchdog()
    dog.watch("ecg", 100.0, start_timeout=40.0, stall_timeout=5.0)
    assert dog.check(140.0) == [Alarm("ecg", START, 40.0, 100.0, RESTART)]
    assert dog.check(141.0) == []  # re-armed: the restarted stream gets its start timeout again
    dog.watch("ecg", 141.0, start_timeout=40.0, stall_timeout=5.0)  # the restart was accepted
    assert dog.check(180.9) == []
    assert dog.check(181.0) == [Alarm("ecg", START, 40.0, 141.0, RECONNECT)]
    assert dog.next_due() is None  # the next connection watches anew


def test_silence_while_streaming_and_recovery_after_a_restart() -> None:
    dog = StreamWatchdog()
    dog.watch("hr", 0.0, start_timeout=10.0, stall_timeout=5.0)
    dog.data("hr", 1.0)
    dog.data("hr", 2.0)
    [alarm] = dog.check(7.5)
    assert (alarm.phase, alarm.since, alarm.silent_s, alarm.action) == (STREAMING, 2.0, 5.5, RESTART)
    dog.watch("hr", 7.6, start_timeout=10.0, stall_timeout=5.0)
    assert dog.data("hr", 8.0) == pytest.approx(0.4)  # data again: the restart helped
    [alarm] = dog.check(13.0)
    assert alarm.action == RESTART  # a new silence starts over with a restart


def test_sources_are_independent() -> None:
    dog = StreamWatchdog()
    dog.watch("ecg", 0.0, 40.0, 5.0)
    dog.watch("hr", 0.0, 10.0, 5.0)
    for t in range(1, 40):
        dog.data("hr", float(t))
    assert dog.check(30.0) == []
    assert [a.source for a in dog.check(40.0)] == ["ecg"]
    dog.forget("hr")
    dog.clear()
    assert dog.next_due() is None and dog.data("ecg", 50.0) is None


def test_timeouts_must_be_positive() -> None:
    with pytest.raises(ValueError, match="timeouts must be > 0"):
        StreamWatchdog().watch("ecg", 0.0, 0.0, 5.0)

"""The coach's checks for a second coach or a second clock on its topics (no ROS)."""

from __future__ import annotations

from hri_physio_coach.conflicts import EchoFilter, SourceWatch


def test_echo_filter_tells_our_messages_from_anyone_elses() -> None:
    echo = EchoFilter()
    for payload in ("a", "b", "a"):
        echo.sent(payload)
    assert not echo.is_foreign("a") and not echo.is_foreign("b")
    assert echo.is_foreign("c")  # never sent
    assert not echo.is_foreign("a")  # the second "a" we sent
    assert echo.is_foreign("a")  # a third "a": someone sends what we send (a twin coach)
    assert echo.foreign == 2


def test_echo_filter_forgets_echoes_it_never_heard_within_its_capacity() -> None:
    echo = EchoFilter(capacity=3)
    for payload in ("1", "2", "3", "4"):
        echo.sent(payload)
    assert echo.is_foreign("1")  # forgotten: an echo lost long ago no longer hides anything
    assert not any(echo.is_foreign(p) for p in ("2", "3", "4"))
    echo.sent("5")
    assert not echo.is_foreign("5") and echo.foreign == 1


def test_source_watch_accepts_a_replaced_source_and_catches_two_taking_turns() -> None:
    watch = SourceWatch()
    assert not any(watch.seen("A") for _ in range(5))
    assert not watch.seen("B")  # A was replaced (a restarted launcher): fine
    assert not any(watch.seen("B") for _ in range(5))
    assert not watch.seen("C")
    assert watch.seen("B")  # B publishes again after C took over: two clocks
    assert watch.sources == 3


def test_source_watch_two_clocks_interleaved() -> None:
    watch = SourceWatch()
    turns = [watch.seen(source) for source in ("A", "B", "A", "B")]
    assert turns == [False, False, True, True]

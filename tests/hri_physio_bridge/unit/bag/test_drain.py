"""The recorder's drain: batches from raw subscriptions, fair between topics, order kept."""

from __future__ import annotations

from collections import deque
from typing import Any

from hri_physio_bridge.nodes.recorder import drain_subscriptions, drain_within


class FakeHandle:
    """What rclpy's subscription handle offers the drain: a context manager and take_message."""

    def __init__(self, queue: deque[bytes]) -> None:
        self.queue = queue
        self.entered = 0

    def __enter__(self) -> FakeHandle:
        self.entered += 1
        return self

    def __exit__(self, *exc: object) -> None:
        self.entered -= 1

    def take_message(self, msg_type: Any, raw: bool) -> tuple[bytes, dict[str, int]] | None:
        assert raw and self.entered == 1, "taken raw, inside the handle's context"
        if not self.queue:
            return None
        data = self.queue.popleft()
        return data, {"received_timestamp": int(data.split(b":")[1])}


class FakeSubscription:
    msg_type = object()

    def __init__(self, topic: str, n: int) -> None:
        self.handle = FakeHandle(deque(f"{topic}:{i}".encode() for i in range(n)))


def test_a_flooding_topic_does_not_starve_the_others() -> None:
    subs = {"/flood": FakeSubscription("/flood", 25), "/hr": FakeSubscription("/hr", 3)}
    got: list[tuple[str, bytes, int]] = []

    def on_message(topic: str, data: bytes, info: dict[str, int]) -> None:
        got.append((topic, data, info["received_timestamp"]))

    assert drain_subscriptions(subs, on_message, budget=10) == (13, True)  # /flood has more
    assert [d for t, d, _ in got if t == "/hr"] == [b"/hr:0", b"/hr:1", b"/hr:2"]
    assert len([1 for t, *_ in got if t == "/flood"]) == 10
    assert drain_subscriptions(subs, on_message, budget=10) == (10, True)
    assert drain_subscriptions(subs, on_message, budget=10) == (5, False)  # emptied
    assert drain_subscriptions(subs, on_message, budget=10) == (0, False)  # nothing waiting
    flood = [(d, stamp) for t, d, stamp in got if t == "/flood"]
    assert [d for d, _ in flood] == [f"/flood:{i}".encode() for i in range(25)]  # each once, in order
    assert [stamp for _, stamp in flood] == list(range(25))  # the middleware's info is passed on


def test_exactly_budget_waiting_reports_more_then_empties() -> None:
    subs = {"/a": FakeSubscription("/a", 4)}
    got: list[str] = []
    assert drain_subscriptions(subs, lambda t, d, i: got.append(d), budget=4) == (4, True)
    assert drain_subscriptions(subs, lambda t, d, i: got.append(d), budget=4) == (0, False)
    assert len(got) == 4


def test_a_stops_drain_takes_every_pass_until_empty() -> None:
    passes = deque([(2000, True), (2000, True), (7, False)])
    assert drain_within(passes.popleft, timeout=10.0, clock=lambda: 0.0) == (4007, False)
    assert not passes


def test_a_topic_that_never_runs_dry_is_cut_at_the_drain_timeout() -> None:
    """A publisher that did not stop: each pass takes 2000 and 1 s of the (fake) clock; the drain
    ends after drain_timeout with more left, which the recorder says as an error."""
    now = [0.0]

    def flood() -> tuple[int, bool]:
        now[0] += 1.0
        return 2000, True

    taken, more = drain_within(flood, timeout=5.0, clock=lambda: now[0])
    assert more and taken == 5 * 2000 and now[0] == 5.0

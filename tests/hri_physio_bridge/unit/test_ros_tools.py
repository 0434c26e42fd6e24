"""ros_tools.wait_all_acked: one shared timeout for many publishers."""

from __future__ import annotations

from hri_physio_bridge.ros_tools import wait_all_acked


class FakePublisher:
    """A publisher whose subscribers ack after ``ack_after`` s of the fake clock (None: never)."""

    def __init__(self, now: list[float], ack_after: float | None) -> None:
        self.now, self.ack_after, self.timeouts = now, ack_after, []

    def wait_for_all_acked(self, timeout) -> bool:
        seconds = timeout.nanoseconds / 1e9
        self.timeouts.append(seconds)
        if self.ack_after is not None and self.ack_after <= seconds:
            self.now[0] += self.ack_after
            return True
        self.now[0] += seconds
        return False


def test_twenty_publishers_never_acked_wait_the_timeout_once_not_twenty_times() -> None:
    now = [0.0]
    pubs = [FakePublisher(now, None) for _ in range(20)]
    assert wait_all_acked(pubs, 1.0, clock=lambda: now[0]) is False
    assert now[0] == 1.0  # a node closing twenty outputs waits 1 s, not 20 s
    assert [p.timeouts[0] for p in pubs[:2]] == [1.0, 0.0] and len({p.timeouts[0] for p in pubs[1:]}) == 1


def test_publishers_acked_in_time_report_true_and_each_is_asked() -> None:
    now = [0.0]
    pubs = [FakePublisher(now, 0.1) for _ in range(3)]
    assert wait_all_acked(pubs, 1.0, clock=lambda: now[0]) is True
    assert all(len(p.timeouts) == 1 for p in pubs) and abs(now[0] - 0.3) < 1e-9


def test_one_publisher_not_acked_makes_the_answer_false() -> None:
    now = [0.0]
    pubs = [FakePublisher(now, 0.1), FakePublisher(now, None), FakePublisher(now, 0.0)]
    assert wait_all_acked(pubs, 1.0, clock=lambda: now[0]) is False
    assert now[0] == 1.0 and len(pubs[2].timeouts) == 1  # the last one is still asked (with 0 s left)

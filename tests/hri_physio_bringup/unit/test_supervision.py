"""The launcher's restart policy on an injected clock: backoff, limits, essential nodes, receiver gaps."""

from __future__ import annotations

import pytest

from hri_physio_bringup.plan import COACH, CONTROLLER, HR_RECEIVER, PARTICIPANT, POLAR_STREAMER, RECORDER
from hri_physio_bringup.supervision import (
    NODE_DIED,
    NODE_RESTARTED,
    RECEIVER_GAP,
    RESTARTABLE,
    Backoff,
    Loss,
    Restart,
    Supervisor,
    gap_line,
    restarts_text,
    status_text,
)


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_backoff_doubles_from_half_a_second_up_to_eight() -> None:
    assert [Backoff().delay(n) for n in range(1, 8)] == [0.5, 1.0, 2.0, 4.0, 8.0, 8.0, 8.0]


def test_the_essential_nodes_are_not_restartable() -> None:
    assert not {COACH, RECORDER, PARTICIPANT, POLAR_STREAMER} & RESTARTABLE


def test_a_restartable_node_is_restarted_after_its_backoff_and_the_record_says_how_long_it_was_down() -> None:
    clock = FakeClock()
    sup = Supervisor(max_restarts=3, monotonic=clock)
    record = sup.died(CONTROLLER, -9, sim_t=1000.0)
    assert isinstance(record, Restart) and sup.pending(CONTROLLER)
    assert sup.awaiting_restart() == [CONTROLLER] and record.record()["restarted_t"] is None
    assert sup.due() == []
    clock.now += 0.49
    assert sup.due() == []
    clock.now += 0.02
    assert sup.due() == [record] and sup.due() == [] and not sup.pending(CONTROLLER)
    assert sup.awaiting_restart() == []
    sup.started(record, sim_t=1007.5)
    assert record.event() == {"t": 1007.5, "event": NODE_RESTARTED, "node": CONTROLLER, "exit_status": -9,
                              "down_s": 7.5, "restart": 1}
    assert record.line(3) == ("[session] restarted qt_controller (1 of 3): it died with exit status "
                              "-9 (SIGKILL), down 7.5 s of session time")
    assert record.record()["restarted_t"] == 1007.5 and record.record()["gap"] is None


def test_the_second_restart_waits_twice_as_long_and_the_limit_ends_the_session() -> None:
    clock = FakeClock()
    sup = Supervisor(max_restarts=2, monotonic=clock)
    for n, wait in ((1, 0.5), (2, 1.0)):
        record = sup.died(CONTROLLER, 1, sim_t=float(n))
        assert isinstance(record, Restart) and record.restart == n
        clock.now += wait - 0.01
        assert sup.due() == []
        clock.now += 0.02
        sup.started(sup.due()[0], sim_t=n + 0.5)
    loss = sup.died(CONTROLLER, 1, sim_t=9.0)
    assert isinstance(loss, Loss) and sup.loss is loss and not loss.essential and loss.restarts == 2
    assert loss.event() == {"t": 9.0, "event": NODE_DIED, "node": CONTROLLER, "exit_status": 1, "restart": 2,
                            "reason": "restart limit"}
    assert loss.problem(2) == ("qt_controller died with exit status 1, after 2 restart(s), the limit "
                               "(--max-restarts 2)")
    assert [r.restart for r in sup.records] == [1, 2]


@pytest.mark.parametrize("node", [COACH, RECORDER, PARTICIPANT, POLAR_STREAMER, "a_node_of_the_future"])
def test_the_loss_of_an_essential_node_ends_the_session(node: str) -> None:
    sup = Supervisor(monotonic=FakeClock())
    loss = sup.died(node, -9, sim_t=5.0, last_words="boom")
    assert isinstance(loss, Loss) and loss.essential and sup.records == []
    assert loss.problem(3) == (f"{node} died with exit status -9 (SIGKILL), an essential node: the session "
                               "cannot go on without it (boom)")
    assert loss.event()["reason"] == "essential"


def test_no_restarts_at_all_with_a_limit_of_zero_and_a_negative_limit_is_refused() -> None:
    assert isinstance(Supervisor(max_restarts=0).died(CONTROLLER, -9, 0.0), Loss)
    with pytest.raises(ValueError, match="max_restarts must be >= 0"):
        Supervisor(max_restarts=-1)


def test_the_first_loss_is_the_one_kept() -> None:
    sup = Supervisor(monotonic=FakeClock())
    first = sup.died(COACH, -9, 1.0)
    sup.died(RECORDER, -15, 2.0)
    assert sup.loss is first


def test_a_receivers_gap_runs_from_its_last_sample_before_the_restart_to_its_first_after() -> None:
    clock = FakeClock()
    sup = Supervisor(monotonic=clock)
    assert not sup.tracks(HR_RECEIVER)
    sup.track(HR_RECEIVER)
    assert sup.tracks(HR_RECEIVER) and sup.watching() == []
    assert sup.output(HR_RECEIVER, [10.0, 11.0]) is None
    record = sup.died(HR_RECEIVER, -9, sim_t=50.0)
    assert isinstance(record, Restart)
    assert sup.output(HR_RECEIVER, [12.0]) is None  # in flight from the dead process: before the restart
    clock.now += 1.0
    sup.started(sup.due()[0], sim_t=60.0)
    assert sup.watching() == [HR_RECEIVER]  # the launcher takes its output until the gap closes
    closed = sup.output(HR_RECEIVER, [19.0, 20.0])
    assert closed is record and record.gap == (12.0, 19.0)
    assert sup.watching() == []
    assert record.gap_event(1.0) == {"t": 60.0, "event": RECEIVER_GAP, "node": HR_RECEIVER, "restart": 1,
                                     "last_before": 12.0, "first_after": 19.0, "missing": 6}
    assert gap_line(record.gap_event(1.0)) == ("[session] hr_receiver publishes again: 6 sample(s) of its "
                                               "source were lost while it was down (source time "
                                               "12.000 .. 19.000)")
    assert "an unknown number of sample(s)" in gap_line(record.gap_event(None))
    assert sup.output(HR_RECEIVER, [21.0]) is None  # closed once
    record.missing = 6
    assert record.record()["gap"] == {"last_before": 12.0, "first_after": 19.0, "missing": 6}


def test_a_receiver_restarted_twice_before_it_published_has_one_gap_on_its_last_restart() -> None:
    clock = FakeClock()
    sup = Supervisor(monotonic=clock)
    sup.track(HR_RECEIVER)
    sup.output(HR_RECEIVER, [5.0])
    for sim_t in (10.0, 20.0):
        sup.died(HR_RECEIVER, -9, sim_t=sim_t)
        clock.now += 10.0
        sup.started(sup.due()[0], sim_t=sim_t + 1)
    sup.output(HR_RECEIVER, [30.0])
    assert [r.gap for r in sup.records] == [None, (5.0, 30.0)]


def test_a_receiver_that_never_published_before_its_restart_has_no_gap_to_tell() -> None:
    clock = FakeClock()
    sup = Supervisor(monotonic=clock)
    sup.track(HR_RECEIVER)
    sup.died(HR_RECEIVER, -9, sim_t=1.0)
    clock.now += 1.0
    record = sup.due()[0]
    sup.started(record, 2.0)
    assert sup.output(HR_RECEIVER, [3.0]) is None and record.gap is None


def test_exit_statuses_in_words() -> None:
    assert status_text(-9) == "-9 (SIGKILL)" and status_text(1) == "1" and status_text(-200) == "-200"


def test_the_closing_line_names_each_restart_its_downtime_and_what_a_receiver_lost() -> None:
    clock = FakeClock()
    sup = Supervisor(monotonic=clock)
    sup.track(HR_RECEIVER)
    sup.output(HR_RECEIVER, [1.0])
    sup.died(HR_RECEIVER, -9, sim_t=10.0)
    sup.died(CONTROLLER, 1, sim_t=11.0)
    clock.now += 0.5
    for record in sup.due():
        sup.started(record, sim_t=record.died_t + 2)
    closed = sup.output(HR_RECEIVER, [5.0])
    assert closed is not None
    closed.missing = closed.gap_event(1.0)["missing"]
    sup.died(CONTROLLER, -11, sim_t=20.0)  # waiting for its second restart when the session ends
    assert restarts_text([r.record() for r in sup.records]) == (
        "[session] nodes that died and their restarts (3): hr_receiver after exit status -9 (SIGKILL) "
        "(down 2 s, 3 sample(s) of its source lost), qt_controller after exit status 1 (down 2 s), "
        "qt_controller after exit status -11 (SIGSEGV) (not restarted before the end)")

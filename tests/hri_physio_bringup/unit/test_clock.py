"""The session's sim clock and the guard that holds it while the loop lags (injected wall clock)."""

from __future__ import annotations

import pytest

from hri_physio_bringup.clock import (
    CLOCK_STEP,
    DECISION,
    HR,
    MEDIA,
    ROBOT,
    UPTAKE,
    ClockGuard,
    ClockHistory,
    SimClock,
)
from hri_physio_coach.participant.perception import message_key, parse_receipt, receipt


class Wall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_sim_clock_steps_keep_up_with_the_wall_clock_at_its_speed() -> None:
    wall = Wall()
    clock = SimClock(start=1000.0, speed=30.0, monotonic=wall)
    assert clock.due_steps() == []
    wall.t += 0.01  # 0.3 s of sim time: three steps
    assert clock.due_steps() == pytest.approx([1000.0 + CLOCK_STEP * k for k in (1, 2, 3)])
    wall.t += 0.001  # 0.03 s: not a whole step yet
    assert clock.due_steps() == []


def test_sim_clock_values_stay_on_the_step_grid_at_epoch_times() -> None:
    """At ~1.8e9 s every float sum rounds: summed step by step, 1035 steps of 0.1 s end up 1e-4 s short of
    103.5 s, enough to put an instruction on another 5-s mark than the evaluation's."""
    wall = Wall()
    start = 1795747467.0
    clock = SimClock(start=start, speed=10.0, monotonic=wall)
    values: list[float] = []
    for k in range(1035):
        wall.t = 100.0 + (k + 1) * 0.01 + 1e-9
        values += clock.due_steps()
    assert len(values) == 1035
    assert values[-1] == start + 1035 * CLOCK_STEP and values[-1] - start == 103.5


def test_the_sim_clock_says_when_its_next_step_is_due() -> None:
    """The launcher sleeps until then: at 1x once per step, not 100 times a second."""
    wall = Wall()
    clock = SimClock(start=1000.0, speed=1.0, monotonic=wall)
    assert clock.next_step_in() == pytest.approx(CLOCK_STEP)
    wall.t += 0.04
    assert clock.next_step_in() == pytest.approx(CLOCK_STEP - 0.04)
    wall.t += 0.07  # due since 0.01 s
    assert clock.next_step_in() == 0.0
    assert len(clock.due_steps()) == 1
    assert clock.next_step_in() == pytest.approx(CLOCK_STEP - 0.01)
    fast = SimClock(start=0.0, speed=30.0, monotonic=wall)
    assert fast.next_step_in() == pytest.approx(CLOCK_STEP / 30)


def test_past_its_limit_the_clock_runs_at_real_time_and_goes_on_at_its_speed_without_catching_up() -> None:
    wall = Wall()
    clock = SimClock(start=0.0, speed=10.0, monotonic=wall)
    wall.t += 1.0  # 10 s due at 10x, but only 2 s allowed: the clock reaches 2 s
    assert clock.due_steps(limit=2.0)[-1] == pytest.approx(2.0)
    wall.t += 1.0  # held: one second of wall time is one second of sim time
    steps = clock.due_steps(limit=2.0)
    assert steps[0] == pytest.approx(2.1) and steps[-1] == pytest.approx(3.0)
    assert clock.held_wall == pytest.approx(0.8 + 0.9)  # 8 s lost in the first second, 9 s in the second
    wall.t += 0.5  # released: 5 s of sim from where it stood, not what it would have reached
    steps = clock.due_steps()
    assert steps[0] == pytest.approx(3.1) and steps[-1] == pytest.approx(8.0)


def test_a_clock_at_real_time_is_not_slowed_by_a_limit() -> None:
    wall = Wall()
    clock = SimClock(start=0.0, speed=1.0, monotonic=wall)
    wall.t += 3.0
    assert clock.due_steps(limit=0.5)[-1] == pytest.approx(3.0) and clock.held_wall == 0.0


def test_the_guard_holds_for_heart_rate_that_has_not_come_through() -> None:
    wall = Wall()
    guard = ClockGuard(hr_lag=2.0, monotonic=wall)
    assert guard.limit(10.0) is None  # nothing seen yet: no limit
    # Samples stamped on another clock (offset 5000 s), arriving 0.1-0.4 s (sim) after they were taken.
    for taken, delay in ((10.0, 0.3), (11.0, 0.1), (12.0, 0.4)):
        guard.hr_sample(5000.0 + taken, taken + delay)
    # The least delayed sample sets the offset: a sample counts as taken 0.1 s before it arrives.
    assert guard.limit(12.4) == pytest.approx(12.0 + 0.1 + 2.0)
    assert guard.limit(14.1) == pytest.approx(14.1) and guard.holds == {HR: 1}
    assert guard.limit(14.1) == pytest.approx(14.1) and guard.holds == {HR: 1}  # the same hold
    guard.hr_sample(5013.0, 14.1)
    assert guard.limit(14.1) == pytest.approx(15.1)


def test_the_guard_holds_for_unanswered_commands_and_unsettled_audio_requests() -> None:
    guard = ClockGuard(reply_lag=1.0, monotonic=Wall())
    guard.command_sent(20.0)
    guard.command_sent(20.5)
    guard.media_requested(20.2)
    assert guard.limit(20.0) == pytest.approx(21.0)
    guard.command_answered()
    assert guard.limit(20.0) == pytest.approx(21.2)  # now the audio request is the oldest
    guard.media_settled(1)
    assert guard.limit(20.0) == pytest.approx(21.5)
    guard.command_answered()
    assert guard.limit(20.0) is None
    guard.media_settled(1)  # a status repeating the same counts settles nothing more
    guard.media_requested(30.0)
    assert guard.limit(30.0) == pytest.approx(31.0)


def test_an_answer_heard_before_its_request_settles_the_request_when_it_is_heard() -> None:
    guard = ClockGuard(reply_lag=1.0, monotonic=Wall())
    guard.media_settled(1)  # the streamer's status came first (another topic, another node)
    guard.media_requested(5.0)
    assert guard.limit(5.0) is None
    guard.command_answered()
    guard.command_sent(6.0)
    guard.command_sent(6.5)
    assert guard.limit(6.0) == pytest.approx(7.5)


def test_a_hold_is_given_up_after_max_hold_and_counted() -> None:
    wall = Wall()
    guard = ClockGuard(reply_lag=1.0, max_hold=5.0, monotonic=wall)
    guard.command_sent(50.0)  # the controller died: no answer will come
    assert guard.limit(51.0) == pytest.approx(51.0) and guard.holds == {ROBOT: 1}
    wall.t += 4.0
    assert guard.limit(51.0) == pytest.approx(51.0)
    wall.t += 1.5
    assert guard.limit(51.0) is None and guard.released == {ROBOT: 1}
    guard.media_requested(60.0)
    wall.t += 1.0
    assert guard.limit(61.0) == pytest.approx(61.0)
    wall.t += 6.0
    assert guard.limit(61.0) is None and guard.released == {ROBOT: 1, MEDIA: 1}
    clock = SimClock(0.0, 1.0, monotonic=wall)
    assert guard.report(clock) == {"held_wall_s": 0.0, "holds": {ROBOT: 1, MEDIA: 1},
                                   "released": {ROBOT: 1, MEDIA: 1}, "late_uptakes": 0}


def test_a_limit_less_than_a_step_ahead_holds_the_clock_and_is_given_up_in_time() -> None:
    wall = Wall()
    guard = ClockGuard(reply_lag=1.0, max_hold=5.0, monotonic=wall)
    guard.command_sent(10.0)
    assert guard.limit(10.95) == pytest.approx(11.0) and guard.holds == {ROBOT: 1}  # no whole step left
    wall.t += 5.5
    assert guard.limit(10.95) is None and guard.released == {ROBOT: 1}


def test_a_strap_gone_quiet_is_released_until_its_next_sample() -> None:
    wall = Wall()
    guard = ClockGuard(hr_lag=2.0, max_hold=5.0, monotonic=wall)
    guard.hr_sample(100.0, 100.0)
    assert guard.limit(102.0) == pytest.approx(102.0)
    wall.t += 6.0
    assert guard.limit(102.0) is None and guard.released == {HR: 1}
    guard.hr_sample(130.0, 130.0)  # back: held to it again
    assert guard.limit(131.0) == pytest.approx(132.0)


def test_the_clock_stops_before_a_rule_updates_wait_ends_until_the_coach_has_decided() -> None:
    wall = Wall()
    guard = ClockGuard(hr_wait=3.0, max_hold=5.0, monotonic=wall)
    guard.coach_decision(540.0)
    assert guard.limit(530.0) == pytest.approx(542.9) and guard.stop == pytest.approx(542.9)
    assert not guard.holds  # far off: no hold
    assert guard.limit(542.9) == pytest.approx(542.9) and guard.holds == {DECISION: 1}
    clock = SimClock(start=542.9, speed=20.0, monotonic=wall)
    wall.t += 1.0
    assert clock.due_steps(guard.limit(clock.t), guard.stop) == []  # stopped, not slowed
    guard.coach_decision(570.0)  # decided: the next one is 30 s on
    assert guard.limit(542.9) == pytest.approx(572.9) and guard.holds == {DECISION: 1}
    guard.coach_decision(None)
    assert guard.limit(542.9) is None


def test_the_clock_stops_at_a_rule_update_the_coach_has_not_reached_and_runs_on_while_it_waits() -> None:
    """A coach slowed down for a moment (the predictive policy's first plan) decides at the
    rule update's own time, not up to hr_wait later: what it sends then still reaches the person
    before the next mark."""
    wall = Wall()
    guard = ClockGuard(hr_wait=3.0, max_hold=5.0, monotonic=wall)
    guard.coach_decision(120.0, waiting=False)
    assert guard.limit(119.0) == pytest.approx(120.05) and guard.stop == pytest.approx(120.05)
    clock = SimClock(start=119.0, speed=10.0, monotonic=wall)
    wall.t += 1.0
    assert clock.due_steps(guard.limit(clock.t), guard.stop)[-1] == pytest.approx(120.0)
    guard.coach_decision(120.0, waiting=True)  # reached: it waits for late heart rate
    assert guard.limit(clock.t) == pytest.approx(122.9)
    guard.coach_decision(150.0, waiting=False)  # decided
    assert guard.limit(clock.t) == pytest.approx(150.05)


def test_a_coach_that_never_decides_is_given_up_on_after_max_hold() -> None:
    wall = Wall()
    guard = ClockGuard(hr_wait=3.0, max_hold=5.0, monotonic=wall)
    guard.coach_decision(100.0)
    assert guard.limit(102.9) == pytest.approx(102.9)
    wall.t += 6.0
    assert guard.limit(102.9) is None and guard.released == {DECISION: 1}
    guard.coach_decision(130.0)
    assert guard.limit(102.9) == pytest.approx(132.9)


def test_after_a_lost_answer_is_given_up_later_answered_commands_hold_nothing() -> None:
    """One reply lost for good (say, sent before the guard's subscription matched) must not leave
    every later command looking unanswered: the release counts afresh."""
    wall = Wall()
    guard = ClockGuard(reply_lag=1.0, max_hold=5.0, monotonic=wall)
    guard.command_sent(10.0)  # its reply is never heard
    guard.command_sent(10.5)
    guard.command_answered()  # the answer to the second one (counted against the first)
    assert guard.limit(11.5) == pytest.approx(11.5)  # held: the count says one is still open
    wall.t += 5.5
    assert guard.limit(11.5) is None and guard.released == {ROBOT: 1}
    for k in range(5):  # later commands, each answered: none holds the clock
        guard.command_sent(20.0 + k)
        guard.command_answered()
        assert guard.limit(21.5 + k) is None
    assert guard.holds == {ROBOT: 1}


def test_a_restarted_streamer_counting_from_zero_again_still_settles_requests() -> None:
    """The streamer's status reports running totals; a restart starts them at 0 again. Its answers
    count on top of the old ones, so later requests are settled, not held until given up."""
    wall = Wall()
    guard = ClockGuard(reply_lag=1.0, max_hold=5.0, monotonic=wall)
    for k in range(3):
        guard.media_requested(10.0 + k)
        guard.media_settled(k + 1)
    assert guard.limit(13.0) is None
    guard.media_settled(0)  # the restarted streamer's first status
    guard.media_requested(20.0)
    assert guard.limit(20.0) == pytest.approx(21.0)  # not answered yet
    guard.media_settled(1)
    assert guard.limit(20.0) is None and not guard.holds.get(MEDIA)
    guard.media_settled(1)  # the same count again settles nothing more
    guard.media_requested(30.0)
    assert guard.limit(30.0) == pytest.approx(31.0)
    guard.media_settled(2)
    assert guard.limit(30.0) is None


COMMANDS, STATUS = "/QtController/input", "/audio_streamer/status"


def test_the_clock_stops_short_of_a_participants_uptake_until_the_participant_confirms() -> None:
    """An instruction heard at 120.3 s (session start 5 s, marks every 5 s) is taken up at 125 s if the
    person hears it by 123.5 s: the clock stops half a step before that until the receipt comes."""
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, max_hold=5.0, monotonic=wall)
    guard.instruction(COMMANDS, message_key("gesture play rest 0.5"), 3.0)
    assert guard.limit(3.0) is None  # before the session start: taken up at once, nothing to hold
    guard.session_started(5.0)
    line = "gesture play step_up 0.9"
    guard.instruction(COMMANDS, message_key(line), 120.3)
    assert guard.limit(120.3) == pytest.approx(123.45) and guard.stop == pytest.approx(123.45)
    clock = SimClock(start=120.3, speed=10.0, monotonic=wall)
    wall.t += 1.0  # 10 s due at 10x: the clock stops at 123.4, the last step before 123.45
    assert clock.due_steps(guard.limit(clock.t), guard.stop)[-1] == pytest.approx(123.4)
    assert guard.limit(clock.t) == pytest.approx(123.45) and guard.holds == {UPTAKE: 1}
    wall.t += 1.0
    assert clock.due_steps(guard.limit(clock.t), guard.stop) == []
    topic, key, heard_at = parse_receipt(receipt(COMMANDS, line, 123.4))
    guard.participant_heard(topic, key, heard_at)
    assert guard.limit(clock.t) is None and guard.stop is None and guard.late_uptakes == 0


def test_a_soft_hold_before_an_uptake_lets_the_clock_creep_only_up_to_the_uptakes_stop() -> None:
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, reply_lag=1.0, monotonic=wall)
    guard.session_started(0.0)
    guard.command_sent(120.0)  # no reply yet: slowed to real time from 121 s
    guard.instruction(COMMANDS, message_key("gesture play marching 1.0"), 120.0)
    clock = SimClock(start=120.0, speed=10.0, monotonic=wall)
    wall.t += 10.0  # at real time from 121 s, it would reach 130 s: it stops at 123.4
    steps = clock.due_steps(guard.limit(clock.t), guard.stop)
    assert steps[-1] == pytest.approx(123.4)


def test_a_receipt_heard_before_its_instruction_confirms_it_and_a_late_one_is_counted() -> None:
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, monotonic=wall)
    guard.session_started(100.0)
    status = '{"state": "playing", "tempo": 130}'
    guard.participant_heard(STATUS, message_key(status), 101.0)  # the participant's receipt came first
    guard.instruction(STATUS, message_key(status), 101.0)
    assert guard.limit(101.0) is None and guard.late_uptakes == 0
    # Heard at 110.2 s (mark 115 s) but taken in at 113.6 s: the person takes it up at 120 s.
    guard.instruction(STATUS, message_key(status), 110.2)
    guard.participant_heard(STATUS, message_key(status), 113.6)
    assert guard.limit(113.6) is None and guard.late_uptakes == 1
    # The same text twice: each receipt confirms one of them.
    guard.instruction(COMMANDS, message_key("say hi"), 121.0)
    guard.instruction(COMMANDS, message_key("say hi"), 121.2)
    guard.participant_heard(COMMANDS, message_key("say hi"), 121.1)
    assert guard.limit(121.2) == pytest.approx(123.45)
    guard.participant_heard(COMMANDS, message_key("say hi"), 121.3)
    assert guard.limit(121.3) is None and guard.late_uptakes == 1
    # Sent at 130 s (mark 135 s) but stamped 128.2 s by a participant whose clock lagged: mark 130 s.
    guard.instruction(COMMANDS, message_key("gesture play step_up 1.0"), 130.0)
    guard.participant_heard(COMMANDS, message_key("gesture play step_up 1.0"), 128.2)
    report = guard.report(SimClock(start=100.0, speed=10.0, monotonic=wall))
    assert report["late_uptakes"] == 1 and report["early_uptakes"] == 1
    assert [e["heard_s"] for e in report["late_examples"]] == [13.6, 28.2]  # type: ignore[union-attr]


def test_a_participant_that_never_confirms_is_given_up_on_after_max_hold() -> None:
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, max_hold=5.0, monotonic=wall)
    guard.session_started(0.0)
    guard.instruction(COMMANDS, message_key("gesture play rest 0.5"), 20.0)
    assert guard.limit(23.45) == pytest.approx(23.45) and guard.holds == {UPTAKE: 1}
    wall.t += 6.0
    assert guard.limit(23.45) is None and guard.released == {UPTAKE: 1}


def test_no_uptake_is_waited_for_without_a_participant_or_with_one_that_reacts_at_once() -> None:
    guard = ClockGuard(reaction_period=0.0, monotonic=Wall())
    guard.session_started(0.0)
    guard.instruction(COMMANDS, message_key("gesture play rest 0.5"), 20.0)
    assert guard.limit(20.0) is None


@pytest.mark.parametrize("text", ["", "[]", '{"topic": "/x", "key": "1", "t": 2.0}',
                                  '{"topic": "/x", "key": 1, "t": NaN}',
                                  '{"topic": "/x", "key": true, "t": 1}', '{"key": 1, "t": 1.0}'])
def test_what_is_not_a_receipt_is_said_so(text: str) -> None:
    assert parse_receipt(text) is None


def test_a_receipt_for_an_instruction_before_the_session_confirms_nothing_later() -> None:
    """The same status text before and after the session start: the early one's receipt must not
    stand in for the later one's (the clock would run on without the participant having heard it)."""
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, max_hold=5.0, monotonic=wall)
    status = '{"state": "playing", "tempo": 120}'
    guard.instruction(STATUS, message_key(status), 10.0)  # before the session: nothing to hold for
    assert guard.limit(10.0) is None
    guard.participant_heard(STATUS, message_key(status), 10.0)
    guard.session_started(30.0)
    guard.instruction(STATUS, message_key(status), 40.2)
    assert guard.limit(40.2) == pytest.approx(43.45)
    guard.participant_heard(STATUS, message_key(status), 40.3)
    assert guard.limit(40.3) is None and guard.late_uptakes == 0


def test_receipts_and_instructions_never_matched_are_forgotten_after_max_hold() -> None:
    wall = Wall()
    guard = ClockGuard(reaction_period=5.0, max_hold=5.0, monotonic=wall)
    guard.participant_heard(COMMANDS, message_key("say hello"), 5.0)  # for a command the launcher missed
    guard.instruction(COMMANDS, message_key("say bye"), 5.0)  # the participant missed it, before the session
    wall.t += 6.0
    guard.session_started(10.0)
    guard.instruction(COMMANDS, message_key("say hello"), 20.0)  # the old receipt does not confirm it
    assert guard.limit(20.0) == pytest.approx(23.45)
    guard.participant_heard(COMMANDS, message_key("say bye"), 20.5)  # nor does a new one for the forgotten
    assert guard.limit(20.5) == pytest.approx(23.45)


def test_the_clock_history_dates_a_message_by_the_value_that_was_newest_when_it_went_out() -> None:
    history = ClockHistory(size=3)
    assert history.at(1_000) is None
    for k in range(4):  # 100.0 at 1000 ns, 100.1 at 2000 ns, ...; the first falls out
        history.published(1_000 * (k + 1), 100.0 + k / 10)
    assert history.at(3_500) == pytest.approx(100.2)
    assert history.at(2_000) == pytest.approx(100.1)
    assert history.at(9_999) == pytest.approx(100.3)
    assert history.at(1_500) is None  # older than what is kept: the caller uses its own clock

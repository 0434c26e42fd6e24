"""The effective rate of a PMD stream from device times and sample counts."""

from __future__ import annotations

import pytest

from hri_physio_bridge.polar.devices import PPG_RATES
from hri_physio_bridge.polar.rate_check import NS, RateCheck

T0 = 599_616_028_000_000_000  # an H10's clock: 2019-01-01 + 28 s


def frames(
    rate: float, samples: int, count: int, lose: frozenset[int] = frozenset(),
) -> list[tuple[int, int]]:
    """(device time of the last sample, samples) of ``count`` frames sampled at ``rate``."""
    out = []
    for k in range(count):
        if k not in lose:
            out.append((T0 + round(((k + 1) * samples - 1) * NS / rate), samples))
    return out


def verdict_of(check: RateCheck, items: list[tuple[int, int]]):
    for t, n in items:
        verdict = check.add(t, n)
        if verdict is not None:
            return verdict
    return check.verdict()


def test_the_announced_rate_stands_when_the_frames_agree() -> None:
    verdict = verdict_of(RateCheck(130.0, known_rates=(130,)), frames(130.045, 73, 6))  # an H10's crystal
    assert not verdict.corrected and verdict.rate == 130.0 and verdict.pairs == 4
    assert verdict.measured == pytest.approx(130.045, rel=1e-4)


def test_a_wrong_announced_rate_is_measured_and_corrected() -> None:
    """Announced 135 Hz, sent 55 Hz (42 samples per ~762 ms); the nearest known rate is taken."""
    verdict = verdict_of(RateCheck(135.0, known_rates=PPG_RATES), frames(55.12, 42, 6))
    assert verdict.corrected and verdict.rate == 55
    assert verdict.measured == pytest.approx(55.12, rel=1e-3)


def test_an_unknown_rate_is_given_as_measured() -> None:
    verdict = verdict_of(RateCheck(100.0, known_rates=(25, 50, 100, 200)), frames(77.3, 20, 6))
    assert verdict.corrected and verdict.rate == pytest.approx(77.3, abs=0.01)


def test_a_lost_frame_is_not_a_rate() -> None:
    items = frames(130.0, 73, 7, lose=frozenset({2}))
    verdict = verdict_of(RateCheck(130.0), items)
    assert not verdict.corrected
    items = frames(55.0, 42, 8, lose=frozenset({3}))  # a corrected rate ignores the pair with the loss
    verdict = verdict_of(RateCheck(135.0, known_rates=PPG_RATES), items)
    assert verdict.rate == 55 and verdict.measured == pytest.approx(55.0, rel=1e-4)


def test_duplicates_and_reordered_frames_give_no_pair() -> None:
    items = frames(130.0, 73, 6)
    check = RateCheck(130.0)
    assert check.add(*items[0]) is None
    assert check.add(*items[0]) is None  # duplicate
    assert check.add(*items[1]) is None
    assert check.add(*items[0]) is None  # backwards
    assert check.verdict().pairs == 1


def test_too_few_pairs_leave_the_announced_rate() -> None:
    check = RateCheck(135.0, known_rates=PPG_RATES)
    for t, n in frames(55.0, 42, 3):
        assert check.add(t, n) is None
    verdict = check.verdict()
    assert verdict.pairs == 2 and not verdict.corrected
    assert RateCheck(135.0).verdict().pairs == 0


def test_the_announced_rate_must_be_positive() -> None:
    with pytest.raises(ValueError, match="must be > 0"):
        RateCheck(0.0)


def test_the_announced_rate_stands_while_frames_are_off_by_less_than_a_quarter_sample() -> None:
    """0.6 % off: nothing for frames of 10 samples (0.06 sample), a gap every frame for 73 (0.44)."""
    short = verdict_of(RateCheck(100.0, known_rates=(100,)), frames(100.6, 10, 6))
    assert not short.corrected
    long = verdict_of(RateCheck(130.0, known_rates=(130,)), frames(130.78, 73, 6))
    assert long.corrected and long.rate == pytest.approx(130.78, abs=0.01)  # 130 is too far for 73 samples

"""Heart-rate zone maths (thesis ch. 4 numbers, Fig. 4.13) and the speed ladder."""

from __future__ import annotations

import numpy as np
import pytest

from hri_physio_coach.ladder import SpeedLadder
from hri_physio_coach.media_names import TEMPO_RANGE, base_name, tempo_from_name
from hri_physio_coach.participant.perception import tempo_from_audio
from hri_physio_coach.policies.simple import FuzzyPolicy
from hri_physio_coach.zones import HeartRateZone, fuzzy_probability, tanaka_hr_max

# The thesis reports values rounded to 0.1 bpm; allow that rounding (plus float noise).
THESIS = 0.05 + 1e-9


@pytest.fixture
def pilot() -> HeartRateZone:
    """The thesis pilot: age 33, seated HR_rest 85.4 bpm."""
    return HeartRateZone.from_age(33, 85.4)


def test_thesis_numbers(pilot: HeartRateZone) -> None:
    assert pilot.hr_max == pytest.approx(184.9, abs=THESIS)
    assert pilot.hrr == pytest.approx(184.9 - 85.4, abs=1e-9)
    assert pilot.low == pytest.approx(125.2, abs=THESIS)  # HRR40
    assert pilot.high == pytest.approx(155.1, abs=THESIS)  # HRR70
    # HR_target is the zone centre. The thesis's 140.2 is the mean of its rounded bounds
    # (125.2 + 155.1) / 2 = 140.15; the unrounded centre is 140.125.
    assert pilot.target == pytest.approx((pilot.low + pilot.high) / 2)
    assert (round(pilot.low, 1) + round(pilot.high, 1)) / 2 == pytest.approx(140.2, abs=THESIS)
    assert pilot.target == pytest.approx(140.125, abs=1e-9)


def test_tanaka_and_karvonen() -> None:
    assert tanaka_hr_max(20) == pytest.approx(194.0)
    assert tanaka_hr_max(70) == pytest.approx(159.0)
    zone = HeartRateZone(60.0, 180.0, 0.5, 0.8)
    assert (zone.low, zone.high, zone.target) == pytest.approx((120.0, 156.0, 138.0))
    assert zone.fraction_of_reserve(120.0) == pytest.approx(0.5)
    assert [zone.classify(hr) for hr in (119.9, 120.0, 156.0, 156.1)] == ["below", "in", "in", "above"]


@pytest.mark.parametrize("age", [0, -1, 121, float("nan")])
def test_invalid_age(age: float) -> None:
    with pytest.raises(ValueError, match="age"):
        tanaka_hr_max(age)


@pytest.mark.parametrize("low,high", [(0.7, 0.4), (0.5, 0.5), (-0.1, 0.5), (0.4, 1.2)])
def test_zone_bounds_out_of_order(low: float, high: float) -> None:
    with pytest.raises(ValueError, match="zone bounds"):
        HeartRateZone(80.0, 180.0, low, high)


def test_resting_must_be_below_max() -> None:
    with pytest.raises(ValueError, match="below the maximum"):
        HeartRateZone(190.0, 184.9)


def test_fig_4_13_probability(pilot: HeartRateZone) -> None:
    p = pilot.adaptation_probability
    # 1 at and below HRR40, 1 at and above HRR70 (thesis values and exact bounds).
    for hr in (60.0, 110.0, 125.0, pilot.low, 125.2, pilot.high, 155.1, 170.0, 220.0):
        assert p(hr) == pytest.approx(1.0), hr
    # 0 at the target; the thesis's rounded 140.2 is 0.075 bpm off-centre, so p there is ~0.005.
    assert p(pilot.target) == 0.0
    assert p(140.2) == pytest.approx((140.2 - pilot.target) / (pilot.target - pilot.low))
    assert p(140.2) < 0.01
    # Linear in between, symmetric about the target.
    half = pilot.target - pilot.low
    for frac in (0.1, 0.25, 0.5, 0.75, 0.9):
        assert p(pilot.target - frac * half) == pytest.approx(frac)
        assert p(pilot.target + frac * half) == pytest.approx(frac)
    hrs = np.linspace(pilot.low, pilot.target, 50)
    values = [p(h) for h in hrs]
    assert all(np.diff(values) < 0)
    slopes = np.diff(values) / np.diff(hrs)
    assert np.allclose(slopes, -1 / half)
    # The policy exposes the same curve for plotting.
    assert FuzzyPolicy.probability(132.0, pilot) == fuzzy_probability(132.0, pilot)
    with pytest.raises(ValueError):
        p(float("nan"))


def test_ladder_steps_within_limits() -> None:
    ladder = SpeedLadder([0.90, 0.95, 1.00, 1.05, 1.10, 1.15], ["110", "115", "120", "125", "130", "135"], 1)
    assert (ladder.speed, ladder.tempo) == (0.95, 115.0)
    assert ladder.step(-1) and ladder.at_bottom
    assert not ladder.step(-1)
    assert (ladder.index, ladder.speed, ladder.tempo) == (0, 0.90, 110.0)
    for _ in range(10):
        ladder.step(+1)
    assert ladder.at_top and (ladder.speed, ladder.tempo) == (1.15, 135.0)
    assert not ladder.step(+1) and not ladder.can_step(1)
    assert not ladder.step(0)
    assert ladder.state() == {"index": 5, "speed": 1.15, "suffix": "135", "tempo": 135.0}


@pytest.mark.parametrize(
    "speeds,suffixes,start,match",
    [
        ([], [], 0, "empty"),
        ([1.0, 1.1], ["120"], 0, "audio_suffix"),
        ([1.0, 1.1], ["120", "125"], 2, "start index"),
        ([1.1, 1.0], ["120", "125"], 0, "increase"),
        ([0.0, 1.0], ["120", "125"], 0, "> 0"),
    ],
)
def test_ladder_rejects_bad_definitions(speeds: list[float], suffixes: list[str], start: int,
                                        match: str) -> None:
    with pytest.raises(ValueError, match=match):
        SpeedLadder(speeds, suffixes, start)


@pytest.mark.parametrize(
    "name,tempo",
    [
        ("125", 125.0),  # a ladder suffix
        ("exercise_125", 125.0),  # audio_exercise_base with the suffix
        ("./audio/exercise_125.wav", 125.0),  # the file the coach asks for
        ("/media/music_130.wav", 130.0),
        ("C:\\music\\fast_140.mp3", 140.0),
        ("beat:125", 125.0),
        ("125bpm.wav", 125.0),
        ("fast_130bpm", 130.0),
        ("track2_bpm110.ogg", 110.0),  # tagged: the tag wins over the track number
        ("120_BPM_remix_v2.flac", 120.0),
        ("song2_125.wav", 125.0),  # 2 is not a tempo
        ("2024_mix_128.wav", 128.0),  # the year is not a tempo either
        ("exercise_127.5", 127.5),  # a decimal tempo, not an extension
        ("ladder_110_to_135.wav", 135.0),  # the last number: where the suffix goes
        ("relaxing", None),
        ("./audio/relaxing.wav", None),
        ("default", None),
        ("calm_12.wav", None),  # out of the tempo range
        ("", None),
    ],
)
def test_tempo_from_name(name: str, tempo: float | None) -> None:
    assert tempo_from_name(name) == tempo
    assert tempo_from_audio(name) == tempo  # the participant reads names by the same rule


def test_tempo_range_and_base_name() -> None:
    low, high = TEMPO_RANGE
    assert tempo_from_name(f"x_{low:g}") == low and tempo_from_name(f"x_{high:g}") == high
    assert tempo_from_name(f"x_{high + 1:g}") is None
    assert base_name("./audio/exercise_125.wav") == "exercise_125"
    assert base_name("exercise_127.5") == "exercise_127.5"


def test_ladder_tempo_follows_the_audio_name_rule() -> None:
    ladder = SpeedLadder([0.9, 1.0, 1.1], ["slow", "beat:120", "140bpm"], 0)
    assert ladder.tempo is None
    ladder.step(1)
    assert ladder.tempo == 120.0
    ladder.step(1)
    assert ladder.state()["tempo"] == 140.0

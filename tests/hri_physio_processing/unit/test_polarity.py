"""An ECG upside down (strap worn the wrong way round, electrodes swapped): the processor turns it over.

With the R waves pointing down the peak detector times other waves of the beat: on a real Polar H10
recording turned over, RMSSD came out 63 ms instead of 6, with a quality that passed. ``polarity``
``auto`` (the default) decides each ECG window by its dominant deflection; raw PPG from a Polar OH1 or
Verity Sense comes upside down and is processed with ``polarity: inverted``.
"""

from __future__ import annotations

import math

import neurokit2 as nk
import numpy as np
import pytest

from helpers.processing import match_beats, published_peaks, random_chunks, run_processor, statuses
from helpers.recordings import heartpy_ppg
from hri_physio_processing.config import ConfigError, ProcessorConfig
from hri_physio_processing.features import FeatureSettings, extract, upright_ecg

FS = 130


def test_auto_turns_over_a_negated_ecg_and_leaves_an_upright_one() -> None:
    clean = np.asarray(nk.ecg_clean(nk.ecg_simulate(duration=30, sampling_rate=FS, heart_rate=80,
                                                    random_state=3), sampling_rate=FS))
    same, turned, clear = upright_ecg(clean, FS)
    assert not turned and clear and same is clean
    back, turned, clear = upright_ecg(-clean, FS)
    assert turned and clear and np.array_equal(back, clean)
    # Fixed polarities do what they say, whatever the signal.
    assert upright_ecg(-clean, FS, "upright")[1:] == (False, False)
    assert np.array_equal(upright_ecg(clean, FS, "inverted")[0], -clean)
    # Shorter than one 2-s block: nothing to decide on, the stream's polarity so far is kept.
    short, turned, clear = upright_ecg(-clean[:FS], FS)
    assert not turned and not clear and np.array_equal(short, -clean[:FS])
    assert upright_ecg(clean[:FS], FS, inverted_when_unclear=True)[1:] == (True, False)


def test_a_window_that_cannot_tell_keeps_the_streams_polarity() -> None:
    """Half the blocks up, half down (or noise): not clear; the caller's last clear polarity decides."""
    clean = np.asarray(nk.ecg_clean(nk.ecg_simulate(duration=40, sampling_rate=FS, heart_rate=70,
                                                    random_state=8), sampling_rate=FS))
    half = 10 * 2 * FS  # ten 2-s blocks each way
    mixed = np.concatenate([clean[:half], -clean[half:2 * half]])
    for before in (False, True):
        out, turned, clear = upright_ecg(mixed, FS, inverted_when_unclear=before)
        assert not clear and turned is before and np.array_equal(out, -mixed if before else mixed)
    noise = np.cumsum(np.random.default_rng(5).normal(size=60 * FS))  # brown noise: no polarity
    assert upright_ecg(noise - noise.mean(), FS)[2] is False


@pytest.mark.parametrize("seconds", [0, 300, 900])
def test_an_inverted_window_gives_the_upright_features(mitdb, seconds: int) -> None:
    sel = slice(seconds * FS, (seconds + 60) * FS)
    t, x = mitdb.t[sel], mitdb.x[sel]
    up = extract(t, x, FeatureSettings())
    down = extract(t, -x, FeatureSettings())
    assert up.ok and down.ok and not up.inverted and down.inverted
    for key, value in up.scalars.items():
        assert math.isclose(down.scalars[key], value, rel_tol=1e-9, abs_tol=1e-9) or (
            math.isnan(value) and math.isnan(down.scalars[key])), key
    np.testing.assert_array_equal(down.peaks, up.peaks)
    # Without the turn the same window is timed on other waves: the beats move.
    kept = extract(t, -x, FeatureSettings(polarity="upright"))
    assert not kept.inverted
    assert kept.peaks.shape != up.peaks.shape or not np.array_equal(kept.peaks, up.peaks)


def test_the_processor_finds_every_reference_beat_in_an_inverted_record(mitdb) -> None:
    cfg = ProcessorConfig.from_mapping({"window_seconds": 45, "hop_seconds": 10, "quality_method": "none"})
    n = 4 * 60 * FS
    t, x = mitdb.t[:n], -mitdb.x[:n]
    proc, out = run_processor(cfg, t, x, random_chunks(n, np.random.default_rng(4), 1, 1000))
    wins = statuses(out)
    assert wins and all(w["ok"] and w["inverted"] for w in wins)
    assert proc.stats.inverted_windows == len(wins)
    assert proc.settings.ecg_inverted_when_unclear  # remembered for windows that cannot tell
    reference = mitdb.beats[mitdb.beats < t[-1] - 1.0]
    detected = published_peaks(out)
    tp = match_beats(reference, detected, 0.05)
    assert tp / reference.shape[0] >= 0.995 and tp / detected.shape[0] >= 0.995, (tp, reference.shape,
                                                                                  detected.shape)
    # The lead-in before each window is turned over as its window is: the same beats as upright.
    _, upright_out = run_processor(cfg, t, -x, random_chunks(n, np.random.default_rng(4), 1, 1000))
    np.testing.assert_array_equal(detected, published_peaks(upright_out))
    assert not any(w["inverted"] for w in statuses(upright_out))


def test_a_polarity_that_is_not_one_of_the_three_is_refused() -> None:
    with pytest.raises(ConfigError, match="polarity"):
        ProcessorConfig.from_mapping({"polarity": "down"})
    assert ProcessorConfig.from_mapping({"polarity": "inverted"}).features.polarity == "inverted"


def test_ppg_upside_down_is_processed_as_upright_when_the_user_says_so() -> None:
    """Raw PPG from a Polar OH1 / Verity Sense comes upside down: polarity inverted turns it over
    (real finger PPG, heartpy's data3, turned over here); auto takes PPG as it comes."""
    ppg = heartpy_ppg("data3")
    sel = slice(int(240 * ppg.fs), int(300 * ppg.fs))
    x = ppg.x[sel]
    t = np.arange(x.shape[0]) / ppg.fs
    up = extract(t, x, FeatureSettings(mode="ppg", sampling_rate=ppg.fs))
    turned = extract(t, -x, FeatureSettings(mode="ppg", sampling_rate=ppg.fs, polarity="inverted"))
    assert up.ok and not up.inverted and turned.inverted
    np.testing.assert_array_equal(turned.peaks, up.peaks)
    assert turned.scalars["hr"] == pytest.approx(up.scalars["hr"], rel=1e-12)
    as_it_comes = extract(t, -x, FeatureSettings(mode="ppg", sampling_rate=ppg.fs))
    assert not as_it_comes.inverted and not np.array_equal(as_it_comes.peaks, up.peaks)

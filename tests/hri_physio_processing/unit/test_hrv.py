"""hri_physio_processing.hrv on real NN series: the Task Force definitions, in ms^2, over the whole window.

References: the independent implementation written from the definition (``helpers.hrv_reference``,
numpy FFT), and the values pyhrv 0.5.0 / hrv-analysis 1.0.6 computed on the same series
(``tests/data/pyhrv_nni/library_reference.json``, configured to the same method where they allow it).
Real series: pyhrv's sample NN series and MIT-BIH 100's reference beat annotations.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers import DATA
from helpers import hrv_reference as ref
from hri_physio_processing import hrv
from hri_physio_processing.features import hrv_frequency_of_beats

LIBRARY = json.loads((DATA / "pyhrv_nni" / "library_reference.json").read_text())["series"]
BEAT_SYMBOLS = set("NLRBAaJSVrFejnE/fQ?")


def beats_of(nn_ms) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.asarray(nn_ms, dtype=np.float64)) / 1000.0])


def windows(beats: np.ndarray, seconds: float, hop: float) -> list[np.ndarray]:
    out, t = [], beats[0]
    while t + seconds <= beats[-1]:
        out.append(beats[(beats >= t) & (beats < t + seconds)])
        t += hop
    return out


@pytest.fixture(scope="module")
def long_series() -> np.ndarray:
    return beats_of(np.load(DATA / "pyhrv_nni" / "SampleNNISeriesLong.npy"))


@pytest.fixture(scope="module")
def mitdb_beats() -> np.ndarray:
    import wfdb

    ann = wfdb.rdann(str(DATA / "mitdb" / "100"), "atr")
    return np.array([s for s, sym in zip(ann.sample, ann.symbol, strict=True) if sym in BEAT_SYMBOLS]) / 360.0


@pytest.mark.parametrize("series", ["long_series", "mitdb_beats"])
def test_lf_hf_in_ms2_equal_the_reference_on_real_rr(series: str, request) -> None:
    beats = request.getfixturevalue(series)
    wins = windows(beats, 300.0, 100.0)
    assert len(wins) >= 15
    for b in wins:
        got = hrv.band_powers(b)
        want = ref.band_powers(np.diff(b) * 1000.0, beat_times=b)
        for key in hrv.FREQUENCY_KEYS:
            assert got[key] == pytest.approx(want[key], rel=0.02), key
        # ms^2: the bands hold a part of the interval variance, not a spectrum scaled to its maximum
        assert 0.05 * np.var(np.diff(b) * 1000.0) < got["lf"] + got["hf"] < 1.5 * np.var(np.diff(b) * 1000.0)


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_lf_hf_equal_pyhrv_configured_to_the_same_method(name: str) -> None:
    """pyhrv's Welch (Hann, cubic 4 Hz, mean removed, nfft 4096) uses one segment below 5 min."""
    item = LIBRARY[name]
    beats = beats_of(item["nn_ms"])
    got = hrv.band_powers(beats, segment_seconds=beats[-1] + 10.0)
    for key in ("lf", "hf"):
        assert got[key] == pytest.approx(item["pyhrv"][key], rel=0.02), key
    # and within 0.5 %: the two differ only in the spline's end conditions
    assert got["lf"] == pytest.approx(item["pyhrv"]["lf"], rel=0.005)


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_time_domain_equals_pyhrv_and_hrv_analysis(name: str) -> None:
    item = LIBRARY[name]
    got = hrv.time_domain(np.asarray(item["nn_ms"], dtype=np.float64))
    for lib in ("pyhrv", "hrvanalysis"):
        for key in ("sdnn", "rmssd", "pnn50", "pnn20"):
            assert got[key] == pytest.approx(item[lib][key], rel=1e-3), (lib, key)


def test_pnn_counts_successive_differences() -> None:
    """NN50 over N - 1 differences: 4 intervals, 3 differences, 1 above 50 ms -> 33.3 %."""
    got = hrv.time_domain(np.array([800.0, 860.0, 870.0, 880.0]))
    assert got["pnn50"] == pytest.approx(100.0 / 3.0)
    assert got["pnn20"] == pytest.approx(100.0 / 3.0)
    assert all(math.isnan(v) for v in hrv.time_domain(np.array([800.0])).values())


def test_the_whole_window_counts(long_series) -> None:
    """Every part of a 300-s window moves the spectrum, its last fifth too (no segment left out)."""
    nn = np.diff(windows(long_series, 300.0, 300.0)[3]) * 1000.0
    x = hrv.resample(beats_of(nn)[1:], nn)
    nperseg, step = hrv.segment_plan(x.shape[0], round(hrv.SEGMENT_SECONDS * hrv.RESAMPLE_HZ))
    assert (x.shape[0] - nperseg) % step == 0 and step < nperseg
    base = hrv.band_powers(beats_of(nn))
    t = beats_of(nn)[1:]
    tail = t > 0.8 * t[-1]
    changed = nn.copy()
    changed[tail] += 40.0 * np.sin(2 * np.pi * 0.1 * t[tail])  # a 0.1 Hz (LF) wave of +-40 ms, last 20 %
    assert hrv.band_powers(beats_of(changed))["lf"] > 1.05 * base["lf"]


@pytest.mark.parametrize("n", [240, 241, 1199, 1200, 1201, 1333, 4000])
def test_segment_plan_tiles_the_series(n: int) -> None:
    nperseg, step = hrv.segment_plan(n, 480)
    k = 1 + (n - nperseg) // step
    assert (k - 1) * step + nperseg == n  # the last segment ends at the last sample
    assert nperseg - step >= nperseg // 2 or k == 1  # at least half overlap


def test_bad_input_gives_nan_with_a_reason() -> None:
    values, reasons = hrv_frequency_of_beats(np.array([0.0, 1.0, 2.0]), 300.0)
    assert all(math.isnan(v) for v in values.values()) and "3 beat(s)" in reasons["lf"]
    values, reasons = hrv_frequency_of_beats(np.arange(0.0, 301.0, 1.0), 300.0)  # constant intervals
    assert all(math.isnan(v) for v in values.values()) and "no power" in reasons["hf"]
    with pytest.raises(ValueError, match="too few"):
        hrv.band_powers(np.array([0.0, 1.0]))


def test_lomb_scargle_option_equals_the_written_out_periodogram(long_series) -> None:
    for b in windows(long_series, 300.0, 700.0)[:4]:
        got = hrv.band_powers(b, spectrum="lomb")
        want = ref.lomb_band_powers(np.diff(b) * 1000.0, b)
        for key in ("lf", "hf", "lfhf"):
            assert got[key] == pytest.approx(want[key], rel=0.02), key
        # the same bands, a different estimator: of the order of Welch's
        welch = hrv.band_powers(b)
        assert 0.5 < got["lf"] / welch["lf"] < 2.0 and 0.5 < got["hf"] / welch["hf"] < 2.0


@pytest.mark.parametrize("spectrum", hrv.SPECTRA)
def test_a_sinusoid_has_its_variance_as_band_power(spectrum: str) -> None:
    """NN = 800 ms +- 30 ms at 0.1 Hz for 5 min: LF = 30^2 / 2 = 450 ms^2, HF about 0."""
    t = np.cumsum(np.full(380, 0.8))
    nn = 800.0 + 30.0 * np.sin(2 * np.pi * 0.1 * t)
    got = hrv.band_powers(beats_of(nn), spectrum=spectrum)
    assert got["lf"] == pytest.approx(450.0, rel=0.02) and got["hf"] < 5.0
    with pytest.raises(ValueError, match="unknown spectrum"):
        hrv.band_powers(beats_of(nn), spectrum="fft")


def test_window_features_use_the_lomb_option(long_series) -> None:
    from hri_physio_processing.features import FeatureSettings, _heart

    b = windows(long_series, 300.0, 300.0)[2]
    fs = 130.0
    peaks = np.rint((b - b[0] + 1.0) * fs).astype(np.int64)
    res = _heart(np.zeros(peaks[-1] + int(fs)), peaks, lambda: math.nan,
                 FeatureSettings(quality_method="none", hrv_spectrum="lomb", frequency_domain=True,
                                 max_corrected_fraction=1.0))
    beats, _ = nk_corrected_beats_at(peaks, fs)
    want = ref.lomb_band_powers(np.diff(beats) * 1000.0, beats)
    assert res.scalars["lf"] == pytest.approx(want["lf"], rel=0.02)


def nk_corrected_beats_at(peaks: np.ndarray, fs: float) -> tuple[np.ndarray, int]:
    from helpers.processing import nk_corrected_times

    return nk_corrected_times(peaks / fs)

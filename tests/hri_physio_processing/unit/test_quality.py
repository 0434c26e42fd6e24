"""The vectorised template-matching quality equals NeuroKit2's ecg_quality(method="templatematch")."""

from __future__ import annotations

import warnings

import neurokit2 as nk
import numpy as np
import pytest

from hri_physio_processing import quality
from hri_physio_processing.quality import beat_windows, templatematch_quality


def _clean_and_peaks(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = nk.ecg_clean(x, sampling_rate=fs)
        _, info = nk.ecg_peaks(clean, sampling_rate=fs)
    return clean, np.asarray(info["ECG_R_Peaks"])


def _reference(clean: np.ndarray, peaks: np.ndarray, fs: float) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(nk.ecg_quality(clean, rpeaks=peaks, sampling_rate=fs, method="templatematch"))


@pytest.mark.parametrize("start", [0, 37, 600, 1200, 1745])
def test_equals_neurokit_on_real_ecg(mitdb, start: int) -> None:
    fs = 130
    x = mitdb.x[start * fs : (start + 60) * fs]
    clean, peaks = _clean_and_peaks(x, fs)
    np.testing.assert_allclose(templatematch_quality(clean, peaks, fs), _reference(clean, peaks, fs),
                               rtol=0, atol=1e-9)


@pytest.mark.parametrize("fs,seconds,bpm,noise", [
    (130, 60, 70, 0.01), (130, 5, 150, 0.2), (130, 300, 55, 0.05), (250, 60, 120, 0.3),
    (1000, 20, 90, 0.1), (64, 45, 180, 0.4),
])
def test_equals_neurokit_on_simulated_ecg(fs: int, seconds: int, bpm: int, noise: float) -> None:
    x = nk.ecg_simulate(duration=seconds, sampling_rate=fs, heart_rate=bpm, noise=noise, random_state=bpm)
    clean, peaks = _clean_and_peaks(x, fs)
    np.testing.assert_allclose(templatematch_quality(clean, peaks, fs), _reference(clean, peaks, fs),
                               rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["white", "brown", "emg"])
def test_equals_neurokit_on_noise(kind: str) -> None:
    fs, n = 130, 40 * 130
    rng = np.random.default_rng(3)
    x = {"white": rng.normal(size=n), "brown": np.cumsum(rng.normal(size=n)),
         "emg": nk.emg_simulate(duration=40, sampling_rate=fs, burst_number=4, random_state=2)}[kind]
    clean, peaks = _clean_and_peaks(x, fs)
    ours = templatematch_quality(clean, peaks, fs)
    np.testing.assert_allclose(ours, _reference(clean, peaks, fs), rtol=0, atol=1e-9)
    assert ours.mean() < 0.5  # and it does tell noise from ECG


def test_windows_of_one_length_match_epochs_create_truncation() -> None:
    w = beat_windows(np.array([40, 41, 500]), 10.5)
    assert w is not None
    np.testing.assert_array_equal(w, [[29, 50], [30, 51], [489, 510]])


def test_rounding_at_a_sample_edge_falls_back_to_neurokit(mitdb, monkeypatch) -> None:
    # Just below a whole number of samples, onset + half rounds up for large onsets only.
    assert beat_windows(np.array([10, 10**7]), 30 - 1e-12) is None
    fs = 130
    clean, peaks = _clean_and_peaks(mitdb.x[: 30 * fs], fs)
    monkeypatch.setattr(quality, "beat_windows", lambda *_: None)
    np.testing.assert_array_equal(templatematch_quality(clean, peaks, fs), _reference(clean, peaks, fs))


def test_too_short_or_too_few_beats_is_refused() -> None:
    with pytest.raises(ValueError, match="too small"):
        templatematch_quality(np.zeros(300), np.array([10, 100, 200]), 130)
    with pytest.raises(ValueError, match="at least 2 beats"):
        templatematch_quality(np.zeros(1300), np.array([10]), 130)

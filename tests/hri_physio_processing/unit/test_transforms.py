"""Hilbert transform and spectrogram: known signals, an independent FFT check, errors."""

from __future__ import annotations

import numpy as np
import pytest

from hri_physio_processing.transforms import (
    analytic_signal,
    envelope,
    instantaneous_frequency,
    instantaneous_phase,
    spectrogram,
)

FS = 130.0


def _analytic_by_hand(x: np.ndarray) -> np.ndarray:
    """Analytic signal straight from the definition: zero the negative frequencies, double the positive."""
    n = x.shape[0]
    spec = np.fft.fft(x)
    weights = np.zeros(n)
    weights[0] = 1
    if n % 2 == 0:
        weights[n // 2] = 1
        weights[1 : n // 2] = 2
    else:
        weights[1 : (n + 1) // 2] = 2
    return np.fft.ifft(spec * weights)


@pytest.mark.parametrize("n", [256, 257, 1000])
def test_analytic_signal_matches_definition(n: int) -> None:
    x = np.random.default_rng(n).normal(size=n)
    z = analytic_signal(x)
    np.testing.assert_allclose(z, _analytic_by_hand(x), atol=1e-12)
    np.testing.assert_allclose(z.real, x, atol=1e-12)


def test_envelope_of_am_tone_and_phase_of_tone() -> None:
    t = np.arange(int(20 * FS)) / FS
    carrier = 12.0
    modulation = 1.0 + 0.5 * np.sin(2 * np.pi * 0.5 * t)
    x = modulation * np.cos(2 * np.pi * carrier * t)
    inner = slice(int(2 * FS), -int(2 * FS))  # away from the block edges
    np.testing.assert_allclose(envelope(x)[inner], modulation[inner], atol=0.01)
    f_inst = instantaneous_frequency(np.cos(2 * np.pi * carrier * t), FS)
    np.testing.assert_allclose(f_inst[inner], carrier, atol=0.01)
    phase = instantaneous_phase(np.cos(2 * np.pi * carrier * t))
    assert phase[-1] - phase[0] == pytest.approx(2 * np.pi * carrier * t[-1], rel=1e-3)


def test_multichannel_hilbert_is_per_channel() -> None:
    x = np.random.default_rng(1).normal(size=(500, 3))
    z = analytic_signal(x)
    for c in range(3):
        np.testing.assert_allclose(z[:, c], analytic_signal(x[:, c]), atol=1e-12)
    assert analytic_signal(x[:, 0], n_fft=1024).shape == (500,)


def test_spectrogram_peak_and_power() -> None:
    t = np.arange(int(60 * FS)) / FS
    x = 2.0 * np.sin(2 * np.pi * 7.0 * t) + np.random.default_rng(0).normal(scale=0.1, size=t.shape)
    sp = spectrogram(x, FS, segment_seconds=4.0, overlap=0.5)
    assert sp.power.shape == (sp.freqs.shape[0], sp.times.shape[0])
    peak_freqs = sp.freqs[np.argmax(sp.power, axis=0)]
    np.testing.assert_allclose(peak_freqs, 7.0, atol=sp.freqs[1])
    # Integrated PSD ~ signal power (2^2 / 2 + 0.1^2), Hann window leakage included.
    df = sp.freqs[1] - sp.freqs[0]
    assert np.mean(sp.power.sum(axis=0) * df) == pytest.approx(2.0 + 0.01, rel=0.05)
    assert sp.times[0] == pytest.approx(2.0, abs=1 / FS)


def test_spectrogram_channels_last() -> None:
    x = np.random.default_rng(2).normal(size=(2000, 2))
    sp = spectrogram(x, FS, segment_seconds=2.0)
    assert sp.power.shape == (sp.freqs.shape[0], sp.times.shape[0], 2)
    np.testing.assert_allclose(sp.power[..., 1], spectrogram(x[:, 1], FS, segment_seconds=2.0).power)


@pytest.mark.parametrize("call,match", [
    (lambda: analytic_signal(np.array([])), "empty"),
    (lambda: envelope(np.array([1.0, np.nan])), "NaN"),
    (lambda: analytic_signal(np.ones(10) * 1j), "complex"),
    (lambda: analytic_signal(np.ones(10), n_fft=5), "n_fft"),
    (lambda: instantaneous_frequency(np.ones(10), 0.0), "sampling rate"),
    (lambda: spectrogram(np.array([]), FS), "empty"),
    (lambda: spectrogram(np.ones(100), FS, segment_seconds=4.0), "longer than the input"),
    (lambda: spectrogram(np.ones(1000), -1.0), "sampling rate"),
    (lambda: spectrogram(np.ones(1000), FS, segment_seconds=0.001), "fewer than 2"),
    (lambda: spectrogram(np.ones(1000), FS, segment_seconds=1.0, overlap=1.0), "overlap"),
])
def test_invalid_input_raises_clear_errors(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()

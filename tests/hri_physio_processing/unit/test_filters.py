"""Streaming biquads: the seed's coefficients against scipy, band shapes, chunking, errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from helpers.processing import random_chunks
from hri_physio_processing.filters import BandPass, BandReject, Biquad, HighPass, LowPass, band_edges

RATES_CUTOFFS = [(130.0, 0.5), (130.0, 5.0), (130.0, 40.0), (130.0, 64.0), (1000.0, 0.05), (44100.0, 1000.0)]


@pytest.mark.parametrize("fs,fc", RATES_CUTOFFS)
def test_lowpass_and_highpass_equal_scipy_butter(fs: float, fc: float) -> None:
    for cls, btype in ((LowPass, "lowpass"), (HighPass, "highpass")):
        b, a = signal.butter(2, fc, btype=btype, fs=fs)
        f = cls(fc, fs)
        np.testing.assert_allclose(f.b, b, rtol=0, atol=1e-12)
        np.testing.assert_allclose(f.a, a, rtol=0, atol=1e-12)


def _response_db(f: Biquad, fs: float, n: int = 400_001) -> tuple[np.ndarray, np.ndarray]:
    freqs = np.linspace(0, fs / 2, n)[1:-1]
    _, h = signal.freqz(f.b, f.a, worN=freqs, fs=fs)
    return freqs, np.abs(h) ** 2


def _crossings(freqs: np.ndarray, power: np.ndarray, level: float) -> np.ndarray:
    """Frequencies where ``power`` crosses ``level`` (linear interpolation between grid points)."""
    s = np.sign(power - level)
    idx = np.flatnonzero(s[:-1] != s[1:])
    f0, f1, p0, p1 = freqs[idx], freqs[idx + 1], power[idx], power[idx + 1]
    return f0 + (level - p0) * (f1 - f0) / (p1 - p0)


# Includes wide bands hugging DC and Nyquist: the design keeps both edges inside (0, fs/2).
BANDS = [(130.0, 10.0, 2.0), (130.0, 1.0, 0.5), (130.0, 30.0, 20.0), (130.0, 50.0, 4.0), (1000.0, 5.0, 1.0),
         (130.0, 0.25, 0.1), (130.0, 2.0, 10.0), (130.0, 64.0, 10.0)]


@pytest.mark.parametrize("fs,fc,bw", BANDS)
def test_bandpass_peak_at_centre_and_3db_bandwidth(fs: float, fc: float, bw: float) -> None:
    f = BandPass(fc, bw, fs)
    freqs, p = _response_db(f, fs)
    peak = freqs[np.argmax(p)]
    assert abs(peak - fc) <= 2 * (freqs[1] - freqs[0])
    assert abs(f.frequency_response(np.array([fc]), fs)[0]) == pytest.approx(1.0, abs=1e-9)  # unity peak
    lo, hi = _crossings(freqs, p, 0.5)
    assert lo < fc < hi
    assert hi - lo == pytest.approx(bw, rel=0.01)
    np.testing.assert_allclose((lo, hi), band_edges(fc, bw, fs), atol=1e-3)


@pytest.mark.parametrize("fs,fc,bw", BANDS)
def test_bandreject_notch_at_centre_and_3db_bandwidth(fs: float, fc: float, bw: float) -> None:
    f = BandReject(fc, bw, fs)
    freqs, p = _response_db(f, fs)
    notch = freqs[np.argmin(p)]
    assert abs(notch - fc) <= 2 * (freqs[1] - freqs[0])
    assert abs(f.frequency_response(np.array([fc]), fs)[0]) < 1e-9  # a true zero at f_center
    lo, hi = _crossings(freqs, p, 0.5)
    assert lo < fc < hi
    assert hi - lo == pytest.approx(bw, rel=0.01)
    assert p[0] == pytest.approx(1.0, abs=1e-6)  # passes DC


@pytest.mark.parametrize("make", [
    lambda: LowPass(8.0, 130.0), lambda: HighPass(0.5, 130.0),
    lambda: BandPass(10.0, 3.0, 130.0), lambda: BandReject(50.0, 2.0, 130.0),
])
@pytest.mark.parametrize("channels", [1, 3])
def test_any_chunking_equals_one_shot(make, channels: int) -> None:
    rng = np.random.default_rng(channels)
    x = rng.normal(size=(5000, channels)).cumsum(axis=0) + rng.normal(size=(5000, channels))
    ref = signal.lfilter(make().b, make().a, x, axis=0)
    for seed in range(3):
        f = make()
        chunks = random_chunks(5000, np.random.default_rng(seed), 1, 300)
        y = np.concatenate([f.process(x[a:b]) for a, b in chunks])
        np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12)
    # scipy's sosfilt (another recursion) agrees to rounding, relative to the signal's scale
    scale = float(np.abs(x).max())
    np.testing.assert_allclose(signal.sosfilt(make().sos, x, axis=0), ref, rtol=0, atol=1e-13 * scale)


def test_channels_are_filtered_independently_and_1d_works() -> None:
    rng = np.random.default_rng(7)
    x = rng.normal(size=(1000, 4))
    multi = LowPass(5.0, 130.0).process(x)
    for c in range(4):
        np.testing.assert_array_equal(multi[:, c], LowPass(5.0, 130.0).process(x[:, c]))


def test_state_reset_and_channel_change() -> None:
    f = HighPass(1.0, 130.0)
    x = np.random.default_rng(0).normal(size=(200, 2))
    first = f.process(x)
    with pytest.raises(ValueError, match="channel"):
        f.process(x[:, :1])
    f.reset()
    np.testing.assert_array_equal(f.process(x), first)
    assert f.process(np.empty((0, 2))).shape == (0, 2)  # an empty chunk changes nothing
    np.testing.assert_array_equal(HighPass(1.0, 130.0).process(np.vstack([x, x]))[200:], f.process(x))


def test_dc_and_nyquist_gains() -> None:
    """Low-pass passes DC and kills Nyquist; high-pass the other way round (Butterworth)."""
    fs = 130.0
    lp, hp = LowPass(10.0, fs), HighPass(10.0, fs)
    assert abs(lp.frequency_response(np.array([0.0]), fs)[0]) == pytest.approx(1.0)
    assert abs(hp.frequency_response(np.array([0.0]), fs)[0]) == pytest.approx(0.0, abs=1e-12)
    assert abs(lp.frequency_response(np.array([10.0]), fs)[0]) ** 2 == pytest.approx(0.5)
    assert abs(hp.frequency_response(np.array([10.0]), fs)[0]) ** 2 == pytest.approx(0.5)


@pytest.mark.parametrize("make,match", [
    (lambda: LowPass(65.0, 130.0), "Nyquist"),
    (lambda: HighPass(80.0, 130.0), "Nyquist"),
    (lambda: LowPass(0.0, 130.0), "> 0"),
    (lambda: LowPass(5.0, 0.0), "sampling rate"),
    (lambda: LowPass(float("nan"), 130.0), "> 0"),
    (lambda: BandPass(10.0, -1.0, 130.0), "bandwidth"),
    (lambda: BandReject(10.0, 0.0, 130.0), "bandwidth"),
    (lambda: BandPass(70.0, 2.0, 130.0), "Nyquist"),
    (lambda: BandPass(10.0, 65.0, 130.0), "Nyquist"),
    (lambda: BandReject(10.0, 70.0, 130.0), "Nyquist"),
    (lambda: Biquad([1, 0], [1, 0, 0]), "3 numerator"),
    (lambda: Biquad([1, 0, 0], [0, 0, 0]), "invalid"),
])
def test_invalid_parameters_raise_clear_errors(make, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_bad_input_shape_raises() -> None:
    with pytest.raises(ValueError, match="3-D"):
        LowPass(5.0, 130.0).process(np.zeros((4, 2, 2)))

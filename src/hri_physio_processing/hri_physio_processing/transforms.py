"""Hilbert transform (analytic signal, envelope, phase) and spectrogram on scipy's FFT.

scipy.fft is PocketFFT, the library the seed vendored for its C++ Hilbert transform.
Samples run along axis 0; extra axes are channels. These are block transforms: they work on
a window of samples (e.g. one the windowing module produced), not sample by sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal


def _as_block(x: np.ndarray, what: str) -> np.ndarray:
    data = np.asarray(x)
    if data.ndim == 0 or data.shape[0] == 0:
        raise ValueError(f"{what} needs at least one sample, got an empty input")
    if np.iscomplexobj(data):
        raise ValueError(f"{what} expects a real signal, got complex values")
    data = data.astype(np.float64, copy=False)
    if not np.all(np.isfinite(data)):
        raise ValueError(f"{what}: the input holds NaN or infinite values")
    return data


def analytic_signal(x: np.ndarray, n_fft: int | None = None) -> np.ndarray:
    """x + j*H{x} along axis 0 (``n_fft`` zero-pads; the result keeps len(x) samples)."""
    data = _as_block(x, "Hilbert transform")
    n = data.shape[0]
    if n_fft is not None and n_fft < n:
        raise ValueError(f"n_fft ({n_fft}) must be at least the number of samples ({n})")
    return signal.hilbert(data, N=n_fft, axis=0)[:n]


def envelope(x: np.ndarray) -> np.ndarray:
    """Instantaneous amplitude |x + j*H{x}|."""
    return np.abs(analytic_signal(x))


def instantaneous_phase(x: np.ndarray) -> np.ndarray:
    """Unwrapped instantaneous phase (radians)."""
    return np.unwrap(np.angle(analytic_signal(x)), axis=0)


def instantaneous_frequency(x: np.ndarray, fs: float) -> np.ndarray:
    """Instantaneous frequency (Hz), one value per sample step (len(x) - 1 values)."""
    _check_rate(fs)
    return np.diff(instantaneous_phase(x), axis=0) * fs / (2.0 * math.pi)


def _check_rate(fs: float) -> None:
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"sampling rate must be a positive number, got {fs}")


@dataclass(frozen=True)
class Spectrogram:
    """Power spectral density per segment: ``power[freq, segment(, channel)]``."""

    freqs: np.ndarray  # Hz
    times: np.ndarray  # seconds from the first sample to each segment's centre
    power: np.ndarray  # PSD, units^2/Hz


def spectrogram(
    x: np.ndarray, fs: float, segment_seconds: float = 4.0, overlap: float = 0.5, window: str = "hann"
) -> Spectrogram:
    """Short-time power spectrum (density scaling, one-sided, per channel along axis 0)."""
    data = _as_block(x, "spectrogram")
    _check_rate(fs)
    nperseg = round(segment_seconds * fs)
    if nperseg < 2:
        raise ValueError(f"segment of {segment_seconds} s at {fs:g} Hz holds fewer than 2 samples")
    if nperseg > data.shape[0]:
        raise ValueError(
            f"segment of {nperseg} samples ({segment_seconds:g} s) is longer than the input "
            f"({data.shape[0]} samples)"
        )
    if not 0 <= overlap < 1:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    noverlap = min(round(overlap * nperseg), nperseg - 1)
    freqs, times, power = signal.spectrogram(
        data, fs=fs, window=window, nperseg=nperseg, noverlap=noverlap, axis=0, scaling="density",
        mode="psd",
    )
    # scipy puts the segment axis last; keep (freq, segment, channel...).
    power = np.moveaxis(power, -1, 1) if power.ndim > 2 else power
    return Spectrogram(freqs, times, power)

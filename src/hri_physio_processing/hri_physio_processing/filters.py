"""Streaming second-order Butterworth filters (biquads) with the seed's coefficients.

The coefficient formulas are Dodge & Jerse's (Computer Music, 2nd ed.; thesis Fig. 3.9),
written there as ``y[n] = a0 x[n] + a1 x[n-1] + a2 x[n-2] - b1 y[n-1] - b2 y[n-2]``. In
scipy's naming that is numerator ``b = [a0, a1, a2]`` and denominator ``a = [1, b1, b2]``.

* Low-/high-pass are the bilinear transform of the analog Butterworth prototype with the
  cut-off pre-warped (the ``tan`` in ``C``), so they equal ``scipy.signal.butter(2, fc)``.
* Band-pass/band-reject put their peak/notch exactly at ``f_center`` and their -3 dB points
  exactly ``bandwidth`` Hz apart: the ``tan(pi*BW/fs)`` is the pre-warping, so no further
  correction is needed (the band is not symmetric around ``f_center``: it is centred where
  ``cos(w_mid) = cos(w_c) * cos(w_bw / 2)``, which keeps both edges inside (0, Nyquist) for
  any valid ``f_center`` and ``bandwidth``).

Samples run along axis 0 and any number of channels along axis 1. The filter state (scipy's
``zi``, one pair per channel) is carried from one call to the next, so filtering a stream in
chunks of any size gives the same output as filtering it in one go.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

SQRT2 = math.sqrt(2.0)


class Biquad:
    """A second-order IIR section applied with :func:`scipy.signal.lfilter`, state carried."""

    def __init__(self, b: np.ndarray, a: np.ndarray) -> None:
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        a = np.asarray(a, dtype=np.float64).reshape(-1)
        if b.shape != (3,) or a.shape != (3,):
            raise ValueError(f"a biquad needs 3 numerator and 3 denominator coefficients, got {b}, {a}")
        if a[0] == 0 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise ValueError(f"invalid biquad coefficients b={b}, a={a}")
        self.b = b / a[0]
        self.a = a / a[0]
        self._zi: np.ndarray | None = None

    @property
    def sos(self) -> np.ndarray:
        """The section as a (1, 6) second-order-sections array."""
        return np.concatenate([self.b, self.a]).reshape(1, 6)

    def reset(self) -> None:
        """Forget the carried state (the next sample starts from rest)."""
        self._zi = None

    def process(self, x: np.ndarray) -> np.ndarray:
        """Filter the next chunk: shape (samples,) or (samples, channels)."""
        data = np.asarray(x, dtype=np.float64)
        if data.ndim not in (1, 2):
            raise ValueError(f"expected samples or samples x channels, got a {data.ndim}-D array")
        if data.shape[0] == 0:
            return data.copy()
        shape_zi = (2, *data.shape[1:])
        if self._zi is None:
            self._zi = np.zeros(shape_zi)
        elif self._zi.shape != shape_zi:
            raise ValueError(
                f"this filter carries state for {self._zi.shape[1:] or 'one'} channel(s); "
                f"got a chunk shaped {data.shape} (reset() to change the channel count)"
            )
        y, self._zi = signal.lfilter(self.b, self.a, data, axis=0, zi=self._zi)
        return y

    def frequency_response(self, freqs: np.ndarray, fs: float) -> np.ndarray:
        """Complex response at ``freqs`` (Hz)."""
        _, h = signal.freqz(self.b, self.a, worN=np.asarray(freqs, dtype=np.float64), fs=fs)
        return h


def _check_rate(fs: float) -> None:
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"sampling rate must be a positive number, got {fs}")


def _check_frequency(name: str, f: float, fs: float) -> None:
    _check_rate(fs)
    if not math.isfinite(f) or f <= 0:
        raise ValueError(f"{name} must be > 0 Hz, got {f}")
    if f >= fs / 2:
        raise ValueError(f"{name} {f:g} Hz must be below the Nyquist frequency {fs / 2:g} Hz (fs={fs:g})")


def band_edges(f_center: float, bandwidth: float, fs: float) -> tuple[float, float]:
    """-3 dB edges (Hz) of the band-pass/band-reject biquads for these parameters."""
    w0 = 2 * math.pi * f_center / fs
    half = math.pi * bandwidth / fs  # half the bandwidth in rad/sample
    mid = math.acos(math.cos(w0) * math.cos(half))
    return (mid - half) * fs / (2 * math.pi), (mid + half) * fs / (2 * math.pi)


def _check_band(f_center: float, bandwidth: float, fs: float) -> None:
    _check_frequency("centre frequency", f_center, fs)
    if not math.isfinite(bandwidth) or bandwidth <= 0:
        raise ValueError(f"bandwidth must be > 0 Hz, got {bandwidth}")
    if bandwidth >= fs / 2:
        raise ValueError(f"bandwidth {bandwidth:g} Hz must be below the Nyquist frequency {fs / 2:g} Hz")


class LowPass(Biquad):
    """Second-order Butterworth low-pass at ``cutoff`` Hz."""

    def __init__(self, cutoff: float, fs: float) -> None:
        _check_frequency("cut-off", cutoff, fs)
        c = 1.0 / math.tan(math.pi * cutoff / fs)
        a0 = 1.0 / (1.0 + SQRT2 * c + c * c)
        b1 = 2.0 * a0 * (1.0 - c * c)
        b2 = a0 * (1.0 - SQRT2 * c + c * c)
        super().__init__([a0, 2.0 * a0, a0], [1.0, b1, b2])
        self.cutoff, self.fs = cutoff, fs


class HighPass(Biquad):
    """Second-order Butterworth high-pass at ``cutoff`` Hz."""

    def __init__(self, cutoff: float, fs: float) -> None:
        _check_frequency("cut-off", cutoff, fs)
        c = math.tan(math.pi * cutoff / fs)
        a0 = 1.0 / (1.0 + SQRT2 * c + c * c)
        b1 = 2.0 * a0 * (c * c - 1.0)
        b2 = a0 * (1.0 - SQRT2 * c + c * c)
        super().__init__([a0, -2.0 * a0, a0], [1.0, b1, b2])
        self.cutoff, self.fs = cutoff, fs


class BandPass(Biquad):
    """Second-order band-pass: unity gain at ``f_center``, -3 dB points ``bandwidth`` Hz apart."""

    def __init__(self, f_center: float, bandwidth: float, fs: float) -> None:
        _check_band(f_center, bandwidth, fs)
        c = 1.0 / math.tan(math.pi * bandwidth / fs)
        d = 2.0 * math.cos(2.0 * math.pi * f_center / fs)
        a0 = 1.0 / (1.0 + c)
        super().__init__([a0, 0.0, -a0], [1.0, -a0 * c * d, a0 * (c - 1.0)])
        self.f_center, self.bandwidth, self.fs = f_center, bandwidth, fs


class BandReject(Biquad):
    """Second-order band-reject: zero gain at ``f_center``, -3 dB points ``bandwidth`` Hz apart."""

    def __init__(self, f_center: float, bandwidth: float, fs: float) -> None:
        _check_band(f_center, bandwidth, fs)
        c = math.tan(math.pi * bandwidth / fs)
        d = 2.0 * math.cos(2.0 * math.pi * f_center / fs)
        a0 = 1.0 / (1.0 + c)
        super().__init__([a0, -a0 * d, a0], [1.0, -a0 * d, a0 * (1.0 - c)])
        self.f_center, self.bandwidth, self.fs = f_center, bandwidth, fs

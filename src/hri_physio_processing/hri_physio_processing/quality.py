"""NeuroKit2's template-matching signal quality, vectorised.

``nk.ecg_quality(clean, rpeaks, fs, method="templatematch")`` (Orphanidou et al. 2015 as
NeuroKit2 implements it) spends about 40 ms of a 60 s / 130 Hz window building one pandas
DataFrame per beat; the arithmetic itself takes well under a millisecond. This module does the
same steps on one numpy array (about 1 ms), so the processor meets its per-window budget. It
follows NeuroKit2 (0.2.13, pinned) step by step; tests compare it with NeuroKit2 to 1e-9 on
real, simulated and noise windows:

1. every beat gets the same window, ``ratio_pre`` = 0.5 of the mean inter-beat interval
   before the peak and 0.5 after, sample bounds truncated as ``epochs_create`` does;
2. beats whose window leaves the signal are dropped;
3. the template is the mean of the remaining beats; each beat but the last is scored by its
   Pearson correlation with the template;
4. the per-beat scores are held from each beat to the next ("previous" interpolation, the
   first score before the first beat) over every sample of the signal.
"""

from __future__ import annotations

import numpy as np


def templatematch_quality(clean: np.ndarray, peaks: np.ndarray, fs: float) -> np.ndarray:
    """Per-sample quality in [-1, 1] of ``clean`` given its beat positions (sample indices)."""
    import neurokit2 as nk

    signal = np.asarray(clean, dtype=np.float64).reshape(-1)
    n = signal.shape[0]
    if n < fs * 4:
        raise ValueError("The data length is too small to be segmented.")
    peaks = np.asarray(peaks, dtype=np.int64).reshape(-1)
    if peaks.shape[0] < 2:
        raise ValueError(f"template matching needs at least 2 beats, got {peaks.shape[0]}")
    mean_rate = float(np.mean(nk.signal_rate(peaks, sampling_rate=fs, desired_length=n)))
    windows = beat_windows(peaks, 0.5 * 60.0 / mean_rate * fs)
    if windows is None:
        return np.asarray(nk.ecg_quality(signal, rpeaks=peaks, sampling_rate=fs, method="templatematch"),
                          dtype=np.float64)
    index = windows[:, :1] + np.arange(windows[0, 1] - windows[0, 0])[None, :]
    inside = np.all((index >= 0) & (index < n), axis=1)  # NeuroKit2 drops beats with NaN padding
    morph = signal[index[inside]]
    kept = peaks[inside]
    template = morph.mean(axis=0)
    scored = morph[:-1] - morph[:-1].mean(axis=1, keepdims=True)  # NeuroKit2 scores all but the last
    centred = template - template.mean()
    cc = (scored @ centred) / np.sqrt((scored * scored).sum(axis=1) * float(centred @ centred))
    return np.asarray(nk.signal_interpolate(kept[:-1], cc, x_new=np.arange(n), method="previous"),
                      dtype=np.float64)


def beat_windows(peaks: np.ndarray, half_samples: float) -> np.ndarray | None:
    """[start, end) sample bounds of each beat's window, shape (beats, 2), as epochs_create cuts them.

    NeuroKit2 pads the signal with ``pad`` NaN samples on both sides and cuts
    ``data[int(onset + pad - half) : int(onset + pad + half)]``. The onsets are whole numbers, so
    all windows have one length, unless float rounding lands a bound on an exact sample edge for
    some beats and not others; then this returns None (NeuroKit2 itself is used for that window).
    """
    pad = int(2 * half_samples)
    onsets = (np.asarray(peaks, dtype=np.int64) + pad).astype(np.float64)
    starts = (onsets - half_samples).astype(np.int64) - pad
    ends = (onsets + half_samples).astype(np.int64) - pad
    lengths = ends - starts
    if np.any(lengths != lengths[0]):
        return None
    return np.stack([starts, ends], axis=1)

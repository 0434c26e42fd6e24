"""User audio files: decoded with soundfile, resampled with librosa (soxr), fitted to the output channels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import soundfile as sf

from audio_video_streamers.requests import RequestError


def fit_channels(samples: np.ndarray, channels: int) -> np.ndarray:
    """(frames, channels): mono is copied to every channel, more channels are mixed down."""
    have = samples.shape[1]
    if have == channels:
        return samples
    if have == 1:
        return np.repeat(samples, channels, axis=1)
    if channels == 1:
        return samples.mean(axis=1, keepdims=True)
    # Keep the first two as left/right and fold the rest into both.
    base = samples[:, :channels].copy()
    if have > channels:
        base += samples[:, channels:].mean(axis=1, keepdims=True) * 0.5
    return base


def decode(path: Path, rate: int, channels: int) -> np.ndarray:
    """The file's audio as (frames, channels) float32 at ``rate``; :class:`RequestError` if unusable."""
    if not path.is_file():
        raise RequestError(f"no such audio file: {path}")
    try:
        samples, file_rate = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, ValueError) as exc:
        raise RequestError(f"cannot decode {path}: {str(exc).strip().splitlines()[0]}") from None
    if len(samples) == 0:
        raise RequestError(f"audio file {path} holds no samples")
    if not np.all(np.isfinite(samples)):
        raise RequestError(f"audio file {path} holds NaN or infinite samples")
    if file_rate != rate:
        import librosa

        samples = librosa.resample(samples.T, orig_sr=file_rate, target_sr=rate).T
    return np.ascontiguousarray(fit_channels(samples, channels), dtype=np.float32)

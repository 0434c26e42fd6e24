"""Helpers for the media tests: a virtual clock, measuring tempo in a recording, test media files."""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import cv2
import numpy as np
import soundfile as sf
from scipy import signal


class VirtualClock:
    """A clock that only moves when a pacer sleeps on it: media renders as fast as the CPU allows."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float, stop: threading.Event) -> bool:
        self.t += seconds
        return stop.is_set()


class ListHandler(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def messages(self, level: int = logging.DEBUG) -> list[str]:
        return [r.getMessage() for r in self.records if r.levelno >= level]


def capture_logger(name: str) -> tuple[logging.Logger, ListHandler]:
    log = logging.getLogger(f"media-test.{name}")
    handler = ListHandler()
    log.handlers[:] = [handler]
    log.setLevel(logging.DEBUG)
    log.propagate = False
    return log, handler


# ----------------------------------------------------------------------------------------------
# Tempo, measured on the recording only
def low_band_onsets(y: np.ndarray, sr: int, cutoff: float = 150.0) -> np.ndarray:
    """Times (s) where the low-band envelope rises through half of each of its peaks.

    The low band holds the kicks (one on every beat); lighter high-band accents do not count.
    The half-height crossing is interpolated between samples, so onsets are sub-millisecond.
    """
    mono = y.mean(axis=1) if y.ndim == 2 else y
    sos = signal.butter(4, cutoff, btype="lowpass", fs=sr, output="sos")
    low = np.abs(signal.sosfiltfilt(sos, mono))
    smooth = signal.sosfiltfilt(signal.butter(2, 40.0, fs=sr, output="sos"), low)
    peaks, _ = signal.find_peaks(smooth, height=0.25 * smooth.max(), distance=int(0.15 * sr))
    onsets = []
    for p in peaks:
        half = smooth[p] / 2
        start = max(0, p - int(0.15 * sr))
        below = np.nonzero(smooth[start:p] < half)[0]
        if len(below) == 0:
            continue
        i = start + below[-1]  # last sample under half height before the peak
        frac = (half - smooth[i]) / (smooth[i + 1] - smooth[i])
        onsets.append((i + frac) / sr)
    return np.asarray(onsets)


def tempo_of_onsets(onsets: np.ndarray) -> tuple[float, float]:
    """(BPM, RMS residual in s) of a straight beat grid fitted to ``onsets``."""
    if len(onsets) < 4:
        raise AssertionError(f"only {len(onsets)} onsets found")
    period = float(np.median(np.diff(onsets)))
    for _ in range(2):  # refine: number the beats on the grid, fit a line
        index = np.round((onsets - onsets[0]) / period)
        period, offset = np.polyfit(index, onsets, 1)
    residual = onsets - (offset + period * index)
    return 60.0 / period, float(np.sqrt(np.mean(residual**2)))


def measure_tempo(path: Path, skip: float = 0.0) -> tuple[float, float]:
    """(BPM, residual) of the kicks in a WAV file, ignoring its first ``skip`` seconds."""
    y, sr = sf.read(str(path), always_2d=True)
    return tempo_of_onsets(low_band_onsets(y[int(skip * sr):], sr))


# ----------------------------------------------------------------------------------------------
# Test media
def write_tone(path: Path, freq: float, seconds: float, amp: float = 0.5, sr: int = 44100) -> Path:
    t = np.arange(int(seconds * sr)) / sr
    sf.write(str(path), (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32), sr)
    return path


def write_drum_clip(path: Path, bpm: float, beats: int, sr: int = 44100) -> Path:
    """A little track at ``bpm``: a low drum on every beat and a changing melody (not our beat synth)."""
    period = 60.0 / bpm
    n = round(beats * period * sr)
    y = np.zeros(n)
    t_hit = np.arange(int(0.2 * sr)) / sr
    drum = np.sin(2 * np.pi * 70 * t_hit) * np.exp(-t_hit / 0.05)
    notes = [330.0, 392.0, 440.0, 392.0, 494.0, 440.0]
    for k in range(beats):
        at = round(k * period * sr)
        end = min(n, at + len(drum))
        y[at:end] += 0.6 * drum[: end - at]
        note_len = min(round(period * sr), n - at)
        tn = np.arange(note_len) / sr
        y[at:at + note_len] += 0.12 * np.sin(2 * np.pi * notes[k % len(notes)] * tn) * np.exp(-tn / 0.3)
    sf.write(str(path), y.astype(np.float32), sr)
    return path


def write_video(path: Path, frames: int, fps: float, size: tuple[int, int] = (160, 120)) -> Path:
    """An MJPG AVI whose frame ``i`` is uniformly grey level ``gray_of(i)`` (readable back from pixels)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert writer.isOpened(), "OpenCV cannot write MJPG here"
    for i in range(frames):
        writer.write(np.full((size[1], size[0], 3), gray_of(i), dtype=np.uint8))
    writer.release()
    return path


def gray_of(index: int) -> int:
    return 10 + 20 * (index % 12)


def index_of_gray(frame: np.ndarray) -> int:
    """Which ``write_video`` frame a (possibly letterboxed, JPEG-decoded) frame shows."""
    h, w = frame.shape[:2]
    centre = frame[h // 3: 2 * h // 3, w // 3: 2 * w // 3]
    return round((float(centre.mean()) - 10) / 20)


def green_mask(frame: np.ndarray) -> np.ndarray:
    """Pixels of the splash's ECG trace: green clearly above red and blue."""
    b, g, r = (frame[..., i].astype(int) for i in range(3))
    return (g > 120) & (g > r + 60) & (g > b + 60)

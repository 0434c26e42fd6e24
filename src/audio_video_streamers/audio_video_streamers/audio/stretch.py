"""A user track at any tempo: its own tempo measured, then time-stretched with librosa, cached.

The track's tempo is measured once (librosa's beat tracker, then a straight line through the
beat times, whose slope is the beat period: finer than the tracker's tempo grid). Among the
measured tempo, its half and its double, the one nearest the requested tempo is taken (a 65
BPM track is a 130 BPM track in half time), so no track is stretched by more than sqrt(2).
librosa's phase-vocoder time stretch then changes the tempo without changing the pitch.

Results are kept on disk (``cache_dir``) keyed by the file's path, size and modification time,
the output format, the tempo and the librosa version, so a session pays each stretch once;
the first stretch in a process also pays librosa's JIT compilation (seconds).
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
from pathlib import Path

import numpy as np

from audio_video_streamers.requests import RequestError

ANALYSIS_RATE = 22050


def measure_tempo(samples: np.ndarray, rate: int) -> float:
    """The tempo (BPM) of a steady track, from a line fitted through its tracked beats."""
    import librosa

    mono = samples.mean(axis=1) if samples.ndim == 2 else samples
    if rate != ANALYSIS_RATE:
        mono = librosa.resample(mono, orig_sr=rate, target_sr=ANALYSIS_RATE)
    hop = 256
    _, beats = librosa.beat.beat_track(y=mono, sr=ANALYSIS_RATE, hop_length=hop, units="time")
    beats = np.asarray(beats, dtype=float)
    if len(beats) < 4:
        raise RequestError("too few beats found to measure the track's tempo")
    slope, _ = np.polyfit(np.arange(len(beats)), beats, 1)
    return 60.0 / float(slope)


def nearest_octave(measured: float, target: float) -> float:
    """The measured tempo, halved or doubled when that is nearer the target (in ratio)."""
    return min((measured / 2, measured, measured * 2), key=lambda bpm: abs(np.log(target / bpm)))


def time_stretch(samples: np.ndarray, ratio: float) -> np.ndarray:
    """``samples`` (frames, channels) played ``ratio`` times faster, same pitch (librosa)."""
    import librosa

    out = librosa.effects.time_stretch(np.ascontiguousarray(samples.T), rate=ratio)
    return np.ascontiguousarray(out.T, dtype=np.float32)


class StretchCache:
    """Stretched tracks and measured tempos on disk (``None`` dir: nothing kept between runs)."""

    def __init__(self, cache_dir: Path | None, log: logging.Logger | None = None) -> None:
        self.dir = cache_dir
        self.log = log or logging.getLogger(__name__)
        self._lock = threading.Lock()
        if self.dir is not None:
            self.dir.mkdir(parents=True, exist_ok=True)

    @staticmethod
    def file_key(path: Path, *parts: object) -> str:
        import librosa

        st = path.stat()
        text = json.dumps([str(path.resolve()), st.st_size, st.st_mtime_ns, librosa.__version__,
                           *[str(p) for p in parts]])
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def _path(self, key: str, suffix: str) -> Path | None:
        return None if self.dir is None else self.dir / f"{key}{suffix}"

    def load_samples(self, key: str) -> np.ndarray | None:
        path = self._path(key, ".npy")
        if path is None or not path.is_file():
            return None
        try:
            return np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            self.log.warning(f"ignoring unreadable cache file {path}: {exc}")
            return None

    def save_samples(self, key: str, samples: np.ndarray) -> None:
        path = self._path(key, ".npy")
        if path is None:
            return
        tmp = path.with_suffix(".tmp.npy")
        with self._lock:
            np.save(tmp, samples, allow_pickle=False)
            tmp.replace(path)  # atomic: a reader never sees half a file

    def load_tempo(self, key: str) -> float | None:
        path = self._path(key, ".json")
        if path is None or not path.is_file():
            return None
        try:
            return float(json.loads(path.read_text())["tempo"])
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def save_tempo(self, key: str, tempo: float) -> None:
        path = self._path(key, ".json")
        if path is not None:
            path.write_text(json.dumps({"tempo": tempo}))


def stretched(path: Path, decoded: np.ndarray, rate: int, target: float,
              cache: StretchCache) -> tuple[np.ndarray, float]:
    """``decoded`` (the file at ``rate``) at ``target`` BPM, and the track's own tempo."""
    tempo_key = cache.file_key(path, "tempo", rate)
    measured = cache.load_tempo(tempo_key)
    if measured is None:
        measured = measure_tempo(decoded, rate)
        cache.save_tempo(tempo_key, measured)
    own = nearest_octave(measured, target)  # so the stretch is within x0.71..x1.41
    ratio = target / own
    key = cache.file_key(path, "stretch", rate, decoded.shape[1], f"{target:.6f}")
    samples = cache.load_samples(key)
    if samples is None or samples.ndim != 2 or samples.shape[1] != decoded.shape[1]:
        samples = time_stretch(decoded, ratio)
        cache.save_samples(key, samples)
    return samples, own

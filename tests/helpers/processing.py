"""Processing test helpers: a processor driver, beat matching, the NeuroKit2 reference, ROS outputs."""

from __future__ import annotations

import json
import threading
import warnings
from typing import Any

import neurokit2 as nk
import numpy as np

from helpers import hrv_reference
from hri_physio_bridge.frames import Frame
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import HEART_SCALARS, SIGNAL_FEATURES
from hri_physio_processing.processor import FrameOutput, NeurokitProcessor, Output, StatusOutput


def random_chunks(n: int, rng: np.random.Generator, low: int = 1, high: int = 400) -> list[tuple[int, int]]:
    """Consecutive [a, b) ranges covering 0..n with random lengths."""
    out, i = [], 0
    while i < n:
        k = int(rng.integers(low, high + 1))
        out.append((i, min(n, i + k)))
        i += k
    return out


def match_beats(reference: np.ndarray, detected: np.ndarray, tol: float = 0.05) -> int:
    """True positives: reference beats with an unused detection within ``tol`` s (closest first)."""
    used = np.zeros(detected.shape[0], dtype=bool)
    tp = 0
    for r in reference:
        k = int(np.searchsorted(detected, r))
        cands = [c for c in (k - 1, k) if 0 <= c < detected.shape[0] and not used[c]
                 and abs(detected[c] - r) <= tol]
        if cands:
            used[min(cands, key=lambda c: abs(detected[c] - r))] = True
            tp += 1
    return tp


def run_processor(cfg: ProcessorConfig, t: np.ndarray, x: np.ndarray,
                  chunks: list[tuple[int, int]]) -> tuple[NeurokitProcessor, list[Output]]:
    """Feed the stream in the given chunks, then finish; return the processor and its outputs."""
    proc = NeurokitProcessor(cfg)
    values = x.reshape(-1, 1) if x.ndim == 1 else x
    out: list[Output] = []
    for a, b in chunks:
        out.extend(proc.push(Frame(t[a:b], values[a:b])))
    out.extend(proc.finish())
    return proc, out


def frames_of(outputs: list[Output], feature: str) -> list[Frame]:
    return [o.frame for o in outputs if isinstance(o, FrameOutput) and o.feature == feature]


def joined(outputs: list[Output], feature: str) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps and first-channel values of every frame of ``feature``, concatenated."""
    frames = frames_of(outputs, feature)
    if not frames:
        return np.empty(0), np.empty(0)
    return (np.concatenate([f.timestamps for f in frames]),
            np.concatenate([f.values[:, 0] for f in frames]))


def statuses(outputs: list[Output], event: str | None = "window") -> list[dict]:
    return [o.payload for o in outputs
            if isinstance(o, StatusOutput) and (event is None or o.payload.get("event") == event)]


def published_peaks(outputs: list[Output], feature: str = "rpeaks") -> np.ndarray:
    t, mask = joined(outputs, feature)
    return t[mask == 1.0]


FS = 130
#: Every output of an ECG processor: the signal features and the heart scalars.
OUTPUTS = (*SIGNAL_FEATURES["ecg"], *HEART_SCALARS)


def nk_direct_ecg(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """The reference: NeuroKit2's cleaning, peaks, quality and artefact correction (``signal_fixpeaks``,
    Lipponen & Tarvainen 2019, its own iterative loop) called by hand, as a user would; rate and HRV
    by the definitions (``helpers.hrv_reference``). ``corrected``: beats moved, removed or inserted."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = nk.ecg_clean(x, sampling_rate=FS)
        _, info = nk.ecg_peaks(clean, sampling_rate=FS)
        peaks = np.asarray(info["ECG_R_Peaks"])
        feats = {"quality": float(np.mean(nk.ecg_quality(clean, rpeaks=peaks, sampling_rate=FS,
                                                         method="templatematch")))}
    beats, corrected = nk_corrected_beats(peaks)
    feats["corrected"] = float(corrected)
    nn = np.diff(beats) * 1000.0
    feats["hr"] = float(np.mean(60000.0 / np.diff(peaks / FS * 1000.0)))  # ECG: every detected interval
    feats.update(hrv_reference.time_domain(nn))
    feats.update(hrv_reference.band_powers(nn, beat_times=beats))
    return clean, peaks, feats


def nk_corrected_beats(peaks: np.ndarray) -> tuple[np.ndarray, int]:
    """Beat times (s) of peak indices at ``FS`` after NeuroKit2's artefact correction (see below)."""
    return nk_corrected_times(np.asarray(peaks) / FS)


def nk_corrected_times(times: np.ndarray) -> tuple[np.ndarray, int]:
    """Beat times (s) after NeuroKit2's ``signal_fixpeaks`` (kubios, iterative) on microseconds from the
    first beat, and how many beats it moved, removed or inserted."""
    times = np.asarray(times, dtype=np.float64)
    us = np.rint((times - times[0]) * 1e6).astype(np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, fixed = nk.signal_fixpeaks(us, sampling_rate=1_000_000, method="kubios", iterative=True)
    fixed = np.unique(np.asarray(fixed, dtype=np.int64))
    corrected = max(np.setdiff1d(us, fixed).shape[0], np.setdiff1d(fixed, us).shape[0])
    return (times[0] + fixed / 1e6 if corrected else times), corrected


class Outputs:
    """Subscribe to every output of a processor prefix (frames and the JSON status)."""

    def __init__(self, collector: Any, prefix: str) -> None:
        from std_msgs.msg import String

        from hri_physio_bridge.qos import event_qos

        self.collector = collector
        self.frames = {name: collector.subscribe_frames(f"{prefix}/{name}") for name in OUTPUTS}
        self.status: list[dict] = []
        self._lock = threading.Lock()

        def on_status(msg: String) -> None:
            with self._lock:
                self.status.append(json.loads(msg.data))

        # As deep as the publisher's: a processor catching up on a backlog publishes windows in bursts.
        collector.node.create_subscription(String, f"{prefix}/status", on_status, event_qos())

    def windows(self) -> list[dict]:
        with self._lock:
            return [s for s in self.status if s.get("event") == "window"]

    def joined(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        frames = list(self.frames[name])
        if not frames:
            return np.empty(0), np.empty(0)
        return (np.concatenate([f.timestamps for f in frames]),
                np.concatenate([f.values[:, 0] for f in frames]))

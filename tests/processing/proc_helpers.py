"""Helpers for the processing tests (imported by name; pytest puts this folder on sys.path)."""

from __future__ import annotations

import numpy as np

from hri_physio_bridge.frames import Frame
from hri_physio_processing.config import ProcessorConfig
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

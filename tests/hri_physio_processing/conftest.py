"""Shared fixtures for the processing tests: real ECG (MIT-BIH 100) and a processor driver."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from helpers import DATA

DATA = DATA / "mitdb"
FS = 130.0
#: WFDB beat annotation symbols (everything else in .atr is rhythm, noise or comment).
BEAT_SYMBOLS = set("NLRBAaJSVrFejnE/fQ?")


@dataclass(frozen=True)
class Record:
    t: np.ndarray  # seconds, 130 Hz
    x: np.ndarray  # MLII, mV, resampled to 130 Hz
    beats: np.ndarray  # reference beat times, seconds


@pytest.fixture(scope="session")
def mitdb() -> Record:
    """Record 100, lead MLII, resampled 360 -> 130 Hz (polyphase, 13/36)."""
    import wfdb
    from scipy.signal import resample_poly

    rec = wfdb.rdrecord(str(DATA / "100"), channels=[0])
    ann = wfdb.rdann(str(DATA / "100"), "atr")
    assert rec.fs == 360
    x = resample_poly(rec.p_signal[:, 0], 13, 36)
    beats = np.array([s for s, sym in zip(ann.sample, ann.symbol, strict=True) if sym in BEAT_SYMBOLS])
    return Record(np.arange(x.shape[0]) / FS, x, beats / 360.0)


@pytest.fixture
def collector(ros_context):
    """A subscriber node (real rclpy) for the processor's outputs, closed after the test."""
    from helpers import RosFrameCollector

    c = RosFrameCollector(ros_context)
    yield c
    c.close()

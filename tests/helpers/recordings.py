"""Real recordings shipped in tests/data, with their independent references (tests and bench)."""

from __future__ import annotations

import gzip
from dataclasses import dataclass

import numpy as np

from helpers import DATA


@dataclass(frozen=True)
class Ecg208:
    x130: np.ndarray  # mV, resampled 360 -> 130 Hz
    gqrs: np.ndarray  # reference beat times (s): wfdb's GQRS detector on the 360 Hz signal

    def gaps(self, longer_than: float = 2.0) -> list[tuple[float, float]]:
        """Beat-free stretches of the reference: (last beat before, first beat after), s."""
        rr = np.diff(self.gqrs)
        return [(float(self.gqrs[i]), float(self.gqrs[i + 1])) for i in np.flatnonzero(rr > longer_than)]

    def rate(self, t0: float, t1: float, max_rr: float = 2.0) -> float:
        """Reference rate in [t0, t1]: mean of 60 / RR (as pyhrv, hrv-analysis), beat-free stretches out."""
        rr = np.diff(self.gqrs[(self.gqrs >= t0) & (self.gqrs <= t1)])
        return float(np.mean(60.0 / rr[rr <= max_rr]))


def ecg208() -> Ecg208:
    """MIT-BIH 208, 5 min, as scipy 1.11.4 shipped it (tests/data/scipy_ecg208)."""
    import wfdb.processing
    from scipy.signal import resample_poly

    with open(DATA / "scipy_ecg208" / "ecg.dat", "rb") as f:
        raw = np.load(f)["ecg"].astype(np.float64)
    x360 = (raw - 1024.0) / 200.0  # scipy.misc.electrocardiogram's scaling, mV
    gqrs = np.asarray(wfdb.processing.gqrs_detect(sig=x360, fs=360), dtype=np.float64) / 360.0
    return Ecg208(resample_poly(x360, 13, 36), gqrs)


@dataclass(frozen=True)
class Ppg:
    name: str
    x: np.ndarray
    fs: float  # mean rate of the recording's own clock
    ref_t: np.ndarray  # heartpy's peaks (s)
    ref_ok: np.ndarray  # heartpy accepted the peak

    def rate(self, t0: float, t1: float, min_cover: float = 0.5) -> float:
        """Reference rate in [t0, t1]: 60 / median of heartpy's accepted consecutive intervals there;
        NaN when those cover less than ``min_cover`` of the stretch (heartpy rejected the rest)."""
        ibi = np.diff(self.ref_t)
        sel = self.ref_ok[1:] & self.ref_ok[:-1] & (self.ref_t[:-1] >= t0) & (self.ref_t[1:] <= t1)
        if ibi[sel].sum() < min_cover * (t1 - t0):
            return float("nan")
        return float(60.0 / np.median(ibi[sel]))


def heartpy_ppg(name: str) -> Ppg:
    """heartpy's data2 (2 min, ~117 Hz) or data3 (11 min, ~100.4 Hz) finger PPG (tests/data/heartpy_ppg)."""
    with gzip.open(DATA / "heartpy_ppg" / f"{name}.csv.gz", "rt") as f:
        d = np.genfromtxt(f, delimiter=",", names=True)
    clock_ms = d[d.dtype.names[0]]
    x = d[d.dtype.names[1]].astype(np.float64)
    fs = (x.shape[0] - 1) / (clock_ms[-1] / 1000.0)
    ref = np.loadtxt(DATA / "heartpy_ppg" / f"{name}_heartpy_peaks.csv", delimiter=",")
    return Ppg(name, x, fs, ref[:, 0] / fs, ref[:, 2] == 1)

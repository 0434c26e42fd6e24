"""Reference beats for the two heartpy PPG recordings, from heartpy's own detector (run once).

heartpy is not a dependency of HRI Physio: run this with heartpy 1.2.7 importable (e.g.
``pip install --target /tmp/refs --no-deps heartpy==1.2.7`` and ``PYTHONPATH=/tmp/refs``). It
writes ``<name>_heartpy_peaks.csv``: every peak heartpy found (sample index into the recording,
time in s at the recording's mean rate) and whether heartpy accepted it (its outlier rejection).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import heartpy as hp
import numpy as np

HERE = Path(__file__).parent


def load(name: str) -> tuple[np.ndarray, float]:
    """Samples and mean sampling rate (Hz) from the recording's own clock column."""
    with gzip.open(HERE / f"{name}.csv.gz", "rt") as f:
        d = np.genfromtxt(f, delimiter=",", names=True)
    clock_ms = d[d.dtype.names[0]]
    return d[d.dtype.names[1]].astype(np.float64), (clock_ms.shape[0] - 1) / (clock_ms[-1] / 1000.0)


def main() -> None:
    for name in ("data2", "data3"):
        x, fs = load(name)
        wd, _ = hp.process(x, fs)
        peaks = np.asarray(wd["peaklist"], dtype=np.int64)
        accepted = np.asarray(wd["binary_peaklist"], dtype=np.int64)
        rows = np.column_stack([peaks, peaks / fs, accepted])
        np.savetxt(HERE / f"{name}_heartpy_peaks.csv", rows, fmt=["%d", "%.6f", "%d"], delimiter=",",
                   header="sample,t_s,accepted  (heartpy 1.2.7 wheel"
                          f" process(), fs={fs:.6f} Hz)", comments="# ")


if __name__ == "__main__":
    main()

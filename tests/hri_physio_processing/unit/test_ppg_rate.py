"""PPG heart rate on real finger-PPG recordings (heartpy's data2, 2 min, and data3, 11 min).

Reference: heartpy's own detector (a different algorithm from NeuroKit2's), 60 / median of its
accepted consecutive inter-beat intervals in each window; windows where those cover less than half
the window are not scored. Before this work the published rate (NeuroKit2's mean instantaneous
rate of all peaks) was off by p90 8.5 bpm on data2 and 3.3 bpm on data3, and the saturation check
dropped 30 % of data3's windows for its clipped peaks.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.processing import run_processor, statuses
from helpers.recordings import heartpy_ppg
from hri_physio_processing.config import ProcessorConfig


@pytest.mark.parametrize("name", ["data2", "data3"])
def test_ppg_rate_within_3_bpm_p90_of_an_independent_detector(name: str) -> None:
    rec = heartpy_ppg(name)
    t = np.arange(rec.x.shape[0]) / rec.fs
    cfg = ProcessorConfig.from_mapping({"mode": "ppg", "sampling_rate": rec.fs, "window_seconds": 60,
                                        "hop_seconds": 5, "input": "ros:/physio/test/ppg"})
    step = int(rec.fs)
    chunks = [(i, min(i + step, t.shape[0])) for i in range(0, t.shape[0], step)]
    _, out = run_processor(cfg, t, rec.x, chunks)
    wins = statuses(out)
    scored, errors = 0, []
    for st in wins:
        ref = rec.rate(st["window"]["t_start"], st["window"]["t_end"])
        if math.isnan(ref):
            continue
        scored += 1
        hr = st["features"]["hr"]
        if hr is None:
            assert st["nan"]["hr"]  # a reason
            continue
        errors.append(abs(hr - ref))
    assert scored >= (8 if name == "data2" else 100)
    assert len(errors) >= 0.7 * scored  # at most 30 % of the windows without a rate
    assert np.percentile(errors, 90) <= 3.0
    assert all("beats" in st and st["beats"]["detected"] > 0 for st in wins if st["ok"])

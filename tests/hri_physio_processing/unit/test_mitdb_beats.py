"""R-peaks on real ECG (MIT-BIH 100 at 130 Hz) through the processor logic, scored against the
reference annotations, with no beat lost or counted twice where windows overlap or meet.

(The same record through the real physio_receiver and neurokit_processor nodes is in
test_node_integration.py.)
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.processing import match_beats, published_peaks, random_chunks, run_processor, statuses
from hri_physio_processing.config import ProcessorConfig

FS = 130


def score(reference: np.ndarray, detected: np.ndarray) -> tuple[float, float]:
    tp = match_beats(reference, detected, 0.05)
    return tp / reference.shape[0], tp / detected.shape[0]


@pytest.mark.parametrize("window,hop", [(20, 20), (45, 10)])
def test_rpeaks_against_reference_annotations(mitdb, window: float, hop: float) -> None:
    cfg = ProcessorConfig.from_mapping(
        {"window_seconds": window, "hop_seconds": hop, "quality_method": "none"}
    )
    n = mitdb.x.shape[0]
    _, out = run_processor(cfg, mitdb.t, mitdb.x, random_chunks(n, np.random.default_rng(9), 1, 1000))
    wins = statuses(out)
    assert all(st["ok"] for st in wins)
    det = published_peaks(out)
    se, ppv = score(mitdb.beats, det)
    assert se >= 0.995 and ppv >= 0.995, (se, ppv)
    assert np.all(np.diff(det) > 0.25)  # strictly increasing, no beat twice (RR >= 0.5 s in record 100)
    # Windowing loses and doubles nothing: the same beats as NeuroKit2 offline on the whole
    # record (2270 peaks, the README's baseline), to within one sample.
    offline = offline_peaks(mitdb.x) / FS
    assert det.shape[0] == offline.shape[0] == 2270
    assert match_beats(offline, det, tol=1.5 / FS) == 2270
    # In particular around the boundaries between one window's published part and the next.
    bounds = np.array([st["published"]["t_start"] for st in wins[1:]])
    near = mitdb.beats[np.min(np.abs(mitdb.beats[:, None] - bounds[None, :]), axis=1) < 1.0]
    near_found_offline = near[[match_beats(np.array([b]), offline) == 1 for b in near]]
    assert near_found_offline.shape[0] > 50
    assert match_beats(near_found_offline, det) == near_found_offline.shape[0]


def offline_peaks(x: np.ndarray) -> np.ndarray:
    import neurokit2 as nk

    _, info = nk.ecg_peaks(nk.ecg_clean(x, sampling_rate=FS), sampling_rate=FS)
    return np.asarray(info["ECG_R_Peaks"], dtype=np.float64)


def test_match_beats_scoring_helper() -> None:
    ref = np.array([1.0, 2.0, 3.0])
    assert match_beats(ref, np.array([1.01, 2.06, 3.0, 3.02])) == 2  # 2.06 too far; 3.02 a spare
    assert match_beats(ref, np.array([1.0])) == 1

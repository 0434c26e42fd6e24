"""Every published window's features equal NeuroKit2 called directly on that window's samples.

Real ECG (MIT-BIH 100 at 130 Hz), several window/hop settings, random input chunking. Also:
an independent numpy HRV computation on the same R-peaks, and PPG / EDA modes.
"""

from __future__ import annotations

import math
import warnings

import neurokit2 as nk
import numpy as np
import pytest

from helpers import hrv_reference
from helpers.processing import (
    frames_of,
    joined,
    nk_corrected_beats,
    nk_direct_ecg,
    published_peaks,
    random_chunks,
    run_processor,
    statuses,
)
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import HEART_SCALARS, MIN_SECONDS

FS = 130


@pytest.mark.parametrize("window,hop,seconds", [(60, 5, 95), (20, 20, 70), (130, 65, 200), (300, 110, 420)])
def test_ecg_features_equal_neurokit_on_each_window(mitdb, window: float, hop: float, seconds: float) -> None:
    n = int(seconds * FS)
    t, x = 1000.0 + mitdb.t[:n], mitdb.x[:n]  # an LSL-like clock offset
    # hrv_window_seconds 0: LF, HF, LF/HF on each window itself (the long window is tested below)
    cfg = ProcessorConfig.from_mapping({"window_seconds": window, "hop_seconds": hop,
                                        "hrv_window_seconds": 0})
    _, out = run_processor(cfg, t, x, random_chunks(n, np.random.default_rng(window), 1, 700))
    wins = statuses(out)
    assert len(wins) >= 2
    scalars = {name: frames_of(out, name) for name in HEART_SCALARS}
    clean_t, clean_v = joined(out, "clean")
    np.testing.assert_array_equal(clean_t, t)  # the published parts tile the stream exactly
    for k, st in enumerate(wins):
        w = st["window"]
        a = int(np.searchsorted(t, w["t_start"]))
        b = a + w["samples"]
        assert t[b - 1] == w["t_end"] == st["t"]
        assert st["ok"], st["flags"]
        clean, _, ref = nk_direct_ecg(x[a:b])
        for name, frames in scalars.items():
            frame = frames[k]
            assert frame.timestamps[0] == w["t_end"]  # stamped with the end of its window
            got = frame.values[0, 0]
            need = MIN_SECONDS.get(name, 0)
            if w["seconds"] < need:
                assert math.isnan(got) and "shorter than" in st["nan"][name]
            else:
                reason = st["nan"].get(name, "")
                if "corrected as artefacts" in reason:  # too many: HRV NaN
                    assert math.isnan(got) and ref["corrected"] > 0.1 * st["beats"]["detected"]
                    continue
                # corrected beats sit on a microsecond grid (from the window's first beat, in the
                # reference from its first sample): up to 1 us apart
                rel = 1e-3 if ref["corrected"] and name != "quality" else 1e-9
                assert got == pytest.approx(ref[name], rel=rel, abs=1e-12), (name, k)
        assert st["beats"]["corrected"] == ref["corrected"]
        if "published" in st:  # the cleaned signal published for this window's new part
            lead = st["lead_in_samples"]  # windows that barely overlap are cleaned with a lead-in
            assert (lead > 0) == (hop > window - 4 and k > 0) and lead <= a
            if lead:
                clean = nk_direct_ecg(x[a - lead : b])[0]
            pa = int(np.searchsorted(t, st["published"]["t_start"]))
            pb = int(np.searchsorted(t, st["published"]["t_end"])) + 1
            sel = (clean_t >= t[pa]) & (clean_t <= t[pb - 1])
            base = a - lead
            np.testing.assert_allclose(clean_v[sel], clean[pa - base : pb - base], rtol=0, atol=1e-9)


def test_outputs_identical_for_any_chunking(mitdb) -> None:
    n = 80 * FS
    t, x = mitdb.t[:n], mitdb.x[:n]
    cfg = ProcessorConfig.from_mapping({"window_seconds": 30, "hop_seconds": 7, "quality_method": "none"})

    def flat(out: list) -> list:
        return [(o.feature, o.frame.timestamps.tobytes(), o.frame.values.tobytes()) if hasattr(o, "frame")
                else ("status", repr(o.payload)) for o in out]

    _, ref = run_processor(cfg, t, x, [(0, n)])
    for chunks in (random_chunks(n, np.random.default_rng(3), 1, 50), [(i, i + 1) for i in range(n)]):
        _, out = run_processor(cfg, t, x, chunks)
        assert flat(out) == flat(ref)


def test_hrv_time_domain_matches_independent_numpy(mitdb) -> None:
    """SDNN, RMSSD, pNN50 from the R-peaks by hand (numpy) within 1 % of the published ones."""
    n = 200 * FS
    t, x = mitdb.t[:n], mitdb.x[:n]
    cfg = ProcessorConfig.from_mapping({"window_seconds": 60, "hop_seconds": 30, "quality_method": "none"})
    _, out = run_processor(cfg, t, x, [(0, n)])
    wins = statuses(out)
    assert len(wins) >= 5
    for k, st in enumerate(wins):
        a = int(np.searchsorted(t, st["window"]["t_start"]))
        _, peaks, _ = nk_direct_ecg(x[a : a + st["window"]["samples"]])
        beats, _ = nk_corrected_beats(peaks)  # NN: after the artefact correction
        rr = np.diff(beats) * 1000.0  # ms
        drr = np.diff(rr)
        # pNN50 as the Task Force (1996), pyhrv and hrv-analysis compute it: NN50 over the number of
        # successive differences.
        mine = {"sdnn": np.std(rr, ddof=1), "rmssd": np.sqrt(np.mean(drr**2)),
                "pnn50": 100.0 * np.count_nonzero(np.abs(drr) > 50.0) / drr.shape[0]}
        for name, value in mine.items():
            got = frames_of(out, name)[k].values[0, 0]
            assert got == pytest.approx(value, rel=0.01), (name, k, got, value)
    assert any(frames_of(out, "pnn50")[k].values[0, 0] > 0 for k in range(len(wins)))  # not all trivial 0


def test_ppg_mode_equals_ppg_process() -> None:
    x = nk.ppg_simulate(duration=70, sampling_rate=FS, heart_rate=75, random_state=4)
    t = 50.0 + np.arange(x.shape[0]) / FS
    cfg = ProcessorConfig.from_mapping({"mode": "ppg", "window_seconds": 60, "hop_seconds": 5,
                                        "hrv_window_seconds": 0, "input": "ros:/physio/polar_oh1/ppg"})
    _, out = run_processor(cfg, t, x, random_chunks(x.shape[0], np.random.default_rng(0), 1, 300))
    wins = statuses(out)
    assert len(wins) == 3 and all(st["ok"] for st in wins)
    for k, st in enumerate(wins):
        a = int(np.searchsorted(t, st["window"]["t_start"]))
        seg = x[a : a + st["window"]["samples"]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sig, info = nk.ppg_process(seg, sampling_rate=FS)
        beats, corrected = nk_corrected_beats(info["PPG_Peaks"])
        rr = np.diff(beats) * 1000.0
        ref = {"hr": hrv_reference.mean_rate(rr), "quality": sig["PPG_Quality"].mean(),
               **hrv_reference.time_domain(rr), "hf": hrv_reference.band_powers(rr, beat_times=beats)["hf"]}
        assert st["beats"]["corrected"] == corrected
        for name, value in ref.items():
            assert frames_of(out, name)[k].values[0, 0] == pytest.approx(value, rel=1e-6), name
        assert math.isnan(frames_of(out, "lf")[k].values[0, 0])
    assert frames_of(out, "peaks") and frames_of(out, "beat_hr")
    beat_t, beat_hr = joined(out, "beat_hr")
    peak_t = published_peaks(out, "peaks")
    assert beat_t.shape[0] == peak_t.shape[0] - 1  # every beat but the very first has a rate
    np.testing.assert_array_equal(beat_t, peak_t[1:])
    np.testing.assert_allclose(beat_hr, 60.0 / np.diff(peak_t), rtol=1e-9)
    assert abs(np.median(beat_hr) - 75) < 10


def test_eda_mode_equals_eda_process() -> None:
    x = nk.eda_simulate(duration=90, sampling_rate=FS, scr_number=6, drift=-0.01, random_state=5)
    t = np.arange(x.shape[0]) / FS
    cfg = ProcessorConfig.from_mapping({"mode": "eda", "window_seconds": 40, "hop_seconds": 20,
                                        "input": "ros:/physio/sim/eda"})
    _, out = run_processor(cfg, t, x, random_chunks(x.shape[0], np.random.default_rng(2), 1, 500))
    wins = statuses(out)
    assert len(wins) == 4 and all(st["ok"] for st in wins)
    total_scr = 0
    for k, st in enumerate(wins):
        a = int(np.searchsorted(t, st["window"]["t_start"]))
        seg = x[a : a + st["window"]["samples"]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sig, info = nk.eda_process(seg, sampling_rate=FS)
        peaks = [p for p in info["SCR_Peaks"] if np.isfinite(p)]
        assert frames_of(out, "tonic")[k].values[0, 0] == pytest.approx(sig["EDA_Tonic"].mean(), rel=1e-9)
        assert frames_of(out, "scr_count")[k].values[0, 0] == len(peaks)
        amp = frames_of(out, "scr_amplitude")[k].values[0, 0]
        if peaks:
            assert amp == pytest.approx(np.nanmean(info["SCR_Amplitude"]), rel=1e-9)
        else:
            assert math.isnan(amp) and "no skin conductance" in st["nan"]["scr_amplitude"]
        total_scr += len(peaks)
    assert total_scr > 0
    mask_t, mask = joined(out, "scr_peaks")
    np.testing.assert_array_equal(mask_t, t)
    assert 1 <= mask.sum() <= total_scr  # each response once, though windows overlap

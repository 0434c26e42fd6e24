"""RR artefacts: beat-free stretches and Lipponen & Tarvainen (2019) correction, on real ECG.

MIT-BIH 208 (scipy's 5-min excerpt): premature ventricular beats, an amplifier saturation of
2.6 s and a baseline jump of 4.2 s without detectable beats (wfdb's GQRS detector is the
independent reference). Before this work none of the windows over those stretches was flagged
and their SDNN was 220 ms against 80 ms elsewhere.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.processing import run_processor, statuses
from helpers.recordings import ecg208
from hri_physio_processing.artifacts import clean_beats, correct_run
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import robust_rate

FS = 130


@pytest.fixture(scope="module")
def record():
    return ecg208()


@pytest.fixture(scope="module")
def windows_208(record) -> list[dict]:
    t = np.arange(record.x130.shape[0]) / FS
    cfg = ProcessorConfig.from_mapping({"window_seconds": 60, "hop_seconds": 5})
    chunks = [(i, min(i + 650, t.shape[0])) for i in range(0, t.shape[0], 650)]
    _, out = run_processor(cfg, t, record.x130, chunks)
    return statuses(out)


def test_windows_holding_a_beat_free_stretch_publish_no_hrv(record, windows_208) -> None:
    gaps = record.gaps()
    assert [round(b - a, 1) for a, b in gaps] == [2.6, 4.2]
    holding = [st for st in windows_208
               if any(st["window"]["t_start"] < a and b < st["window"]["t_end"] for a, b in gaps)]
    assert len(holding) >= 20
    for st in holding:
        for key in ("sdnn", "rmssd", "pnn50", "pnn20"):
            assert st["features"][key] is None, (st["window"], key)
            assert "beat-free stretch" in st["nan"][key]
        assert st["beats"]["beat_free"]  # where, in the status
        assert st["features"]["hr"] is not None  # the rate comes from the beats around the stretch
    # No window publishes an SDNN or RMSSD inflated by a stretch or by artefacts (208 has a premature
    # ventricular beat in every few: most windows hold more than 10 % and their HRV is NaN, with why).
    sdnn = [st["features"]["sdnn"] for st in windows_208 if st["features"]["sdnn"] is not None]
    rmssd = [st["features"]["rmssd"] for st in windows_208 if st["features"]["rmssd"] is not None]
    assert len(sdnn) >= 3 and max(sdnn) < 130.0 and max(rmssd) < 200.0  # was 220 / 323 ms over the stretches
    for st in windows_208:
        if st["features"]["sdnn"] is None:
            assert "beat-free" in st["nan"]["sdnn"] or "artefacts" in st["nan"]["sdnn"], st["nan"]["sdnn"]


def test_corrected_beats_are_reported_and_rate_follows_the_reference(record, windows_208) -> None:
    corrected = [st["beats"]["corrected"] for st in windows_208]
    assert all(isinstance(c, int) and c >= 0 for c in corrected)
    assert sum(c > 0 for c in corrected) >= len(corrected) // 2  # 208 is full of premature beats
    errors = [abs(st["features"]["hr"] - record.rate(st["window"]["t_start"], st["window"]["t_end"]))
              for st in windows_208]
    assert len(errors) == len(windows_208)
    assert np.percentile(errors, 90) < 5.0


def test_the_long_hrv_window_restarts_after_a_stretch(record, windows_208) -> None:
    """LF, HF, LF/HF come from 300 s of beats fit for HRV: the series restarts after every window
    whose beats are not (a beat-free stretch, too many artefacts), so no long window holds a stretch."""
    gaps = record.gaps()
    restarted = 0
    for st in windows_208:
        h = st["hrv_window"]
        if h["t_start"] is None:
            assert st["features"]["lf"] is None
            continue
        assert not any(h["t_start"] < a and b < h["t_end"] for a, b in gaps), h
        restarted += h["t_start"] > gaps[0][1]
    assert restarted >= 1
    unfit = [st for st in windows_208 if st["features"]["sdnn"] is None]
    assert all(st["hrv_window"]["t_start"] is None for st in unfit)


def rsa_beats(n: int) -> np.ndarray:
    """Beat times of a sinus rhythm at 75 bpm with a 0.25 Hz respiratory modulation of +-40 ms."""
    k = np.arange(n)
    return np.cumsum(0.8 + 0.04 * np.sin(2 * np.pi * 0.2 * k))


def test_clean_beats_on_a_series_with_a_stretch_an_extra_and_a_missed_beat() -> None:
    t = rsa_beats(120)
    extra = np.sort(np.append(t, t[30] + 0.3))  # a spurious beat 0.3 s after a real one
    missed = np.delete(extra, 70)  # a beat the detector lost
    gap = np.concatenate([missed[missed < t[100]], missed[missed > t[100] + 3.0]])  # 3 s without beats
    res = clean_beats(gap)
    assert len(res.runs) == 2 and len(res.gaps) == 1 and "beat-free stretch" in res.hrv_reason
    assert res.corrected_beats >= 2 and res.found["missed"] >= 1
    assert res.nn_ms.max() < 1000.0  # the stretch is no interval
    assert res.beats == gap.shape[0]
    # A clean series is left exactly as it was.
    fixed, counts, changed = correct_run(t)
    assert changed == 0 and fixed is t and not any(counts.values())


@pytest.mark.parametrize("every", [6, 10, 15])
@pytest.mark.parametrize("mode", ["ecg", "ppg"])
def test_spurious_beats_never_reach_hrv(every: int, mode: str) -> None:
    """Spurious beats in 60: the correction catches some (its thresholds adapt to the contaminated
    series); corrected plus left-over irregular intervals above 10 % make HRV NaN. A PPG rate rests on
    the regular intervals and holds; an ECG rate counts every detected beat (R-peaks are trusted)."""
    from hri_physio_processing.features import FeatureSettings, _heart

    t = rsa_beats(60)
    noisy = np.sort(np.concatenate([t, t[5:60:every] + 0.3]))
    peaks = np.rint(noisy * FS).astype(np.int64)
    res = _heart(np.zeros(peaks[-1] + FS), peaks, lambda: math.nan,
                 FeatureSettings(mode=mode, quality_method="none"))
    assert math.isnan(res.scalars["sdnn"]) and math.isnan(res.scalars["rmssd"])
    if math.isfinite(res.scalars["hr"]):
        assert "artefacts" in res.nan_reasons["sdnn"]
        if mode == "ppg":
            assert res.scalars["hr"] == pytest.approx(75.0, abs=1.0)
    else:  # so many that no rate is trusted either
        assert "no trusted rate" in res.nan_reasons["hr"] == res.nan_reasons["sdnn"]


def test_robust_rate_ignores_a_left_over_extra_beat() -> None:
    nn = np.full(60, 1000.0)
    nn[20:22] = [310.0, 690.0]  # one extra peak splits an interval
    rate, regular = robust_rate(nn)
    assert rate == pytest.approx(60.0, abs=0.01) and regular == pytest.approx(58 / 60)
    assert np.mean(60000.0 / nn) > 62.0  # a plain mean of instantaneous rates is pulled up
    assert all(math.isnan(v) for v in robust_rate(np.empty(0)))


def test_an_irregular_rhythm_keeps_its_ecg_rate_but_no_hrv() -> None:
    """Atrial-fibrillation-like intervals (uniform 0.45-1.05 s): R-peaks are trusted, so the ECG rate
    stays (every interval counts); PPG gives no rate; HRV is NaN in both."""
    from hri_physio_processing.features import FeatureSettings, _heart

    rr = np.random.default_rng(7).uniform(0.45, 1.05, 80)
    peaks = np.rint(np.cumsum(rr) * FS).astype(np.int64)
    for mode in ("ecg", "ppg"):
        res = _heart(np.zeros(peaks[-1] + FS), peaks, lambda: math.nan,
                     FeatureSettings(mode=mode, quality_method="none"))
        assert math.isnan(res.scalars["sdnn"]) and res.nan_reasons["sdnn"]
        if mode == "ecg":
            want = np.mean(60.0 / (np.diff(peaks) / FS))
            assert res.scalars["hr"] == pytest.approx(want, rel=1e-9)
        else:
            assert math.isnan(res.scalars["hr"]) and "no trusted rate" in res.nan_reasons["hr"]

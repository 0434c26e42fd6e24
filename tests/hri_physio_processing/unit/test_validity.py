"""Validity rules and bad input: NaN with a reason, flagged windows, never a crash or a silent 0."""

from __future__ import annotations

import math

import neurokit2 as nk
import numpy as np
import pytest

from helpers import SRC
from helpers.processing import frames_of, random_chunks, run_processor, statuses
from hri_physio_bridge.config import ConfigError
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import FeatureSettings, extract
from hri_physio_processing.signal_checks import check_values, longest_run

FS = 130


def ecg(seconds: float, bpm: float = 70, seed: int = 1) -> np.ndarray:
    return nk.ecg_simulate(duration=seconds, sampling_rate=FS, heart_rate=bpm, noise=0.01, random_state=seed)


def features(x: np.ndarray, **kw) -> object:
    t = np.arange(x.shape[0]) / FS
    return extract(t, x, FeatureSettings(sampling_rate=FS, **kw))


@pytest.mark.parametrize("seconds,nan_expected", [
    (30, {"hf", "lf", "lfhf"}), (60, {"lf", "lfhf"}), (150, {"lfhf"}), (300, set()),
])
def test_frequency_features_need_long_enough_windows(mitdb, seconds: int, nan_expected: set) -> None:
    r = features(mitdb.x[: seconds * FS], quality_method="none")
    assert r.ok, r.flags
    for key in ("hf", "lf", "lfhf"):
        if key in nan_expected:
            assert math.isnan(r.scalars[key]) and "shorter than" in r.nan_reasons[key]
        else:
            assert math.isfinite(r.scalars[key]) and r.scalars[key] > 0
    for key in ("hr", "sdnn", "rmssd", "pnn50"):
        assert math.isfinite(r.scalars[key])


def test_too_few_beats_gives_nan_with_reason() -> None:
    r = features(ecg(5, bpm=40), min_beats=5)
    assert not r.ok and r.flags[0].code == "too_few_beats"
    assert all(math.isnan(v) for v in r.scalars.values())
    assert "beat(s) found" in r.nan_reasons["sdnn"]
    assert r.peaks.shape[0] == 0


def test_signal_checks() -> None:
    x = np.sin(np.arange(1000) / 5.0)
    assert check_values(x, FS, 2.0, 0.01) == []
    flat = x.copy()
    flat[100:400] = 0.25
    assert [f.code for f in check_values(flat, FS, 2.0, 0.01)] == ["flatline"]
    clipped = np.clip(x, -0.5, 0.5)
    assert [f.code for f in check_values(clipped, FS, 2.0, 0.01)] == ["saturated"]
    holes = x.copy()
    holes[10:30] = np.nan
    (flag,) = check_values(holes, FS, 2.0, 0.01)
    assert flag.code == "nonfinite" and "longest run 20" in flag.reason
    assert longest_run(np.array([1, 1, 0, 1, 1, 1, 0], dtype=bool)) == 3
    assert longest_run(np.zeros(5, dtype=bool)) == 0


@pytest.mark.parametrize("value", [1e308, -1e200, 1e20, 2e4])
def test_a_corrupt_sample_flags_only_windows_that_hold_it_and_says_so(mitdb, value: float) -> None:
    """One absurd value (a decoding error, a unit mix-up) in real ECG: before, the windows holding it
    said "only 1 beat(s) found" or "NeuroKit2 failed: IndexError"; a real artefact stays processed."""
    x = mitdb.x[: 60 * FS].copy()  # MIT-BIH in mV: its 1-99 % range is about 1.5
    x[30 * FS] = value
    _, out = _run(x)
    for st in statuses(out):
        w = st["window"]
        holds = w["t_start"] <= 30.0 <= w["t_end"]
        assert (_flags(st) == {"corrupt_values"}) == holds, st
        if holds:
            assert f"the farthest {value:.3g}" in st["flags"][0]["reason"], st["flags"]
    spike = mitdb.x[: 60 * FS].copy()
    spike[30 * FS] = 50.0  # a big artefact, 30 times the range: processed
    assert features(spike).ok
    many = mitdb.x[: 20 * FS].copy()
    many[::20] = 1e308 * (-1.0) ** np.arange(many[::20].shape[0])  # 5 %, both signs: the range overflows
    (flag,) = check_values(many, FS, 2.0, 0.01)
    assert flag.code == "corrupt_values" and "up to 1e+308" in flag.reason, flag


def test_real_quantised_ecg_is_not_flagged_saturated(mitdb) -> None:
    """MIT-BIH's 11-bit ADC values (5 uV steps) must not look clipped or flat."""
    raw = np.round(mitdb.x[: 60 * FS] * 200) / 200
    r = features(raw)
    assert r.ok, r.flags


def _run(x: np.ndarray, t: np.ndarray | None = None, **cfg) -> tuple:
    t = np.arange(x.shape[0]) / FS if t is None else t
    conf = ProcessorConfig.from_mapping({"window_seconds": 20, "hop_seconds": 5, **cfg})
    return run_processor(conf, t, x, random_chunks(x.shape[0], np.random.default_rng(0), 1, 200))


def _flags(st: dict) -> set[str]:
    return {f["code"] for f in st["flags"]}


def test_nan_run_flags_only_windows_that_contain_it(mitdb) -> None:
    x = mitdb.x[: 60 * FS].copy()
    x[30 * FS : 30 * FS + 40] = np.nan  # 0.3 s of NaN at t = 30 s
    proc, out = _run(x)
    for st in statuses(out):
        w = st["window"]
        holds = w["t_start"] <= 30.3 and w["t_end"] >= 30.0
        assert (_flags(st) == {"nonfinite"}) == holds, st
        if holds:
            assert all(math.isnan(frames_of(out, k)[w["index"]].values[0, 0]) for k in ("hr", "sdnn"))
            assert "NaN/inf" in st["nan"]["hr"]
    assert proc.stats.flagged_windows == 4  # windows ending at 35, 40, 45, 50 s (20 s long)


def test_gap_restarts_windows_and_is_reported(mitdb) -> None:
    n = 70 * FS
    keep = np.ones(n, dtype=bool)
    keep[30 * FS : 32 * FS] = False  # 2 s lost
    t, x = (np.arange(n) / FS)[keep], mitdb.x[:n][keep]
    _, out = _run(x, t)
    (gap,) = statuses(out, "discontinuity")
    assert gap["gaps"] == 1 and gap["missing_samples"] == 2 * FS
    assert "restart" in gap["reason"] and gap["t"] == pytest.approx(32.0)
    wins = statuses(out)
    assert all(st["ok"] for st in wins)
    assert not any(st["window"]["t_start"] < 30 < st["window"]["t_end"] for st in wins)  # none spans it
    assert {st["window"]["segment"] for st in wins} == {0, 1}
    # every sample is still published exactly once as cleaned signal
    clean_t = np.concatenate([f.timestamps for f in frames_of(out, "clean")])
    np.testing.assert_array_equal(clean_t, t)


def test_each_discontinuity_report_counts_what_came_since_the_last(mitdb) -> None:
    n = 90 * FS
    keep = np.ones(n, dtype=bool)
    keep[30 * FS : 32 * FS] = False  # 2 s lost
    keep[60 * FS : 61 * FS] = False  # then 1 s, long after the first report
    t, x = (np.arange(n) / FS)[keep], mitdb.x[:n][keep]
    proc, out = _run(x, t)
    first, second = statuses(out, "discontinuity")
    assert (first["gaps"], first["missing_samples"]) == (1, 2 * FS)
    assert (second["gaps"], second["missing_samples"]) == (1, FS)
    assert first["t"] == pytest.approx(32.0) and second["t_first"] == pytest.approx(60.0 - 1 / FS)
    assert (proc.stats.gaps, proc.stats.missing_samples) == (2, 3 * FS)  # the totals


def test_backward_clock_jump_restarts_windows_but_is_not_a_gap(mitdb) -> None:
    n = 70 * FS
    t = np.arange(n) / FS
    t[40 * FS :] -= 5.0  # the source clock steps 5 s back at 40 s: nothing is missing
    proc, out = _run(mitdb.x[:n], t)
    (jump,) = statuses(out, "discontinuity")
    assert (jump["gaps"], jump["missing_samples"], jump["backward_steps"]) == (0, 0, 1)
    assert proc.stats.gaps == 0 and proc.stats.clock_jumps == 1
    assert {st["window"]["segment"] for st in statuses(out)} == {0, 1}
    clean_t = np.concatenate([f.timestamps for f in frames_of(out, "clean")])
    np.testing.assert_array_equal(clean_t, t)  # every sample still published once


def test_samples_with_a_nan_or_infinite_timestamp_are_dropped_and_reported(mitdb) -> None:
    """They crashed the node (a NaN in its JSON status, an infinite gap length): now dropped, counted,
    reported with the discontinuities, and the windows go on from the good samples around them."""
    n = 70 * FS
    t = np.arange(n) / FS
    t[30 * FS] = np.nan
    t[30 * FS + 1] = np.inf
    proc, out = _run(mitdb.x[:n], t)
    assert proc.stats.bad_timestamp_samples == 2
    reports = statuses(out, "discontinuity")
    assert sum(r["bad_timestamp_samples"] for r in reports) == 2
    assert any("2 sample(s) dropped: their timestamp is NaN or infinite" in r["reason"] for r in reports)
    assert all(math.isfinite(r["t"]) for r in reports)
    clean_t = np.concatenate([f.timestamps for f in frames_of(out, "clean")])
    assert np.isfinite(clean_t).all() and clean_t.size == n - 2
    ends = [st["window"]["t_end"] for st in statuses(out)]
    assert min(ends) < 30 < max(ends)  # windows on both sides of the dropped samples (a gap between)


def test_wrong_sampling_rate_is_flagged(mitdb) -> None:
    x = mitdb.x[: 40 * FS]
    t = np.arange(x.shape[0]) / 100.0  # really 100 Hz timestamps, configured 130 Hz
    _, out = _run(x, t)
    wins = statuses(out)
    assert wins and all(_flags(st) == {"rate_mismatch"} for st in wins)
    assert "100 Hz" in wins[0]["flags"][0]["reason"]
    assert all(math.isnan(f.values[0, 0]) for f in frames_of(out, "hr"))


def test_far_too_slow_stream_reports_discontinuities_rate_limited() -> None:
    x = np.random.default_rng(0).normal(size=2000)
    t = np.arange(2000) / 50.0  # 40 s at 50 Hz: every step looks like a gap at 130 Hz
    proc, out = _run(x, t)
    assert statuses(out) == []  # nothing was long enough to process
    reports = statuses(out, "discontinuity")
    assert 1 <= len(reports) <= 40 / 5 + 2  # at most about one per hop of source time
    assert sum(r["discarded_samples"] for r in reports) == 2000
    assert "sampling_rate" in reports[-1]["reason"]
    assert proc.stats.gaps == 1999


def test_arrival_stamped_chunks_are_reported_with_the_receivers_dejitter_as_the_way_out() -> None:
    """A source that stamps each 73-sample chunk on arrival: every boundary steps a few ms forward or
    back, so no window fills; the report says what it looks like and what smooths it."""
    x = ecg(40.0)
    per_chunk = 73
    n = len(x) // per_chunk * per_chunk
    jitter = np.random.default_rng(2).uniform(0.0, 0.025, n // per_chunk)
    last = (np.arange(n // per_chunk) + 1) * per_chunk / FS + jitter
    t = (last[:, None] - (per_chunk - 1 - np.arange(per_chunk))[None, :] / FS).reshape(-1)
    _proc, out = _run(x[:n], t)
    assert statuses(out) == []
    reason = statuses(out, "discontinuity")[-1]["reason"]
    assert "forward and back" in reason and "?dejitter=1" in reason and "sampling_rate" not in reason


@pytest.mark.parametrize("kind", ["white", "emg", "brown", "sine", "flat", "clipped"])
def test_non_ecg_input_is_flagged_not_processed(kind: str) -> None:
    rng = np.random.default_rng(5)
    n = 40 * FS
    x = {
        "white": rng.normal(size=n),
        "emg": nk.emg_simulate(duration=40, sampling_rate=FS, burst_number=4, random_state=2),
        "brown": np.cumsum(rng.normal(size=n)),
        "sine": np.sin(2 * np.pi * 7 * np.arange(n) / FS),
        "flat": np.zeros(n),
        "clipped": np.clip(ecg(40), -0.2, 0.3),
    }[kind]
    _, out = _run(x)
    wins = statuses(out)
    assert wins
    for st in wins:
        assert not st["ok"], (kind, st["features"])
        assert all(v is None for k, v in st["features"].items() if k != "quality")
    for name in ("hr", "sdnn", "rmssd", "pnn50"):
        assert all(math.isnan(f.values[0, 0]) for f in frames_of(out, name))  # NaN, never 0
    _, mask = (np.concatenate([f.timestamps for f in frames_of(out, "rpeaks")]),
               np.concatenate([f.values[:, 0] for f in frames_of(out, "rpeaks")]))
    assert mask.sum() == 0 and frames_of(out, "beat_hr") == []


def test_clean_ecg_is_not_flagged() -> None:
    _, out = _run(ecg(40))
    assert all(st["ok"] for st in statuses(out))


@pytest.mark.parametrize("values,match", [
    ({"mode": "emg"}, "mode"),
    ({"hop_seconds": 90}, "hop_seconds"),
    ({"hop_seconds": 0}, "hop_seconds"),
    ({"sampling_rate": -1}, "sampling_rate"),
    ({"window_seconds": "long"}, "window_seconds"),
    ({"min_beats": 2.5}, "min_beats"),
    ({"lsl_output": "maybe"}, "lsl_output"),
    ({"sampling_rate": "fast", "buffer": 100}, "sampling_rate"),
    ({"input": "ros:bad"}, "must be absolute"),
    ({"input": "lsl:X"}, "output_prefix is required"),
    ({"input": "nope:X", "output_prefix": "/x"}, "unknown stream scheme"),
    ({"quality_method": "best"}, "quality_method"),
    ({"min_hr": 200, "max_hr": 100}, "min_hr"),
    ({"channel": 2}, "channel"),
    ({"bogus": 1}, "unknown option"),
    ({"buffer": 100, "window": 100}, "below buffer"),
    ({"buffer": 100, "window_seconds": 3}, "either buffer"),
    ({"window": 10}, "needs buffer"),
    ({"plot": True}, "plot is not supported"),
    ({"output_prefix": "relative/name"}, "absolute"),
])
def test_bad_configuration_is_refused_clearly(values: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        ProcessorConfig.from_mapping(values)


def test_seed_keys_are_translated() -> None:
    seed = {"name": "neurokitProcessor", "input": "/stream", "buffer": 7800, "window": 7150, "verbose": True}
    with pytest.raises(ConfigError, match="output_prefix is required"):  # an LSL input: say where to publish
        ProcessorConfig.from_mapping(seed)
    cfg = ProcessorConfig.from_mapping({**seed, "output_prefix": "/physio/seed/ecg/"})
    assert cfg.input == "lsl:/stream" and cfg.lsl_prefix == "/neurokitProcessor" and cfg.verbose
    assert cfg.window_samples == 7800 and cfg.hop_samples == 650
    assert cfg.resolved_output_prefix() == "/physio/seed/ecg"
    assert ProcessorConfig().resolved_output_prefix() == "/physio/polar_h10/ecg"


def test_shipped_config_file_holds_the_defaults() -> None:
    import yaml

    package = SRC / "hri_physio_processing"
    path = package / "config" / "neurokit_processor.yaml"
    values = yaml.safe_load(path.read_text())
    assert set(values) == set(ProcessorConfig.model_fields)
    assert ProcessorConfig.from_mapping(values) == ProcessorConfig()


def test_the_feature_settings_come_from_the_options() -> None:
    cfg = ProcessorConfig().replace(mode="ppg", sampling_rate=55.0, min_beats=7, hrv_window_seconds=0.0)
    settings = cfg.features
    assert (settings.mode, settings.sampling_rate, settings.min_beats) == ("ppg", 55.0, 7)
    assert settings.flatline_seconds == cfg.mode_default("flatline_seconds")
    assert settings.frequency_domain  # no long HRV window: LF/HF on the window itself
    assert not ProcessorConfig().replace(hrv_window_seconds=300.0).features.frequency_domain

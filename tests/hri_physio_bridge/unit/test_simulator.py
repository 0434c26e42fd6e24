"""physio_simulator's logic: signal sources, segment splicing, pacing on a fake clock, options.

The node streaming over real LSL is tested in test_simulator_node.py."""

from __future__ import annotations

import itertools

import neurokit2 as nk
import numpy as np
import pytest

from hri_physio_bridge.config import ConfigError
from hri_physio_bridge.simulator import (
    SIGNALS,
    Block,
    HeartRateValues,
    Pacer,
    SimulatorConfig,
    make_source,
    neurokit_segment,
    run_paced,
    stream_spec,
)

NEUROKIT = [s for s in SIGNALS if s not in ("ramp", "hr")]


def take_all(src, sizes) -> tuple[np.ndarray, np.ndarray, list[Block]]:
    blocks = [src.take(n) for n in sizes]
    for prev, nxt in itertools.pairwise(blocks):
        assert nxt.first == prev.first + len(prev)  # consecutive, no gap or overlap
    return (np.concatenate([b.timestamps for b in blocks]),
            np.concatenate([b.values for b in blocks]), blocks)


def r_peak_intervals(ecg: np.ndarray, fs: int) -> np.ndarray:
    _, info = nk.ecg_peaks(ecg, sampling_rate=fs)  # ecgsyn at low noise needs no cleaning
    return np.diff(info["ECG_R_Peaks"]) / fs


# -- sources ------------------------------------------------------------------------------


@pytest.mark.parametrize("sig", SIGNALS)
def test_finite_source_length_rate_and_exact_timestamps(sig: str) -> None:
    cfg = SimulatorConfig(seconds=12, rate=100)
    src = make_source(sig, cfg, t0=50.0)
    rate = 1.0 if sig == "hr" else 100.0
    assert src.rate == rate and src.total == round(12 * rate)
    t, v, _ = take_all(src, [1, 37, 500, 10_000])
    n = round(12 * rate)
    assert len(t) == len(v) == n and src.done and src.sent == n
    np.testing.assert_array_equal(t, 50.0 + np.arange(n) / rate)
    assert np.all(np.isfinite(v))
    if sig in NEUROKIT:
        assert np.ptp(v) > 0.01  # a real waveform, not a constant
    assert len(src.take(10)) == 0  # a finished source stays finished


def test_ramp_is_an_exact_counter() -> None:
    src = make_source("ramp", SimulatorConfig(seconds=5, rate=130), t0=0.0)
    _, v, _ = take_all(src, [13] * 50)
    np.testing.assert_array_equal(v, np.arange(650, dtype=np.float64))


@pytest.mark.parametrize("sig", ["ramp", *NEUROKIT])
def test_continuous_source_keeps_index_and_timestamps_across_segments(sig: str) -> None:
    cfg = SimulatorConfig(seconds=0, rate=50, segment_seconds=20)
    assert cfg.continuous
    src = make_source(sig, cfg, t0=1.0)
    sizes = [7, 333, 1, 1200, 59, 1000, 400]  # 3000 samples = 60 s, three segments or more
    t, v, _ = take_all(src, sizes)
    assert src.total is None and not src.done and len(v) == sum(sizes)
    np.testing.assert_array_equal(t, 1.0 + np.arange(3000) / 50.0)
    assert np.all(np.isfinite(v))
    if sig == "ramp":
        np.testing.assert_array_equal(v, np.arange(3000))
    else:
        assert len(src._values.joints) >= 2  # the test really crossed segment joints


def test_same_seed_same_signal_regardless_of_block_sizes() -> None:
    cfg = SimulatorConfig(seconds=0, rate=50, segment_seconds=20, seed=7)
    _, a, _ = take_all(make_source("ecg", cfg), [3000])
    _, b, _ = take_all(make_source("ecg", cfg), [1] * 13 + [987, 2000])
    np.testing.assert_array_equal(a, b)
    _, c, _ = take_all(make_source("ecg", SimulatorConfig(seconds=0, rate=50, segment_seconds=20, seed=8)),
                       [3000])
    assert not np.allclose(a, c)


def test_ecg_rhythm_carries_on_across_segment_joints() -> None:
    """Splice points are chosen so no beat is doubled or skipped; the check itself is shown
    to catch the naive alternative (plain concatenation of the same segments)."""
    fs, bpm = 130, 70
    cfg = SimulatorConfig(seconds=0, rate=fs, bpm=bpm, segment_seconds=20, seed=42)
    src = make_source("ecg", cfg)
    _, ecg, _ = take_all(src, [65 * fs])
    joints = src._values.joints
    assert len(joints) >= 3
    nominal = 60.0 / bpm

    def regular(x: np.ndarray) -> bool:
        rr = r_peak_intervals(x, fs)
        return bool(np.all(np.abs(rr - nominal) < 0.15 * nominal))

    assert regular(ecg)
    naive = np.concatenate([neurokit_segment("ecg", cfg, 20 * fs, seed) for seed in (42, 43, 44)])
    assert not regular(naive)


@pytest.mark.parametrize("sig", NEUROKIT)
def test_segment_joints_have_no_step(sig: str) -> None:
    cfg = SimulatorConfig(seconds=0, rate=130, segment_seconds=20)
    src = make_source(sig, cfg)
    _, x, _ = take_all(src, [65 * 130])
    step = np.abs(np.diff(x))
    typical = np.percentile(step, 99)
    joints = [j for j in src._values.joints if j + 3 < len(x)]
    assert len(joints) >= 3
    for j in joints:
        assert step[j - 3: j + 3].max() <= typical, (sig, j)


def test_hr_stream_is_1hz_and_reports_the_ecg_rate() -> None:
    cfg = SimulatorConfig(seconds=40, rate=130, bpm=84)
    hr = make_source("hr", cfg, t0=10.0)
    t, v, _ = take_all(hr, [1, 1, 100])
    np.testing.assert_array_equal(t, 10.0 + np.arange(40))
    assert np.all(v == np.round(v))  # whole bpm, as a strap sends
    assert v[0] == v[1] == 84  # configured bpm until there are beats to average
    _, ecg, _ = take_all(make_source("ecg", cfg), [40 * 130])
    actual = 60.0 / np.mean(r_peak_intervals(ecg, 130))
    assert abs(actual - 84) < 3
    assert abs(np.mean(v[5:]) - actual) < 1.0
    assert np.all(np.abs(v[5:] - actual) <= 4)


def test_hr_is_derived_from_the_very_ecg_the_ecg_stream_sends() -> None:
    cfg = SimulatorConfig(seconds=0, rate=100, segment_seconds=20, seed=3)
    _, ecg, _ = take_all(make_source("ecg", cfg), [5000])
    np.testing.assert_array_equal(HeartRateValues(cfg).ecg.values(0, 5000), ecg)


# -- pacing on a fake clock ------------------------------------------------------------


class FakeClock:
    def __init__(self, now: float) -> None:
        self.now = now
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, dt: float) -> None:
        assert dt > 0
        self.sleeps.append(dt)
        self.now += dt


def test_pacer_sends_whole_chunks_when_their_last_sample_is_due() -> None:
    # Below NeuroKit2's minimum rate, which only the pacing here does not need: skip the model's checks.
    cfg = SimulatorConfig.model_construct(seconds=3, rate=10)
    start = 100.0
    sources = {"ramp": make_source("ramp", cfg, t0=start), "hr": make_source("hr", cfg, t0=start)}
    pacer = Pacer(sources, chunk=4, start=start)
    clock = FakeClock(start)
    sent: list[tuple[float, str, int, int]] = []

    def emit(key: str, block: Block) -> None:
        assert block.timestamps[-1] <= clock.now + 1e-9  # never a sample from the future
        sent.append((clock.now, key, block.first, len(block)))

    assert run_paced(pacer, clock, clock.sleep, emit, lambda: False, max_sleep=0.25) is True
    ramp = [(round(t - start, 6), first, n) for t, k, first, n in sent if k == "ramp"]
    expected = [(round((first + 3) / 10, 6), first, 4) for first in range(0, 28, 4)] + [(2.9, 28, 2)]
    assert ramp == expected  # 30 samples: seven chunks of 4, then the last 2 at sample 29's time
    hr = [(round(t - start, 6), first, n) for t, k, first, n in sent if k == "hr"]
    assert hr == [(0.0, 0, 1), (1.0, 1, 1), (2.0, 2, 1)]
    assert max(clock.sleeps) <= 0.25 and clock.now == pytest.approx(start + 2.9)


def test_pacer_catches_up_after_a_stall_without_losing_samples() -> None:
    src = make_source("ramp", SimulatorConfig(seconds=0, rate=100), t0=0.0)
    pacer = Pacer({"ramp": src}, chunk=10, start=0.0)
    assert pacer.due(0.085) == []  # sample 9 not measured yet
    first = pacer.due(0.09)
    assert [(k, b.first, len(b)) for k, b in first] == [("ramp", 0, 10)]
    late = pacer.due(1.0)  # the process stalled for ~0.9 s
    assert [len(b) for _, b in late] == [10] * 9  # samples 10..99, still one chunk per push
    values = np.concatenate([b.values for _, b in first + late])
    np.testing.assert_array_equal(values, np.arange(100))
    assert pacer.next_due() == pytest.approx(1.09)


def test_run_paced_stops_on_request() -> None:
    src = make_source("ramp", SimulatorConfig(seconds=0, rate=50), t0=0.0)
    clock = FakeClock(0.0)
    got: list[int] = []
    finished = run_paced(Pacer({"ramp": src}, 5, 0.0), clock, clock.sleep,
                         lambda _k, b: got.extend(b.values.astype(int)), lambda: clock.now >= 2.0)
    assert finished is False
    assert got == list(range(len(got))) and 95 <= len(got) <= 105


def test_pacer_rejects_empty_chunks() -> None:
    with pytest.raises(ValueError, match="chunk must be >= 1"):
        Pacer({}, 0, 0.0)


# -- options and naming --------------------------------------------------------------------


def test_defaults_and_stream_specs_look_like_a_polar_strap() -> None:
    opts = SimulatorConfig.from_mapping({})
    assert opts.signals == ["ecg", "hr"] and opts.rate == 130 and opts.chunk_samples == 13
    assert opts.seconds == 60 and opts.device_id == "SIM0001" and not opts.continuous
    ecg = stream_spec("ecg", opts, "DEV1")
    assert (ecg.name, ecg.type, ecg.nominal_rate, ecg.channel_count, ecg.dtype, ecg.source_id,
            ecg.channels) == ("PolarH10/DEV1/ECG", "ECG", 130, 1, "float64", "DEV1-ECG", ("ECG",))
    hr = stream_spec("hr", opts, "DEV1", prefix="t/x/")
    assert (hr.name, hr.nominal_rate) == ("t/x/PolarH10/DEV1/HR", 1.0)
    assert stream_spec("ppg", opts, "D").name == "PolarOH1/D/PPG"
    for sig, kind in (("eda", "EDA"), ("emg", "EMG"), ("rsp", "RSP"), ("ramp", "RAMP")):
        assert stream_spec(sig, opts, "D").name == f"NeuroKitSim/D/{kind}"


def test_options_from_yaml_style_mapping() -> None:
    opts = SimulatorConfig.from_mapping({"continuous": True, "signals": ["ramp", "ECG", "ramp"], "rate": 250,
                                         "device-id": "H10X", "chunk": 25, "scr": 2.0, "name_prefix": "/p/"})
    assert opts.continuous and opts.seconds == 0 and opts.signals == ["ramp", "ecg"] and opts.scr == 2
    assert opts.device_id == "H10X" and opts.chunk_samples == 25 and opts.name_prefix == "p"
    assert SimulatorConfig(seconds=0).continuous  # the two spellings of "until stopped" agree


@pytest.mark.parametrize(
    "values,option",
    [
        ({"rate": -5}, "rate"),
        ({"seconds": -1}, "seconds"),
        ({"signals": "ecg,pulse"}, "signals"),
        ({"signals": ""}, "signals"),
        ({"heart_rate": 70}, "heart_rate"),
        ({"bpm": "fast"}, "bpm"),
        ({"bpm": True}, "bpm"),
        ({"scr": 2.5}, "scr"),
        ({"bpm": 500}, "bpm"),
        ({"resp": 0}, "resp"),
        ({"chunk": -1}, "chunk"),
        ({"device_id": "a/b"}, "device_id"),
        ({"continuous": "maybe"}, "continuous"),
        ({"signals": "emg", "bnum": 70}, "bnum"),
        ({"rate": 5}, "rate"),
        ({"segment_seconds": 5}, "segment_seconds"),
    ],
)
def test_bad_options_are_refused_naming_the_option(values: dict, option: str) -> None:
    with pytest.raises(ConfigError) as err:
        SimulatorConfig.from_mapping(values)
    assert option in str(err.value) and "\n" not in str(err.value)


def test_ramp_only_may_run_slow() -> None:
    assert SimulatorConfig.from_mapping({"rate": 5, "signals": "ramp"}).rate == 5


def test_unknown_signal_source() -> None:
    with pytest.raises(ValueError, match="unknown signal 'ecgg'"):
        make_source("ecgg", SimulatorConfig())


# -- each seed flag changes the signal as NeuroKit2 documents it ------------------------------------
def _seg(signal_name: str, seconds: int = 60, rate: float = 250.0, **flags: float) -> np.ndarray:
    return neurokit_segment(signal_name, SimulatorConfig(rate=rate, **flags), int(seconds * rate), seed=7)


def test_noise_flag_scales_the_added_noise() -> None:
    clean = _seg("ecg", noise=0.0)
    added = [np.std(_seg("ecg", noise=level) - clean) for level in (0.01, 0.1, 0.5)]
    assert added[0] > 0
    np.testing.assert_allclose(np.array(added) / added[0], [1, 10, 50], rtol=0.05)  # proportional


def test_resp_flag_sets_the_breathing_rate() -> None:
    for rate in (10.0, 30.0):
        x = _seg("rsp", rate=50.0, resp=rate, noise=0.0)
        _, info = nk.rsp_peaks(nk.rsp_clean(x, sampling_rate=50), sampling_rate=50)
        assert len(info["RSP_Peaks"]) == pytest.approx(rate, abs=2)  # breaths in 60 s


def test_scr_and_drift_flags_shape_the_skin_conductance() -> None:
    none, many = _seg("eda", rate=50.0, scr=0, noise=0.0, drift=0.0), _seg("eda", rate=50.0, scr=6, noise=0.0,
                                                                            drift=0.0)
    assert np.ptp(none) < 0.05 * np.ptp(many)  # no responses: a flat tonic level
    rising = _seg("eda", rate=50.0, scr=0, noise=0.0, drift=0.5)
    assert rising[-50:].mean() - rising[:50].mean() > 10 * abs(none[-50:].mean() - none[:50].mean()) + 0.1


def test_bnum_and_bdur_flags_set_the_emg_bursts() -> None:
    def active_seconds(x: np.ndarray, rate: float = 250.0) -> float:
        envelope = np.convolve(np.abs(x), np.ones(50) / 50, mode="same")
        return float(np.sum(envelope > 0.25 * envelope.max()) / rate)

    assert np.std(_seg("emg", bnum=0, noise=0.01)) < 0.5 * np.std(_seg("emg", bnum=3, noise=0.01))
    short, long = active_seconds(_seg("emg", bnum=3, bdur=0.5)), active_seconds(_seg("emg", bnum=3, bdur=2.0))
    assert long > 2.5 * short

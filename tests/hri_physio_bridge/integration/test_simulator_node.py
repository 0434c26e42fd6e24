"""physio_simulator as a process: streams named like a Polar strap over real LSL, signals, options."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import numpy as np
import pylsl
import pytest

from helpers import NEUROKIT_START, NodeProcess, resolve_lsl

pytestmark = pytest.mark.lsl


# -- the CLI over real LSL -----------------------------------------------------------------

KINDS = {"ramp": "NeuroKitSim/DEV42/RAMP", "ecg": "PolarH10/DEV42/ECG", "hr": "PolarH10/DEV42/HR",
         "ppg": "PolarOH1/DEV42/PPG", "eda": "NeuroKitSim/DEV42/EDA", "emg": "NeuroKitSim/DEV42/EMG",
         "rsp": "NeuroKitSim/DEV42/RSP"}


def pull(inlet: pylsl.StreamInlet, expected: int, timeout: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    """Everything the inlet gets until ``expected`` samples are in (and any surplus)."""
    values: list[float] = []
    stamps: list[float] = []
    deadline = time.monotonic() + timeout
    while len(stamps) < expected and time.monotonic() < deadline:
        data, ts = inlet.pull_chunk(timeout=0.05, max_samples=10_000)
        values.extend(row[0] for row in data)
        stamps.extend(ts)
    data, ts = inlet.pull_chunk(timeout=0.0, max_samples=10_000)  # a surplus would be a bug
    values.extend(row[0] for row in data)
    stamps.extend(ts)
    return np.array(values), np.array(stamps)


def test_cli_streams_named_like_a_polar_strap_and_the_ramp_arrives_complete(lsl_name: str) -> None:
    with NodeProcess(
        "physio_simulator", "--seconds", "3", "--rate", "100", "--signals", ",".join(KINDS),
        "--device-id", "DEV42", "--name-prefix", lsl_name, "--chunk", "10", "--wait-for-consumers", "30",
    ) as sim:
        # It says so after loading NeuroKit2 and simulating every signal: on a busy machine (CI,
        # three test workers beside the session tests) that took more than 30 s once.
        sim.wait_for_output("streaming", timeout=NEUROKIT_START)
        found = resolve_lsl(pred=f"starts-with(name,'{lsl_name}/')", minimum=len(KINDS))
        by_name = {info.name(): info for info in found}
        assert sorted(by_name) == sorted(f"{lsl_name}/{kind}" for kind in KINDS.values()), sim.output
        inlets = {sig: pylsl.StreamInlet(by_name[f"{lsl_name}/{kind}"], max_buflen=60)
                  for sig, kind in KINDS.items()}
        for inlet in inlets.values():
            inlet.open_stream(10)
        infos = {sig: inlet.info(5) for sig, inlet in inlets.items()}
        got = {sig: pull(inlet, 3 if sig == "hr" else 300) for sig, inlet in inlets.items()}
        assert sim.wait(30) == 0, sim.output
    for sig, info in infos.items():
        kind = KINDS[sig].rsplit("/", 1)[1]
        assert info.type() == kind and info.channel_count() == 1
        assert info.channel_format() == pylsl.cf_double64
        assert info.nominal_srate() == (1.0 if sig == "hr" else 100.0)
        assert info.source_id() == f"DEV42-{kind}"
        assert info.desc().child("channels").child("channel").child_value("label") == kind
    ramp, stamps = got["ramp"]
    np.testing.assert_array_equal(ramp, np.arange(300))  # complete, in order, no repeats
    t0 = stamps[0]
    np.testing.assert_allclose(stamps, t0 + np.arange(300) / 100.0, rtol=0, atol=1e-9)
    assert abs(t0 - pylsl.local_clock()) < 30  # on this machine's LSL clock
    for sig in ("ecg", "ppg", "eda", "emg", "rsp"):
        values, ts = got[sig]
        assert len(values) == 300 and np.ptp(values) > 0, sig
        np.testing.assert_allclose(ts, stamps, rtol=0, atol=1e-9)  # one clock for all streams
    hr, hr_t = got["hr"]
    assert len(hr) == 3 and np.all((hr > 50) & (hr < 90))
    np.testing.assert_allclose(hr_t, t0 + np.arange(3), rtol=0, atol=1e-9)
    assert "done: sent ramp: 300, ecg: 300, hr: 3, ppg: 300" in sim.output


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_cli_stops_cleanly_on_a_signal_in_continuous_mode(lsl_name: str, sig: signal.Signals) -> None:
    with NodeProcess("physio_simulator", "--continuous", "--signals", "ramp,hr", "--rate", "50",
                     "--name-prefix", lsl_name) as sim:
        sim.wait_for_output("until stopped", timeout=NEUROKIT_START)  # after NeuroKit2, as above
        found = resolve_lsl(f"{lsl_name}/NeuroKitSim/SIM0001/RAMP")
        assert found, sim.output
        inlet = pylsl.StreamInlet(found[0])
        inlet.open_stream(10)
        sample, _ = inlet.pull_sample(timeout=10.0)
        assert sample is not None, "no samples before the stop"
        assert sim.stop(sig) == 0, sim.output
    assert f"{sig.name} received: stopping" in sim.output and "done: sent ramp: " in sim.output
    assert "Traceback" not in sim.output


@pytest.mark.parametrize(
    "args,conf,message",
    [
        (["--rate", "-5"], None, "rate"),
        (["--signals", "ecg,pulse"], None, "pulse"),
        (["--chunk", "-3"], None, "chunk"),
        (["--bpm", "fast"], None, "bpm"),
        (["--continuous", "--bnum", "70", "--signals", "emg"], None, "bnum"),
        (["--colour", "red"], None, "--colour"),
        ([], "bpm: [70\n", "is not valid YAML at line"),
        ([], "heart_rate: 70\n", "heart_rate"),
        ([], "- 1\n- 2\n", "must hold key: value pairs"),
        (["--ros-args", "-p", "bpm:=abc"], None, "bpm"),
        (["--ros-args", "-p", "seed:=1.5"], None, "seed"),
        (["--ros-args", "-p", "signals:=ecg,pulse"], None, "pulse"),
        (["--ros-args", "-p", "colour:=red"], None, "colour"),
        (["--ros-args", "--params-file", "/nonexistent/params.yaml"], None, "/nonexistent/params.yaml"),
    ],
)
def test_cli_bad_input_gives_one_clear_line_and_status_2(tmp_path: Path, args: list[str], conf: str | None,
                                                         message: str) -> None:
    if conf is not None:
        path = tmp_path / "sim.yaml"
        path.write_text(conf)
        args = [*args, "--conf", str(path)]
    with NodeProcess("physio_simulator", *args) as sim:
        assert sim.wait(30) == 2, sim.output
    lines = sim.output.strip().splitlines()
    assert "Traceback" not in sim.output and message in lines[-1], sim.output
    assert lines[-1].startswith("physio_simulator: error:") or "usage:" in lines[0], sim.output


def test_cli_broken_params_file_is_one_line(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("physio_simulator:\n  ros__parameters:\n    bpm: [70\n")
    with NodeProcess("physio_simulator", "--ros-args", "--params-file", str(params)) as sim:
        assert sim.wait(30) == 2, sim.output
    assert sim.output.strip().splitlines() == [sim.output.strip()] and str(params) in sim.output, sim.output
    params.write_text("physio_simulator:\n  ros__parameters:\n    bpm: 10\n")
    with NodeProcess("physio_simulator", "--ros-args", "--params-file", str(params)) as sim:
        assert sim.wait(30) == 2, sim.output
    assert "physio_simulator: error:" in sim.output and "bpm" in sim.output and "Traceback" not in sim.output


def test_cli_conf_file_sets_options_and_flags_win(tmp_path: Path, lsl_name: str) -> None:
    path = tmp_path / "sim.yaml"
    path.write_text(f"seconds: 1\nsignals: [ramp]\nrate: 80\nname_prefix: {lsl_name}\ndevice-id: CONF1\n")
    with NodeProcess("physio_simulator", "--conf", str(path), "--rate", "40") as sim:
        assert sim.wait(30) == 0, sim.output
    assert f"streaming {lsl_name}/NeuroKitSim/CONF1/RAMP (1 s, 40 Hz" in sim.output
    assert "done: sent ramp: 40" in sim.output

"""Whole chains of real nodes (subprocesses, real rclpy and pylsl):

* MIT-BIH 100 (CSV log, 130 Hz) -> physio_receiver -> neurokit_processor -> subscriber, as
  fast as possible: R-peaks scored against the reference annotations.
* physio_simulator (LSL) -> physio_receiver -> neurokit_processor -> subscriber, real time:
  outputs line up with the windows they describe.
"""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np
import pytest

from helpers import NEUROKIT_START, NodeProcess, wait_until
from helpers.processing import Outputs, match_beats

pytestmark = pytest.mark.ros
FS = 130


def test_mitdb_through_receiver_and_processor(mitdb, collector, lsl_name: str, tmp_path: Path) -> None:
    tag = lsl_name.split("/")[0]
    topic = f"/test/{tag}/mitdb/ecg"
    log = tmp_path / "mitdb_100_130hz.csv"
    np.savetxt(log, np.column_stack([mitdb.t, mitdb.x]), fmt="%.17g", delimiter=",", header="t,ecg",
               comments="")
    out = Outputs(collector, topic)
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}", "--window-seconds", "60",
                     "--hop-seconds", "5", "--quality-method", "none", "--wait-for-consumers", "30") as proc:
        # every output has a consumer
        wait_until(lambda: collector.node.count_subscribers(topic) > 0, NEUROKIT_START,
                   lambda: f"the processor's subscription:\n{proc.output}")
        with NodeProcess("physio_receiver", "--input", f"csv:{log}?rate=0", "--output", f"ros:{topic}",
                         "--output-frame", "1300", "--input-frame", "1300",
                         "--wait-for-consumers", "30") as rx:
            assert rx.wait(120) == 0, rx.output
        # 350 full windows (starts 0, 5, ..., 1745 s); the last 0.55 s comes with the final one.
        wait_until(lambda: len(out.windows()) >= 350, 240, lambda: f"350 windows, got {len(out.windows())}")
        assert proc.stop(signal.SIGINT) == 0, proc.output
        wait_until(lambda: len(out.windows()) >= 351, 20, "the final window")
    wins = out.windows()
    assert len(wins) == 351 and all(w["ok"] for w in wins)
    assert wins[-1]["window"]["final"] and wins[-1]["t"] == mitdb.t[-1]
    clean_t, _ = out.joined("clean")
    np.testing.assert_array_equal(clean_t, mitdb.t)  # every sample once, through both nodes
    peak_t, mask = out.joined("rpeaks")
    det = peak_t[mask == 1]
    tp = match_beats(mitdb.beats, det, 0.05)
    sensitivity, ppv = tp / mitdb.beats.shape[0], tp / det.shape[0]
    assert sensitivity >= 0.995 and ppv >= 0.995, (sensitivity, ppv)
    assert np.all(np.diff(det) > 0.25)  # no beat counted twice
    assert det.shape[0] == 2270  # as NeuroKit2 offline on the whole record: none lost between windows


@pytest.mark.lsl
def test_simulator_receiver_processor_chain(collector, lsl_name: str) -> None:
    tag = lsl_name.split("/")[0]
    topic = f"/test/{tag}/sim/ecg"
    out = Outputs(collector, topic)
    stream = f"{lsl_name}/PolarH10/SIM0001/ECG"
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}", "--window-seconds", "8",
                     "--hop-seconds", "4", "--min-window-seconds", "4", "--wait-for-consumers", "30") as proc:
        wait_until(lambda: collector.node.count_subscribers(topic) > 0, NEUROKIT_START,
                   lambda: f"the processor's subscription:\n{proc.output}")
        # The receiver waits for the simulator's stream as long as the simulator waits for it (a busy
        # machine starts either of them late).
        with NodeProcess("physio_receiver", "--input", f"lsl:{stream}", "--output", f"ros:{topic}",
                         "--output-frame", "13", "--wait-for-consumers", "30",
                         "--resolve-timeout", "60") as rx, NodeProcess(
            "physio_simulator", "--seconds", "22", "--signals", "ecg", "--bpm", "70",
            "--name-prefix", lsl_name, "--wait-for-consumers", "30",
        ) as sim:
            assert sim.wait(90) == 0, sim.output
            wait_until(lambda: len(out.windows()) >= 4, 30, lambda: f"windows:\n{rx.output}\n{proc.output}")
            assert rx.stop(signal.SIGINT) == 0, rx.output
        wait_until(lambda: len(out.windows()) >= 4, 10, "windows")
        assert proc.stop(signal.SIGINT) == 0, proc.output
    wins = out.windows()
    clean_t, _ = out.joined("clean")
    n = clean_t.shape[0]
    assert n == 22 * FS  # every simulated sample, once
    np.testing.assert_allclose(np.diff(clean_t), 1 / FS, rtol=1e-6)  # the simulator's LSL stamps
    ends = [w["window"]["t_end"] for w in wins]
    full = [w for w in wins if not w["window"]["final"]]
    assert len(full) == 4  # windows of 8 s every 4 s in 22 s: ending at 8, 12, 16, 20 s
    for k, w in enumerate(full):
        assert w["window"]["t_start"] == clean_t[k * 4 * FS]
        assert w["window"]["t_end"] == clean_t[k * 4 * FS + 8 * FS - 1]
    assert wins[-1]["window"]["final"] and ends[-1] == clean_t[-1]
    for name in ("hr", "sdnn", "rmssd", "quality"):
        stamps = [f.timestamps[0] for f in out.frames[name]]
        assert stamps == ends  # each scalar stamped with the end of the window it describes
    # HF comes from the long HRV window of beats already published: stamped with that window's end.
    assert [f.timestamps[0] for f in out.frames["hf"]] == [w["hrv_window"]["t_end"] for w in wins]
    hr = np.array([f.values[0, 0] for f in out.frames["hr"]])
    assert np.all(np.abs(hr - 70) < 5), hr
    assert all(np.isnan(f.values[0, 0]) for f in out.frames["hf"])  # 8 s windows: too short for HF
    assert all("shorter than" in w["nan"]["hf"] for w in wins)
    _, mask = out.joined("rpeaks")
    assert abs(mask.sum() - 22 * 70 / 60) <= 2

"""polar_streamer --replay as a process: a soak over hours of ECG, and real-time replays that lose nothing.

Counts come from the node's final status (what it pushed onto LSL), never from timing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from hri_physio_bridge.polar.synthetic import synthetic_h10, write_capture

pytestmark = pytest.mark.lsl

FRAME = 73  # samples of an H10 ECG notification


def replay(capture: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "hri_physio_bridge.nodes.polar_streamer", "--replay", str(capture),
         "--name-prefix", f"test{uuid.uuid4().hex[:8]}", *args],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
    )


def final_status(proc: subprocess.Popen[str], timeout: float) -> dict:
    """The node's exit status 0 and the JSON of its final status line."""
    try:
        out = proc.communicate(timeout=timeout)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    assert "Traceback" not in out, out
    line = next(line for line in out.splitlines() if "final status: " in line)
    return json.loads(line.split("final status: ", 1)[1])


def test_two_hour_replay_pushes_every_sample_with_no_false_gap(tmp_path: Path) -> None:
    """A generated capture of 2 h 10 min of H10 ECG (clock from 2019, +-20 ppm crystal, BLE jitter)."""
    syn = synthetic_h10(7800.0, heart_rate=False, ppm=20.0, jitter_ms=6.0, seed=23)
    capture = tmp_path / "two_hours.jsonl"
    notifications = write_capture(capture, syn)
    assert notifications * FRAME / 130 >= 2 * 3600
    status = final_status(replay(capture, "--replay-speed", "1000", "--status-period", "5"), timeout=900)
    ecg = status["streams"]["ecg"]
    assert list(status["streams"]) == ["ecg"]  # the streams the capture holds
    assert (ecg["frames"], ecg["samples"]) == (notifications, notifications * FRAME)
    counts = ("gaps", "missing_samples", "dropped_frames", "decode_errors", "out_of_order_samples",
              "clock_jumps")
    assert {k: ecg[k] for k in counts} == dict.fromkeys(counts, 0)
    assert status["unexpected_notifications"] == 0 and status["reconnects"] == 0


def test_real_time_replays_never_lose_a_notification(tmp_path: Path) -> None:
    """Six replays of six ECG frames at speed 1, side by side: every one pushes all 438 samples."""
    syn = synthetic_h10(6 * FRAME / 130 + 0.2, heart_rate=False, jitter_ms=9.0, seed=6)
    capture = tmp_path / "six_frames.jsonl"
    assert write_capture(capture, syn) == 6
    runs = [replay(capture) for _ in range(6)]
    pushed = [final_status(proc, timeout=120)["streams"]["ecg"]["samples"] for proc in runs]
    assert pushed == [6 * FRAME] * 6

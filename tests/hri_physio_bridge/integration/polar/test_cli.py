"""polar_streamer as a process: no Bluetooth here, configuration errors, --help, replaying a capture."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path

import pylsl
import pytest

from helpers import DATA, own_lines, resolve_lsl

CAPTURE = DATA / "polar" / "synthetic_h10.jsonl"
HAS_SYSTEM_BUS = (
    Path("/run/dbus/system_bus_socket").exists() or Path("/var/run/dbus/system_bus_socket").exists()
)


def streamer(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "hri_physio_bridge.nodes.polar_streamer", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ),
    )


@pytest.mark.skipif(
    HAS_SYSTEM_BUS, reason="this machine has a system D-Bus: the no-Bluetooth path needs a machine without"
)
@pytest.mark.parametrize("args", [["--scan"], ["--device", "A1B2C3D4"]])
def test_no_bluetooth_is_one_line_and_status_2(args: list[str]) -> None:
    """The real bleak path: no BlueZ / D-Bus / adapter on this machine."""
    done = streamer(*args, "--scan-timeout", "2")
    assert done.returncode == 2, done.stderr
    lines = own_lines(done.stderr)
    assert len(lines) == 1 and lines[0].startswith("polar_streamer: error: no Bluetooth"), done.stderr
    assert "Traceback" not in done.stderr + done.stdout


@pytest.mark.parametrize(
    "args, option",
    [
        (["--device", "X", "--acc-rate", "7"], "acc_rate"),
        (["--device", "X", "--acc-range", "3"], "acc_range"),
        (["--device", "X", "--streams", "ecg,foo"], "streams"),
        (["--device", "X", "--ros-args", "-p", "ppg_rate:=60"], "ppg_rate"),
        (["--device", "X", "--backoff-initial", "40"], "backoff_initial"),
        (["--device", "X", "--sdk-mode", "--streams", "ppg,hr"], "sdk_mode"),
        (["--device", "X", "--stall-timeout", "0"], "stall_timeout"),
        (["--device", "X", "--start-timeout", "-1"], "start_timeout"),
        (["--replay", "x.jsonl", "--replay-speed", "2000"], "replay_speed"),
        ([], "device"),
        (["--replay", "/nonexistent/capture.jsonl"], "does not exist"),
    ],
)
def test_configuration_errors(args: list[str], option: str) -> None:
    done = streamer(*args)
    assert done.returncode == 2
    lines = own_lines(done.stderr)
    assert len(lines) == 1 and option in lines[0], done.stderr


@pytest.mark.parametrize(
    "case, args, message",
    [
        ("other device", ["--device", "Polar OH1"], "'Polar OH1' is not the device of capture"),
        ("bad control point", [], "c.jsonl:5: control point"),
        ("header only", [], "holds no notification to replay"),
    ],
)
def test_replay_input_errors(tmp_path: Path, case: str, args: list[str], message: str) -> None:
    """A capture the replay cannot play as asked: one line naming it, status 2, never a wait or a trace."""
    lines = CAPTURE.read_text().splitlines()
    if case == "header only":
        lines = lines[:1]
    elif case == "bad control point":
        lines[4] = json.dumps({"t": 5000.03, "op": "notify", "char": "pmd_cp", "hex": "ff00"})
    capture = tmp_path / "c.jsonl"
    capture.write_text("\n".join(lines) + "\n")
    done = streamer("--replay", str(capture), *args)
    assert done.returncode == 2, done.stderr
    own = own_lines(done.stderr)
    assert len(own) == 1 and message in own[0], done.stderr
    assert "Traceback" not in done.stderr + done.stdout


def test_capture_never_overwrites(tmp_path: Path) -> None:
    existing = tmp_path / "taken.jsonl"
    existing.write_text("keep me\n")
    done = streamer("--device", "A1B2C3D4", "--capture", str(existing))
    assert (
        done.returncode == 2
        and "exists already" in done.stderr
        and len(own_lines(done.stderr)) == 1
    )
    assert existing.read_text() == "keep me\n"
    done = streamer("--replay", str(CAPTURE), "--capture", str(tmp_path / "new.jsonl"))
    assert done.returncode == 2 and "cannot be used together" in done.stderr


def test_help_lists_the_devices_valid_values() -> None:
    done = streamer("--help")
    assert done.returncode == 0
    text = " ".join(done.stdout.split())
    for needle in (
        "--scan",
        "--device",
        "H10: ECG 130 Hz; ACC 25, 50, 100, 200 Hz at 2, 4, 8 G",
        "Verity Sense: PPG 55 Hz",
        "--sdk-mode",
        "--stall-timeout",
        "--start-timeout",
        "--capture",
        "--replay",
    ):
        assert needle in text


def test_replay_a_capture_onto_lsl(tmp_path: Path) -> None:
    """The node end to end: a 3 s piece of the synthetic capture replayed onto LSL; exits by itself."""
    lines = CAPTURE.read_text().splitlines()
    short = [line for line in lines if "format" in line or json.loads(line).get("t", 0) < 5003.1]
    piece = tmp_path / "piece.jsonl"
    piece.write_text("\n".join(short) + "\n")
    prefix = f"test{uuid.uuid4().hex[:8]}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "hri_physio_bridge.nodes.polar_streamer",
            "--replay",
            str(piece),
            "--name-prefix",
            prefix,
            "--streams",
            "ecg,hr",
            "--replay-speed",  # 3 s of capture played over 12 s: time for a busy machine to resolve it
            "0.25",
            "--status-period",
            "0.5",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ),
    )
    try:
        found = resolve_lsl(f"{prefix}/PolarH10/0A1B2C3D/ECG")
        assert found, "the replayed ECG stream did not appear"
        inlet = pylsl.StreamInlet(found[0])
        samples, stamps = [], []
        while proc.poll() is None:
            chunk, times = inlet.pull_chunk(timeout=0.2)
            samples += chunk
            stamps += times
        out = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    assert samples and {row[0] for row in samples} <= {104, 88, 70, 61, 50, 38, 22, 4}
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert "Traceback" not in out


def test_sigterm_stops_cleanly_mid_stream() -> None:
    """Stop while streaming (a replay of the full 10 s capture): the stop path runs, exit status 0."""
    prefix = f"test{uuid.uuid4().hex[:8]}"
    command = [
        sys.executable,
        "-m",
        "hri_physio_bridge.nodes.polar_streamer",
        "--replay",
        str(CAPTURE),
        "--replay-speed",  # 10 s of capture over 40 s: still streaming when a busy machine has resolved it
        "0.25",
        "--name-prefix",
        prefix,
    ]
    proc = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ)
    )
    try:
        assert resolve_lsl(f"{prefix}/PolarH10/0A1B2C3D/ECG"), "no stream"
        proc.send_signal(signal.SIGTERM)
        out = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    assert "SIGTERM received" in out and "Traceback" not in out

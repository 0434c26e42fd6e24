"""hri_physio_session: the closed loop as a researcher starts it, on a shortened routine.

Real processes throughout (participant on LSL, receivers, processor, coach, controller, mock
robot, recorder); the bag it writes is the evidence of what happened.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import NodeProcess

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / "bin"
PACKAGED = Path(__file__).resolve().parents[2] / "src" / "hri_physio_coach" / "config"


@pytest.fixture
def short_session(tmp_path: Path, session_tag: str) -> list[str]:
    """A 4.5-minute routine (1 min calibration, warm-up, conditioning, cool-down) and its options."""
    routine = yaml.safe_load((PACKAGED / "exercise_routine.yaml").read_text())
    keep = {"calibration": (0, None), "warm_up": (0, 60), "conditioning": (1, 90), "cool_down": (0, 60)}
    for phase in routine["phases"]:
        index, seconds = keep[phase["kind"]]
        phase["activities"] = [phase["activities"][index]]  # marching, lateral knees, step-up
        if seconds is not None:
            phase["activities"][0]["duration"] = seconds
    (tmp_path / "routine.yaml").write_text(yaml.safe_dump(routine))
    (tmp_path / "coach.yaml").write_text("calib_time: 60\n")
    return ["--routine", str(tmp_path / "routine.yaml"), "--conf", str(tmp_path / "coach.yaml"),
            "--bag-dir", str(tmp_path / "bags"), "--device-id", f"SIM{session_tag}", "--quiet-nodes",
            "--speed", "20"]


def read_bag(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


def events(msgs: list) -> list[dict]:
    return [json.loads(m.data) for m in msgs]


def test_closed_loop_session_runs_to_its_end_and_records_everything(short_session: list[str]) -> None:
    with NodeProcess("hri_physio_session", *short_session) as session:
        code = session.wait(240)
    out = session.output
    assert code == 0, out
    assert "[session] system ready" in out and "Traceback" not in out
    assert re.search(r"\[session\] done: 4\.\d min of session", out), out
    bag = Path(re.search(r"recorded to (\S+)", out).group(1))
    assert (bag / "metadata.yaml").is_file()
    msgs = read_bag(bag)

    coach = events(msgs["/coach/events"])
    kinds = [e["event"] for e in coach]
    assert kinds.index("session_start") < kinds.index("zone") < kinds.index("session_end")
    start = next(e["t"] for e in coach if e["event"] == "session_start")
    end = next(e["t"] for e in coach if e["event"] == "session_end")
    assert end - start == pytest.approx(60 + 60 + 90 + 60, abs=1.0)
    assert sum(k == "rule_update" for k in kinds) >= 5  # every 30 s of exercise

    # The robot did what the coach asked: the gestures of the routine, at the mock.
    robot = events(msgs["/qt_robot/mock/events"])
    gestures = [e["name"] for e in robot if e.get("event") == "gesture_started"]
    distinct = [g for i, g in enumerate(gestures) if i == 0 or g != gestures[i - 1]]
    assert distinct == ["base", "marching", "lateral", "step_up"], gestures

    # The participant followed the robot: exercise raised the (true, model) heart rate ...
    model = [json.loads(m.data) for m in msgs["/participant/state"]]
    seated = [m["hr_model"] for m in model if start <= m["t"] < start + 60]
    moving = [m["hr_model"] for m in model if start + 150 <= m["t"] < start + 210]
    assert np.mean(moving) > np.mean(seated) + 15, (np.mean(seated), np.mean(moving))

    # ... and every strap HR sample reached ROS 2 once, in order, one per second of sim time.
    from hri_physio_bridge.ros_frames import msg_to_frame

    hr_t = np.concatenate([msg_to_frame(m).timestamps for m in msgs["/physio/polar_h10/hr"]])
    assert np.all(np.diff(hr_t) > 0)
    assert len(hr_t) >= (end - start)
    np.testing.assert_allclose(np.diff(hr_t), 1.0, atol=0.05)
    # The receivers waited for all their listeners: the bag holds every sample each published,
    # from the first (their last status, published after their input stopped, says how many).
    ecg_n = sum(msg_to_frame(m).num_samples for m in msgs["/physio/polar_h10/ecg"])
    for node, recorded in (("hr_receiver", len(hr_t)), ("ecg_receiver", ecg_n)):
        final = events(msgs[f"/{node}/status"])[-1]
        assert final["published_samples"] == recorded, (node, final)
        assert final["received_samples"] == recorded and final["gaps"] == 0, (node, final)

    # The processor turned the ECG into features along the way.
    assert len(msgs["/physio/polar_h10/ecg/hr"]) >= 10


def test_coach_can_adapt_on_the_processors_heart_rate(short_session: list[str]) -> None:
    with NodeProcess("hri_physio_session", *short_session, "--hr-source", "ecg", "--no-record") as session:
        code = session.wait(240)
    assert code == 0, session.output
    updates = int(re.search(r"adaptations in (\d+) rule updates", session.output).group(1))
    starved = re.search(r"(\d+) rule update\(s\) gated: too few valid HR samples", session.output)
    assert updates >= 5 and (starved is None or int(starved.group(1)) <= 2), session.output
    # The summary counts HR samples from the coach's input, here the processor's 5 s windows.
    samples = int(re.search(r"on the coach's input during the session: (\d+)", session.output).group(1))
    assert 270 / 5 - 5 <= samples <= 270 / 5 + 2, session.output


def test_sigint_stops_every_node_and_closes_the_bag(short_session: list[str]) -> None:
    with NodeProcess("hri_physio_session", *short_session, "--speed", "1") as session:
        session.wait_for_output("[session] system ready", timeout=90)
        session.wait_for_output("[session] 00:0", timeout=30)  # the first progress line, 2 s later
        code = session.stop(signal.SIGINT, timeout=60)
    out = session.output
    assert code == 0, out
    assert "SIGINT: stopping the session" in out and "Traceback" not in out
    stopped = r"\[session\] stopped before its end: 0\.\d min of session in \d+ s wall \(1x\)"
    assert re.search(stopped, out), out
    bag = Path(re.search(r"recorded to (\S+)", out).group(1))
    assert (bag / "metadata.yaml").is_file()
    coach = events(read_bag(bag)["/coach/events"])
    assert coach[0]["event"] == "session_start" and "session_end" not in [e["event"] for e in coach]


@pytest.mark.parametrize("args,message", [
    (["--speed", "0"], "--speed must be > 0"),
    (["--age", "150"], "--age must be in (0, 120]"),
    (["--conf", "/nonexistent/coach.yaml"], "--conf /nonexistent/coach.yaml does not exist"),
    (["--hr-source", "ecg", "--no-ecg"], "--hr-source ecg needs the ECG path"),
])
def test_bad_options_are_one_clear_line(args: list[str], message: str) -> None:
    c = subprocess.run([str(BIN / "hri_physio_session"), *args], capture_output=True, text=True, timeout=30,
                       env=dict(os.environ), stdin=subprocess.DEVNULL)
    assert c.returncode == 2, (c.stdout, c.stderr)
    assert c.stderr.strip().splitlines() == [f"hri_physio_session: error: {message}"] or \
        message in c.stderr.strip().splitlines()[-1]
    assert "Traceback" not in c.stderr

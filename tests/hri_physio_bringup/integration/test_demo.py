"""scripts/demo end to end: the whole 23-minute routine at the default 30x, as a new user runs it.

Not a terminal here (the output goes to a file), so the console is plain: a few lines per minute
of session at most. Everything else is in the session folder, checked against the bag.
"""

from __future__ import annotations

import itertools
import json
import re
import subprocess
from pathlib import Path
from typing import TypeAlias

import numpy as np
import pytest
import yaml

from helpers import ROOT, run_to_end, session_env
from helpers.session_bags import failed_nodes_logs

pytestmark = [pytest.mark.ros, pytest.mark.lsl, pytest.mark.session]

NODES = ("physio_recorder", "mock_qt_robot", "qt_controller", "audio_streamer", "video_streamer",
         "simulated_participant", "hr_receiver",
         "ecg_receiver", "neurokit_processor", "qt_physio_coach")
Run: TypeAlias = subprocess.CompletedProcess[str]
#: The gestures of the thesis routine, in order (calibration's base gesture first).
GESTURES = ["base", "marching", "step_up", "marching", "lateral", "marching", "arms_forward", "marching",
            "lateral", "marching", "step_up", "marching"]


def read_bag(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory, session_tag: str) -> tuple[Run, Path]:
    out = tmp_path_factory.mktemp("demo")
    command = ["bash", str(ROOT / "scripts" / "demo"), "--out", str(out / "sessions"), "--device-id",
               f"SIM{session_tag}"]
    run = run_to_end(command, timeout=280, cwd=out, env=session_env())
    folders = re.findall(r"^\[session\] session folder: (\S+)$", run.stdout, re.M)
    assert len(folders) == 1, run.stdout
    return run, out / folders[0]


def test_the_demo_runs_to_its_end_calmly(demo: tuple[Run, Path]) -> None:
    run, folder = demo
    assert run.returncode == 0, failed_nodes_logs(run.stdout, folder.parents[1])
    lines = run.stdout.splitlines()
    assert len(lines) < 150, run.stdout
    assert "Traceback" not in run.stdout
    assert lines[-1] == f"[session] session folder: {folder.relative_to(folder.parents[1])}"
    assert re.search(r"^\[session\] done: 23\.0 min of session", run.stdout, re.M), run.stdout


def test_the_session_folder_holds_everything(demo: tuple[Run, Path]) -> None:
    run, folder = demo
    assert (folder / "bag" / "metadata.yaml").is_file()
    for node in NODES:
        assert (folder / "logs" / f"{node}.log").stat().st_size > 0, node
        conf = yaml.safe_load((folder / "configs" / f"{node}.yaml").read_text())
        assert len(conf) == 1 and "ros__parameters" in next(iter(conf.values())), node
    summary = json.loads((folder / "summary.json").read_text())
    assert (summary["outcome"], summary["exit_status"], summary["bag"]) == ("finished", 0, "bag"), \
        failed_nodes_logs(run.stdout, folder.parents[1])
    assert {name: n["exit_status"] for name, n in summary["nodes"].items()} == dict.fromkeys(NODES, 0)
    conf = str(folder / "configs" / "hr_receiver.yaml")
    assert summary["nodes"]["hr_receiver"]["argv"][:2] == ["--conf", conf]
    # The music the coach will ask for was prepared before the session: six beats and the relaxing pad.
    assert "prepared 7 of 7 preloaded tracks" in (folder / "logs" / "audio_streamer.log").read_text()
    report = json.loads((folder / "report.json").read_text())
    assert set(report["in_zone_fraction"]) == {"warm_up", "conditioning", "cool_down"}
    assert (folder / "report.html").stat().st_size > 0 and (folder / "hr_session.png").is_file()
    # The processor's 300 s HRV window gives LF, HF and LF/HF over a whole session; the report plots them.
    hrv = report["hrv"]
    for feature in ("lf", "hf", "lfhf"):
        assert hrv[f"/physio/polar_h10/ecg/{feature}"]["finite"] > 0, hrv
    assert (folder / "hrv.png").is_file()


def _gesture_repeat_lag(coach: list[dict], robot: list[dict]) -> tuple[float, float]:
    """(The coach's largest lag in repeating a gesture: a repeat's time less when it was due, 0 at
    least; the longest gesture at the slowest speed commanded), in sim seconds, from the bag's events."""
    from qt_controller.commands import SetGesture, parse_command

    length = {e["name"]: e["recorded_duration"] for e in robot if e.get("event") == "gesture_started"}
    commands = [(e, parse_command(e["command"])) for e in coach if e["event"] == "command"]
    gestures = [(e, c) for e, c in commands if isinstance(c, SetGesture)]
    lag = 0.0
    for (sent, gesture), (repeat, _) in itertools.pairwise(gestures):
        if repeat["why"] == "gesture repeat":
            lag = max(lag, repeat["t"] - (sent["t"] + length[gesture.name] / gesture.speed))
    return lag, max(length.values()) / min(g.speed for _, g in gestures)


def test_the_bag_holds_the_whole_session_with_no_sample_lost(demo: tuple[Run, Path],
                                                             session_tag: str) -> None:
    from hri_physio_bridge.ros_frames import msg_to_frame

    _, folder = demo
    msgs = read_bag(folder / "bag")
    coach = [json.loads(m.data) for m in msgs["/coach/events"]]
    kinds = [e["event"] for e in coach]
    start = next(e["t"] for e in coach if e["event"] == "session_start")
    end = next(e["t"] for e in coach if e["event"] == "session_end")
    assert end - start == pytest.approx(1380.0, abs=1.0)
    assert kinds.count("rule_update") == 39

    robot = [json.loads(m.data) for m in msgs["/qt_robot/mock/events"]]
    gestures = [e["name"] for e in robot if e.get("event") == "gesture_started"]
    performed = [g for i, g in enumerate(gestures) if i == 0 or g != gestures[i - 1]]
    # The demo's predictive policy may run another of the routine's activities in a slot: the robot
    # performs exactly the gestures the coach commanded, in order, starting with the thesis's first two.
    commanded = [e["command"].split()[2] for e in coach
                 if e["event"] == "command" and e["command"].startswith("set gesture ")]
    assert performed == [g for i, g in enumerate(commanded) if i == 0 or g != commanded[i - 1]]
    assert performed[:2] == GESTURES[:2] and set(performed) <= set(GESTURES)
    # The robot leads each exercise activity for its whole length: its gesture starts again and again
    # (gestures last 3-4.5 s; the exact cadence is tested on a fake clock in tests/coach). The coach
    # repeats a gesture once it has played for its length on the coach's clock; at 30x on a loaded
    # machine a starved coach process repeats late, by as much as its clock jumped meanwhile (0.4 s of
    # wall time is 12 s of sim time). That lag is in the bag: each repeat's time less when it was due.
    activities = [e for e in coach if e["event"] == "activity" and e.get("gesture")]
    ends = [e["t"] for e in activities[1:]] + [end]
    starts = [e["t"] for e in robot if e.get("event") == "gesture_started"]
    lag, longest = _gesture_repeat_lag(coach, robot)
    for activity, activity_end in zip(activities, ends, strict=True):
        inside = [t for t in starts if activity["t"] <= t < activity_end]
        assert len(inside) >= (activity_end - activity["t"]) / 10.0, (activity, len(inside))
        # the last start is one gesture, the coach's largest lag and the robot's reaction from the end
        # (12 s would do on an idle machine)
        allowed = max(12.0, longest + lag + 2.0)
        last = activity_end - max(inside)
        assert last < allowed, (activity, f"last start {last:.1f} s before the end; allowed {allowed:.1f} s")

    # The participant followed the robot: exercise raised the (true, model) heart rate.
    model = [json.loads(m.data) for m in msgs["/participant/state"]]
    seated = [m["hr_model"] for m in model if start <= m["t"] < start + 180]
    moving = [m["hr_model"] for m in model if start + 480 <= m["t"] < start + 1080]
    assert np.mean(moving) > np.mean(seated) + 20, (np.mean(seated), np.mean(moving))

    # Every strap HR sample reached ROS 2 once, in order, one per second of sim time ...
    hr_t = np.concatenate([msg_to_frame(m).timestamps for m in msgs["/physio/polar_h10/hr"]])
    assert np.all(np.diff(hr_t) > 0) and len(hr_t) >= end - start
    np.testing.assert_allclose(np.diff(hr_t), 1.0, atol=0.05)
    # ... and each receiver's last status (after its input stopped) says received = published =
    # recorded: nothing lost between the strap and the bag.
    ecg_n = sum(msg_to_frame(m).num_samples for m in msgs["/physio/polar_h10/ecg"])
    for node, recorded in (("hr_receiver", len(hr_t)), ("ecg_receiver", ecg_n)):
        final = json.loads(msgs[f"/{node}/status"][-1].data)
        assert final["published_samples"] == recorded, (node, final)
        assert final["received_samples"] == recorded and final["gaps"] == 0, (node, final)
    assert len(msgs["/physio/polar_h10/ecg/hr"]) >= 10  # the processor turned the ECG into features

    # summary.json says what the bag holds.
    counts = json.loads((folder / "summary.json").read_text())["session"]
    assert counts["robot_actions"] == len(robot)
    assert counts["rule_updates"] == kinds.count("rule_update")
    updates = [e for e in coach if e["event"] == "rule_update"]
    assert counts["adaptations"] == sum(bool(e["decision"]["changed"]) for e in updates)
    assert abs(counts["hr_samples"] - (end - start)) <= 3
    assert counts["receivers"]["hr_receiver"]["published_samples"] == len(hr_t)
    # The configuration kept is the one that ran.
    participant = yaml.safe_load((folder / "configs" / "simulated_participant.yaml").read_text())
    assert participant["simulated_participant"]["ros__parameters"]["device_id"] == f"SIM{session_tag}"

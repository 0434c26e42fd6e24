"""hri_physio_session: the closed loop as a researcher starts it, on a shortened routine.

Real processes throughout (participant on LSL, receivers, processor, coach, controller, mock
robot, recorder). What a session leaves is checked in its folder: summary.json and the bag.
The whole 23-minute routine runs in tests/session/test_session_demo.py.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from helpers import NodeProcess, own_lines, session_env, wait_until
from helpers.foxglove_ws import check_against_schema, watch
from helpers.routines import FOUR_AND_A_HALF_MINUTES, short_routine
from helpers.session_bags import failed_nodes_logs
from hri_physio_bridge import topics

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / "bin"
FOLDER_LINE = re.compile(r"^\[session\] session folder: (\S+)$", re.M)


@pytest.fixture
def short_session(tmp_path: Path, session_tag: str) -> list[str]:
    """A 4.5-minute routine (1 min calibration, warm-up, conditioning, cool-down) and its options."""
    return [*short_routine(tmp_path, FOUR_AND_A_HALF_MINUTES),
            "--out", str(tmp_path / "sessions"), "--device-id", f"SIM{session_tag}", "--speed", "20"]


def run_session(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "hri_physio_session"), *args], capture_output=True, text=True,
                          timeout=60, env=session_env() if env is None else env, stdin=subprocess.DEVNULL)


def session_folder(output: str) -> Path:
    found = FOLDER_LINE.findall(output)
    assert len(found) == 1, output
    return Path(found[0])


def read_bag(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


@pytest.mark.session
def test_coach_can_adapt_on_the_processors_heart_rate(short_session: list[str], tmp_path: Path) -> None:
    # 10x: the processor's NeuroKit windows (one per 5 s of ECG) keep up on a loaded machine.
    with NodeProcess("hri_physio_session", *short_session, "--hr-source", "ecg", "--no-record",
                     "--speed", "10", env=session_env()) as session:
        code = session.wait(240)
    assert code == 0, failed_nodes_logs(session.output)
    folder = session_folder(session.output)
    assert not (folder / "bag").exists() and not (folder / "report.json").exists()  # nothing recorded
    summary = json.loads((folder / "summary.json").read_text())
    counts = summary["session"]
    assert summary["outcome"] == "finished" and summary["exit_status"] == 0
    starved = counts["gated"].get("too_few_samples", 0)
    assert counts["rule_updates"] >= 5 and starved <= 2, counts
    # The coach's input is the processor's HR: one value per 5 s window of ECG. Counted by arrival
    # between session start and end, so a processor that lags (a loaded machine) may deliver windows
    # of ECG from before the start inside the session: only the lower bound holds for any load.
    assert counts["hr_samples"] >= 270 / 5 - 5, counts
    coach = yaml.safe_load((folder / "configs" / "qt_physio_coach.yaml").read_text())["qt_physio_coach"]
    assert coach["ros__parameters"]["hr_topic"] == "/physio/polar_h10/ecg/hr"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.session
def test_sigint_stops_every_node_and_leaves_a_bag_a_summary_and_a_report(short_session: list[str]) -> None:
    """Ctrl-C mid-session; meanwhile a second session told to use the same ROS domain is refused, and a
    Foxglove client watches the heart rate live (--live)."""
    port = free_port()
    with NodeProcess("hri_physio_session", *short_session, "--speed", "6", "--no-ecg",
                     "--live", f"127.0.0.1:{port}", env=session_env()) as session:
        session.wait_for_output("[session] system ready", timeout=120)
        assert f"[session] live view on ws://127.0.0.1:{port} (this host only)" in session.output
        live = watch(f"ws://127.0.0.1:{port}", {topics.POLAR_H10_HR: 3, topics.COACH_STATE: 1}, timeout=120)
        schema = json.loads(live.channels[topics.POLAR_H10_HR]["schema"])
        for _log_time, payload in live.messages[topics.POLAR_H10_HR]:
            message = json.loads(payload)
            check_against_schema(message, schema)
            _t, bpm = message["data"]
            assert bpm is None or 40 < bpm < 200, message
        # The coach's state (latched: it comes at once; its phase is None until the routine starts).
        state = json.loads(json.loads(live.messages[topics.COACH_STATE][0][1])["data"])
        assert {"phase", "zone"} <= set(state), state
        first = json.loads((session_folder_of_running(session.output) / "summary.json").read_text())
        # A domain of its own: not the one this test process holds.
        assert first["outcome"] == "running" and first["ros_domain"] != int(os.environ["ROS_DOMAIN_ID"])
        second = run_session(*short_session, env=session_env(ROS_DOMAIN_ID=str(first["ros_domain"])))
        assert second.returncode == 1, (second.stdout, second.stderr)
        lines = own_lines(second.stderr)
        line = lines[0]
        assert len(lines) == 1 and line.startswith("hri_physio_session: error: ROS domain "), line
        assert f"pid {session.proc.pid}" in line and first["folder"] in line
        assert "Traceback" not in second.stdout + second.stderr
        # Stop mid-session once the coach has set the zone (at calibration's end, a minute into the
        # 04:30): its state, latched, read through the live view. (The launcher's "01:00" line can
        # come before the coach has handled that minute's end.)
        wait_until(lambda: coach_state(f"ws://127.0.0.1:{port}")["zone"] is not None, 120,
                   lambda: f"the coach's zone\n{session.output}", period=0.5)
        code = session.stop(signal.SIGINT, timeout=120)
    out = session.output
    assert code == 0, failed_nodes_logs(out)
    assert "SIGINT: stopping the session" in out and "Traceback" not in out
    assert re.search(r"\[session\] stopped before its end: [0-3]\.\d min of session", out), out
    folder = session_folder(out)
    assert len(list(folder.parent.iterdir())) == 1  # the refused session made no folder
    summary = json.loads((folder / "summary.json").read_text())
    assert (summary["outcome"], summary["stopped_by"], summary["exit_status"]) == ("stopped", "SIGINT", 0)
    assert all(node["exit_status"] == 0 for node in summary["nodes"].values()), summary["nodes"]
    msgs = read_bag(folder / "bag")
    coach = [json.loads(m.data) for m in msgs["/coach/events"]]
    kinds = [e["event"] for e in coach]
    assert kinds[0] == "session_start" and "session_end" not in kinds and "session_stopped" in kinds
    assert summary["session"]["rule_updates"] == kinds.count("rule_update")
    # The streamers played what the coach asked for, on the session's clock, and the bag shows it.
    audio = [json.loads(m.data) for m in msgs["/audio_streamer/status"]]
    assert any(a["state"] == "playing" and a["source"] == "relaxing" and a["sink"] == "null" for a in audio)
    video = [json.loads(m.data) for m in msgs["/video_streamer/status"]]
    assert any(v["state"] == "playing" and v["display"] == "offscreen" for v in video)
    previews = msgs["/video_streamer/preview"]
    assert previews and previews[0].format.lower().startswith("jp")
    mock = [json.loads(m.data) for m in msgs["/qt_robot/mock/events"]]
    assert not [e for e in mock if e["event"] in ("audio", "video")]  # no longer mirrored by the mock
    for node in ("audio_streamer", "video_streamer"):
        assert (folder / "configs" / f"{node}.yaml").is_file() and summary["nodes"][node]["exit_status"] == 0
    report = json.loads((folder / "report.json").read_text())  # the report of what ran
    zone = next(e for e in coach if e["event"] == "zone")
    assert report["hr_rest"] == pytest.approx(zone["hr_rest"], abs=0.01)


def test_ctrl_c_during_start_up_stops_the_session_before_it_began(short_session: list[str]) -> None:
    """The researcher's stop while the nodes are still starting (a wrong participant id, say) is not a
    failure: exit 0, outcome "not started", every node stopped, no report of a session that never
    began. A node stopped before it had a signal handler (SIGINT ended it: -2; inside the
    interpreter's own start: 1) is not a failed node, and its KeyboardInterrupt is not a crash."""
    # At 1x on the processor's heart rate the system cannot be ready before its first 60-s window.
    session = NodeProcess("hri_physio_session", *short_session, "--speed", "1", "--hr-source", "ecg",
                          env=session_env())
    try:
        session.wait_for_output("[session] folder ", timeout=60)
        coach_log = session_folder_of_running(session.output) / "logs" / "qt_physio_coach.log"
        wait_until(lambda: coach_log.exists() or session.proc.poll() is not None, 60,
                   lambda: f"the coach's start\n{session.output}", period=0.1)
        code = session.stop(signal.SIGINT, timeout=120)
    finally:
        session.stop(signal.SIGKILL)
    out = session.output
    assert code == 0, failed_nodes_logs(out)
    assert "[session] stopped during start-up: the session did not begin" in out, out
    assert "hri_physio_session: error" not in out, out
    folder = session_folder(out)
    summary = json.loads((folder / "summary.json").read_text())
    assert (summary["outcome"], summary["stopped_by"], summary["exit_status"], summary["problem"]) == (
        "not started", "SIGINT", 0, None), summary
    # Each node was stopped; one still starting may have had no handler yet (its status is kept).
    assert all(node["exit_status"] is not None for node in summary["nodes"].values()), summary["nodes"]
    assert "crashed: KeyboardInterrupt" not in out, out
    # (The recorder, stopped before it made its bag, leaves none.)
    assert ("no report: the session did not begin" in out) == (folder / "bag").exists(), out
    assert not (folder / "report.json").exists()


def coach_state(url: str) -> dict:
    """The coach's current state (/coach/state, latched), as a live-view client gets it on subscribing."""
    live = watch(url, {topics.COACH_STATE: 1}, timeout=60)
    return json.loads(json.loads(live.messages[topics.COACH_STATE][-1][1])["data"])


def session_folder_of_running(output: str) -> Path:
    """The folder a running session announced at its start."""
    m = re.search(r"^\[session\] folder (\S+);", output, re.M)
    assert m, output
    return Path(m.group(1))


#: The launcher, its own ROS 2 teardown stuck as a Fast DDS deadlock leaves it: in C, holding the GIL.
STUCK_TEARDOWN = """
import ctypes, sys
import rclpy.node
from hri_physio_bringup import session
rclpy.node.Node.destroy_node = lambda self: ctypes.PyDLL(None).sleep(3600)
sys.exit(session.main(sys.argv[1:]))
"""


def test_a_launcher_stuck_in_its_ros_teardown_has_written_everything(short_session: list[str]) -> None:
    """The launcher tears its own ROS 2 node down last, after summary.json and its last line, and a
    teardown stuck in the middleware ends the process (status 1, every thread's stack) instead of
    leaving it to hang. (A session fails at start-up here, so that the test is short.)"""
    run = subprocess.run([sys.executable, "-c", STUCK_TEARDOWN, *short_session, "--startup-timeout", "1"],
                         capture_output=True, text=True, timeout=180, env=session_env(),
                         stdin=subprocess.DEVNULL)
    assert run.returncode == 1, (run.stdout, run.stderr)
    folder = session_folder(run.stdout)
    assert run.stdout.splitlines()[-1] == f"[session] session folder: {folder}"
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["outcome"] == "failed" and "not ready after 1 s" in summary["problem"], summary
    # Every node was stopped (some by the SIGINT itself: still starting, they had no handler yet).
    assert all(node["exit_status"] is not None for node in summary["nodes"].values()), summary["nodes"]
    assert "hri_physio_session: error: the system was not ready after 1 s" in run.stderr
    assert "Timeout" in run.stderr and "shut_down_ros" in run.stderr, run.stderr


@pytest.mark.parametrize("args,message", [
    (["--speed", "0"], "speed: expected greater than 0"),
    (["--age", "150"], "age: expected less than or equal to 120"),
    (["--conf", "/nonexistent/coach.yaml"], "conf: /nonexistent/coach.yaml does not exist"),
    (["--hr-source", "ecg", "--no-ecg"], "hr_source ecg needs the ECG path"),
    (["--policy", "bogus"], "--policy: invalid choice"),
    (["--live", "localhost:99999"], "live: expected [HOST:]PORT with a port from 1 to 65535"),
])
def test_bad_options_are_one_clear_line(args: list[str], message: str, tmp_path: Path) -> None:
    c = run_session(*args, "--out", str(tmp_path / "s"))
    assert c.returncode == 2, (c.stdout, c.stderr)
    lines = own_lines(c.stderr)
    assert len(lines) == 1 and lines[0].startswith("hri_physio_session: error: "), lines
    assert message in lines[0], lines
    assert c.stdout == "" and not (tmp_path / "s").exists()


@pytest.mark.parametrize("coach_yaml,message", [
    ("zone_low: 0.8\nzone_high: 0.7\n", "zone bounds out of order"),
    ("routine_file: /nonexistent/routine.yaml\n", "/nonexistent/routine.yaml"),
    ("speed_idx: 9\n", "speed_idx 9 is outside the ladder"),
])
def test_an_invalid_coach_configuration_starts_nothing(coach_yaml: str, message: str, tmp_path: Path) -> None:
    conf = tmp_path / "coach.yaml"
    conf.write_text(coach_yaml)
    c = run_session("--conf", str(conf), "--out", str(tmp_path / "s"))
    assert c.returncode == 2, (c.stdout, c.stderr)
    lines = own_lines(c.stderr)
    assert len(lines) == 1 and message in lines[0], lines
    assert not (tmp_path / "s").exists()  # no folder, no bag, no node started

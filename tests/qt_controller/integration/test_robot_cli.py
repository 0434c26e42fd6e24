"""The console scripts as a researcher runs them: help, errors, clean exits, a mock restart."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import SRC, NodeProcess, own_lines, wait_until

pytestmark = pytest.mark.ros

BIN = Path(sys.prefix) / "bin"
CONFIG = SRC / "qt_controller" / "config"


def run(script: str, *args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / script), *args], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


def test_help() -> None:
    c = run("qt_controller", "--help")
    assert c.returncode == 0 and "set gesture <name> [<speed>]" in c.stdout and "--interactive" in c.stdout
    assert "--allow-remote-exit" in c.stdout and "--command-queue-limit" in c.stdout
    m = run("mock_qt_robot", "--help")
    assert m.returncode == 0 and "--gesture-dir" in m.stdout and "--joint-state-rate" in m.stdout


@pytest.mark.parametrize(
    "script,args,fragment",
    [
        ("qt_controller", ["--conf", "/nonexistent/qt.yaml"], "/nonexistent/qt.yaml does not exist"),
        ("qt_controller", ["--ros-args", "--params-file", "/nonexistent/qt.yaml"], "/nonexistent/qt.yaml"),
        ("qt_controller", ["--ros-args", "-p", "speech_channel:=shout"], "speech_channel"),
        ("qt_controller", ["--ros-args", "-p", "joint_limits:=HeadYaw:9"], "must look like Joint:min:max"),
        ("qt_controller", ["--ros-args", "-p", "service_timeout:=abc"], "service_timeout"),
        ("qt_controller", ["--ros-args", "-p", "allow_remote_exit:=maybe"], "allow_remote_exit"),
        ("qt_controller", ["--ros-args", "-p", "colour:=red"], "colour"),
        ("qt_controller", ["--command-queue-limit", "0"], "command_queue_limit"),
        ("qt_controller", ["--discovery-timeout", "-1"], "discovery_timeout"),
        ("mock_qt_robot", ["--gesture-dir", "/nonexistent/gestures"],
         "gesture directory /nonexistent/gestures does not exist"),
        ("mock_qt_robot", ["--ros-args", "-p", "emotion_seconds:=0.0"], "emotion_seconds"),
        ("mock_qt_robot", ["--ros-args", "-p", "joint_state_rate:=fast"], "joint_state_rate"),
        ("mock_qt_robot", ["--ros-args", "-p", "gesture_busy_policy:=wait"], "gesture_busy_policy"),
        ("mock_qt_robot", ["--default-volume", "101"], "default_volume"),
        ("mock_qt_robot", ["--ros-args", "--params-file", "/nonexistent/mock.yaml"], "/nonexistent/mock"),
    ],
)
def test_bad_configuration_is_one_line_and_status_2(script: str, args: list[str], fragment: str) -> None:
    p = run(script, *args)
    assert p.returncode == 2, p.stderr
    lines = own_lines(p.stderr)
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error:") and fragment in lines[0], p.stderr
    assert "Traceback" not in p.stderr, p.stderr


def test_unknown_or_broken_conf_file(tmp_path: Path) -> None:
    conf = tmp_path / "qt.yaml"
    conf.write_text("speech_chanel: say\n")
    p = run("qt_controller", "--conf", str(conf))
    assert p.returncode == 2 and "speech_chanel" in p.stderr, p.stderr
    conf.write_text("mock_qt_robot:\n  ros__parameters:\n    emotion_seconds: [3\n")
    p = run("mock_qt_robot", "--ros-args", "--params-file", str(conf))
    assert p.returncode == 2 and str(conf) in p.stderr and "Traceback" not in p.stderr, p.stderr


def test_interactive_console_and_clean_signal_exit(tmp_path: Path) -> None:
    with NodeProcess("mock_qt_robot", "--conf", str(CONFIG / "mock_qt_robot.yaml")) as mock:
        mock.wait_for_output("mock QT robot ready", 60)
        # Typed right after start-up: give discovery of the mock more than the default 2 s on a busy machine.
        with NodeProcess("qt_controller", "--interactive", "--speech-channel", "say",
                         "--discovery-timeout", "30", stdin=subprocess.PIPE) as ctl:
            ctl.wait_for_output("listening for commands", 60)
            assert ctl.proc.stdin is not None
            ctl.proc.stdin.write("set speech hello\nset emotion Happy\nget emotion\nset volume 500\n")
            ctl.proc.stdin.close()  # end of input: the controller exits
            assert ctl.wait(30) == 0, ctl.output
            out = ctl.output
        assert "ok: speech sent to /qt_robot/speech/say" in out
        assert "ok: emotion QT/happy sent to /qt_robot/emotion/show" in out
        assert "ok: emotion QT/happy (sent at t=" in out
        assert "error: bad command: volume 500 is out of range [0, 100]" in out
        wait_until(lambda: "emotion_started" in mock.output, 30, "the mock to show the emotion")
        assert mock.stop(signal.SIGINT) == 0, mock.output
    with NodeProcess("qt_controller", "--conf", str(CONFIG / "qt_controller.yaml")) as ctl:
        ctl.wait_for_output("listening for commands", 60)  # the shipped defaults file is valid
        assert ctl.stop(signal.SIGTERM) == 0, ctl.output


def test_controller_keeps_working_across_a_mock_restart(wall_probe) -> None:
    p = wall_probe
    mock = NodeProcess("mock_qt_robot")
    mocks = [mock]
    try:
        with NodeProcess("qt_controller", "--ros-args", "-p", "service_timeout:=1.5",
                         "-p", "discovery_timeout:=1.0") as ctl:
            ctl.wait_for_output("listening for commands", 60)
            p.wait_answering(20, "qt_controller to answer")
            wait_until(lambda: p.send("set gesture base 2.0")["ok"], 60, "the first gesture to be accepted")
            assert p.send("set speech before the restart")["ok"]

            assert mock.stop(signal.SIGTERM) == 0, mock.output
            down = p.send("set gesture base 2.0")
            assert not down["ok"] and "/qt_robot/gesture/play is not available" in down["message"], down
            silent = p.send("set speech anyone there?")
            assert not silent["ok"] and "nobody listens on /qt_robot/behavior/talkText" in silent["message"]

            restarted_at = time.time()
            mock = NodeProcess("mock_qt_robot")
            mocks.append(mock)
            wait_until(lambda: p.send("set gesture base 2.0")["ok"], 60, "gestures to work again")
            assert p.send("set speech after the restart")["ok"]
            wait_until(lambda: "speech_started" in mock.output, 10, "the new mock to speak")
            wait_until(lambda: p.send("get state head")["data"].get("stamp", 0) > restarted_at, 20,
                       "joint states from the new mock")
            assert ctl.proc.poll() is None, "the controller kept running"
            assert ctl.stop(signal.SIGTERM) == 0, ctl.output
    finally:
        for m in mocks:
            m.__exit__()

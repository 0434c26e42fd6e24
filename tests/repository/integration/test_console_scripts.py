"""Every console script answers bad input with one line and exit status 2, never a traceback.

For each node: a wrong-typed parameter (``--ros-args -p <numeric option>:=abc``), a missing params
file, a broken params file and an unknown flag. For the tools and launchers (no ROS parameters):
an unknown flag and a wrong-typed option. The list of scripts comes from the packages' setup.cfg
files, so a new script without an entry here fails the test.
"""

from __future__ import annotations

import configparser
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import ROOT, own_lines

BIN = Path(sys.prefix) / "bin"

#: Node -> one of its numeric options (a ROS parameter of the same name).
NODES = {
    "physio_receiver": "input_frame",
    "physio_simulator": "seconds",
    "polar_streamer": "ecg_rate",
    "physio_recorder": "status_period",
    "recorder": "status_period",
    "physio_replayer": "clock_step",
    "replayer": "clock_step",
    "neurokit_processor": "num_channels",
    "qt_controller": "service_timeout",
    "mock_qt_robot": "emotion_seconds",
    "qt_physio_coach": "part_age",
    "simulated_participant": "age",
    "audio_streamer": "fade",
    "video_streamer": "width",
    "live_view": "port",
}
#: Tools and launchers -> a numeric flag.
TOOLS = {
    "hri_physio_session": "--speed",
    "physio_bridge_demo": "--seconds",
    "hri_physio_demo": "--seconds",
    "hri_physio_evaluate": "--cohort",
    "hri_physio_report": None,
}


def _console_scripts() -> set[str]:
    names = set()
    for setup in ROOT.glob("src/*/setup.cfg"):
        config = configparser.ConfigParser()
        config.read(setup)
        lines = config.get("options.entry_points", "console_scripts", fallback="").splitlines()
        names.update(line.split("=")[0].strip() for line in lines if line.strip())
    return names


def test_every_console_script_is_covered() -> None:
    assert _console_scripts() == set(NODES) | set(TOOLS)


def _run(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(BIN / script), *args], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)


def _one_line_error(result: subprocess.CompletedProcess[str], script: str, *words: str) -> None:
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert "Traceback" not in output, output
    lines = [line for line in own_lines(result.stderr) if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error:"), output
    for word in words:
        assert word in lines[0], output


@pytest.mark.parametrize("script", sorted(NODES))
def test_node_bad_parameters_are_one_line(script: str, tmp_path: Path) -> None:
    option = NODES[script]
    # a real bag for the replayer, so that only the parameter is wrong
    bag = next((ROOT / "tests" / "data" / "report").glob("session_*"))
    extra = [str(bag)] if "replayer" in script else []
    _one_line_error(_run(script, *extra, "--ros-args", "-p", f"{option}:=abc"), script, option)
    _one_line_error(_run(script, *extra, "--ros-args", "--params-file", str(tmp_path / "missing.yaml")),
                    script, "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text(f"{script}:\n  ros__parameters: [\n")
    _one_line_error(_run(script, *extra, "--ros-args", "--params-file", str(broken)), script, "YAML")
    _one_line_error(_run(script, *extra, "--no-such-flag"), script, "--no-such-flag")


@pytest.mark.parametrize("script", sorted(TOOLS))
def test_tool_bad_options_are_one_line(script: str, tmp_path: Path) -> None:
    _one_line_error(_run(script, "--no-such-flag", str(tmp_path)), script, "--no-such-flag")
    flag = TOOLS[script]
    if flag is not None:
        _one_line_error(_run(script, flag, "abc"), script, flag.lstrip("-").replace("-", "_"))

"""The bridge demo (physio_bridge_demo, alias hri_physio_demo): simulator -> LSL -> receivers -> ROS 2."""

from __future__ import annotations

import pytest

from helpers import NodeProcess

pytestmark = [pytest.mark.ros, pytest.mark.lsl]


@pytest.mark.parametrize("script", ["physio_bridge_demo", "hri_physio_demo"])
def test_demo_streams_the_simulated_participant_into_ros(session_tag: str, script: str) -> None:
    """The bridge demo, shortened: simulator -> LSL -> receivers -> ROS 2, all samples arrive."""
    args = ("--seconds", "4", "--quiet-nodes", "--device-id", f"SIM{session_tag}")  # not a live demo's
    with NodeProcess(script, *args) as demo:
        code = demo.wait(90)
    assert code == 0, demo.output
    assert "done: 520 ECG samples received on ROS 2 (520 simulated at 130 Hz), 4 HR values" in demo.output
    assert "timestamps strictly increasing: True" in demo.output


@pytest.mark.parametrize(
    "args,option",
    [(["--bpm", "0"], "bpm"), (["--seconds", "0"], "seconds"), (["--device-id", "a/b"], "device_id"),
     (["--colour", "red"], "--colour")],
)
def test_bad_options_are_refused_before_anything_starts(args: list[str], option: str) -> None:
    """--bpm 0 used to start everything, let the simulator refuse, and report '3900 simulated'."""
    with NodeProcess("physio_bridge_demo", *args) as demo:
        code = demo.wait(60)
    assert code == 2, demo.output
    lines = demo.output.strip().splitlines()
    assert lines[-1].startswith("physio_bridge_demo: error:") and option in lines[-1], demo.output
    assert "simulated" not in demo.output and "Traceback" not in demo.output, demo.output

"""The README's main job (shortened): simulator -> LSL -> receivers -> ROS 2, all samples arrive."""

from __future__ import annotations

import pytest

from helpers import NodeProcess


@pytest.mark.ros
def test_demo_streams_the_simulated_participant_into_ros(session_tag: str) -> None:
    """The bridge demo, shortened: simulator -> LSL -> receivers -> ROS 2, all samples arrive."""
    args = ("--seconds", "4", "--quiet-nodes", "--device-id", f"SIM{session_tag}")  # not a live demo's
    with NodeProcess("hri_physio_demo", *args) as demo:
        code = demo.wait(90)
    assert code == 0, demo.output
    assert "done: 520 ECG samples received on ROS 2 (520 simulated at 130 Hz), 4 HR values" in demo.output
    assert "timestamps strictly increasing: True" in demo.output

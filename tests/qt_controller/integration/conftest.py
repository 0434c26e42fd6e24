"""The robot side in one process (mock_qt_robot + qt_controller + a probe) for the integration tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from helpers import wait_unmatched
from helpers.robot_side import Probe, RobotSide
from hri_physio_bridge.ros_tools import ExecutorThread

SHORT_GESTURE = """<gesture><name>test_blink</name><joints><joint>HeadPitch</joint></joints><points>
<point time="0">0</point><point time="0.25">10</point><point time="0.5">0</point></points></gesture>"""


@pytest.fixture
def robot_side(ros_context: Any, tmp_path: Path) -> Iterator[RobotSide]:
    (tmp_path / "test_blink.xml").write_text(SHORT_GESTURE)
    side = RobotSide(
        ros_context,
        {"gesture_dirs": [str(tmp_path)], "emotion_seconds": 2.0, "speech_seconds_per_char": 0.05},
        {"service_timeout": 10.0},
    )
    try:
        yield side
    finally:
        side.close()


@pytest.fixture
def wall_probe(ros_context: Any) -> Iterator[Probe]:
    """A probe on wall time, spinning on its own thread (for node subprocesses)."""
    probe = Probe(ros_context, use_sim_time=False)
    spinner = ExecutorThread(probe.node, context=ros_context)
    try:
        yield probe
    finally:
        spinner.close()
        wait_unmatched(probe.node)  # the tests' node subprocesses have gone: let their departure settle
        probe.node.destroy_node()

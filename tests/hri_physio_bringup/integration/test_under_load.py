"""A session on a machine kept busy: two processes spin on both cores the whole time (issue 26).

It must end as on an idle machine: exit 0, every node's exit 0, no node restarted, every strap
sample in the bag once (counter check), the processor's input drained, the report written.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from helpers import NodeProcess, session_env
from helpers.routines import FOUR_AND_A_HALF_MINUTES, short_routine
from helpers.session_bags import RECEIVERS, bag_messages, check_counter, failed_nodes_logs, session_folder

pytestmark = [pytest.mark.ros, pytest.mark.lsl, pytest.mark.session]

SPEED = 30


@pytest.fixture
def both_cores_busy() -> Iterator[None]:
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        yield
    finally:
        for proc in spinners:
            proc.kill()
            proc.wait()


@pytest.mark.timeout(900)  # the clock guard slows sim time down to what the busy machine can do
def test_a_session_with_both_cores_busy_ends_cleanly_with_nothing_lost(
        both_cores_busy: None, tmp_path: Path, session_tag: str) -> None:
    options = [*short_routine(tmp_path, FOUR_AND_A_HALF_MINUTES), "--speed", str(SPEED),
               "--out", str(tmp_path / "sessions"), "--device-id", f"SIM{session_tag}busy"]
    with NodeProcess("hri_physio_session", *options, env=session_env()) as session:
        code = session.wait(840)
    out = session.output
    assert code == 0, failed_nodes_logs(out)
    assert "Traceback" not in out and "not processed" not in out
    folder = session_folder(out)
    summary = json.loads((folder / "summary.json").read_text())
    assert (summary["outcome"], summary["exit_status"], summary["restarts"]) == ("finished", 0, []), summary
    assert all(node["exit_status"] == 0 for node in summary["nodes"].values()), summary["nodes"]
    held = summary["clock"]["held_wall_s"]
    # The console says when the clock waited for the loop (a second of wall time or more), and why.
    assert (f"the nodes could not keep up with {SPEED}x here" in out) == (held >= 1.0), (held, out[-2000:])
    assert (folder / "report.json").is_file() and (folder / "report.html").stat().st_size > 0
    bag = bag_messages(folder / "bag")
    receivers = summary["session"]["receivers"]
    for node, (topic, rate) in RECEIVERS.items():
        stamps = np.concatenate(bag[topic])
        assert check_counter(stamps, rate, []) == 0, node  # every sample once, in order, none missing
        assert receivers[node]["published_samples"] == len(stamps), (node, receivers[node])
        assert receivers[node]["received_samples"] == len(stamps), (node, receivers[node])
    processor = (folder / "logs" / "neurokit_processor.log").read_text()
    assert "received but not processed" not in processor

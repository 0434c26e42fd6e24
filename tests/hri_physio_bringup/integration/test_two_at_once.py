"""Two sessions started a second apart on one machine do not mix (issue 16).

Neither is told a ROS domain nor a device id: each claims a free domain and names its strap's
LSL streams itself, and each ends when its own routine ends, with the counts of a session alone.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from helpers import session_env
from helpers.routines import FOUR_AND_A_HALF_MINUTES, routine_seconds, short_routine

pytestmark = [pytest.mark.ros, pytest.mark.lsl, pytest.mark.session]

SHORT = FOUR_AND_A_HALF_MINUTES
SESSION_SECONDS = routine_seconds(SHORT)


def test_two_sessions_a_second_apart_each_run_alone(tmp_path: Path) -> None:
    env = session_env()  # each session chooses a domain of its own
    options = [*short_routine(tmp_path, SHORT), "--speed", "20", "--no-ecg", "--no-record", "--no-report"]
    procs, logs = [], []
    for name in ("a", "b"):
        log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - closed below
        procs.append(subprocess.Popen(
            [str(Path(sys.prefix) / "bin" / "hri_physio_session"), *options, "--out", str(tmp_path / name)],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env, text=True))
        logs.append(log)
        time.sleep(1.0)  # the case: the second session starts a second after the first
    outputs = []
    try:
        for proc, log in zip(procs, logs, strict=True):
            code = proc.wait(240)  # each ends by itself when its routine ends
            log.seek(0)
            outputs.append(log.read())
            assert code == 0, outputs[-1]
    finally:
        for proc, log in zip(procs, logs, strict=True):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            log.close()
    summaries = []
    for name, out in zip("ab", outputs, strict=True):
        folder = re.findall(r"^\[session\] session folder: (\S+)$", out, re.M)
        assert len(folder) == 1, out
        summaries.append(json.loads((tmp_path / name / Path(folder[0]).name / "summary.json").read_text()))
    a, b = summaries
    assert a["ros_domain"] != b["ros_domain"] and a["ros_domain_chosen"] and b["ros_domain_chosen"]
    assert a["lsl_device_id"] != b["lsl_device_id"]
    for s in summaries:
        counts = s["session"]
        assert (s["outcome"], counts["stop_reason"]) == ("finished", None), s
        # One strap HR sample per second of its own session (mixed sessions doubled it).
        assert abs(counts["hr_samples"] - SESSION_SECONDS) <= 3, counts
        hr = counts["receivers"]["hr_receiver"]
        assert hr["received_samples"] == hr["published_samples"] and hr["gaps"] == 0, hr
        # Mixed sessions starved rule updates of heart rate; one pause on a loaded machine is not that.
        assert sum(counts["gated"].values()) <= 1, counts
        assert counts["rule_updates"] == (60 + 90 + 60) // 30 - 1, counts  # every 30 s of exercise
    # The robot did for each what a session alone gets (mixed sessions saw each other's actions).
    ra, rb = a["session"]["robot_actions"], b["session"]["robot_actions"]
    assert abs(ra - rb) <= 0.2 * max(ra, rb), (ra, rb)

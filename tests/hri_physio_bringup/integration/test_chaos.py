"""Supervision under fire: every restartable node killed -9 once mid-session, then an essential one.

The session must carry on through the restarts and say each of them (console, summary.json,
/session/events in the bag, the report); what a killed receiver could not get (a new LSL inlet
gets no history) must be exactly what its recorded gap says, nothing else missing, nothing twice.
"""

from __future__ import annotations

import json
import os
import random
import signal
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from helpers import NodeProcess, session_env
from helpers.routines import FOUR_AND_A_HALF_MINUTES, short_routine
from helpers.session_bags import RECEIVERS, bag_messages, check_counter, failed_nodes_logs, session_folder
from hri_physio_bridge import topics

pytestmark = [pytest.mark.ros, pytest.mark.session]

SEED = 2026
RESTARTABLE = ["qt_controller", "mock_qt_robot", "audio_streamer", "video_streamer", "hr_receiver",
               "ecg_receiver", "neurokit_processor"]


def node_pid(launcher: int, node: str) -> int:
    """The pid of the session's process running ``node`` (a child of the launcher, by its command line)."""
    found = []
    for child in psutil.Process(launcher).children():
        try:
            argv = child.cmdline()
        except psutil.NoSuchProcess:
            continue
        scripts = {os.path.basename(a) for a in argv[:2]}
        if node in scripts or (f"__node:={node}" in argv and "physio_receiver" in scripts):
            found.append(child.pid)
    assert len(found) == 1, (node, found)
    return found[0]


@pytest.fixture
def short_session(tmp_path: Path, session_tag: str) -> list[str]:
    return [*short_routine(tmp_path, FOUR_AND_A_HALF_MINUTES),
            "--out", str(tmp_path / "sessions"), "--device-id", f"SIM{session_tag}"]


def test_every_restartable_node_killed_once_is_restarted_and_only_the_gaps_lose_data(
        short_session: list[str]) -> None:
    rng = random.Random(SEED)
    order = rng.sample(RESTARTABLE, len(RESTARTABLE))
    delays = [rng.uniform(0.3, 1.5) for _ in order]
    plan = f"seed {SEED}: kills {list(zip(order, [round(d, 2) for d in delays], strict=True))}"
    print(plan)  # pytest shows it with any failure
    with NodeProcess("hri_physio_session", *short_session, "--speed", "10", env=session_env()) as session:
        session.wait_for_output("[session] system ready", timeout=180)
        for node, delay in zip(order, delays, strict=True):
            time.sleep(delay)  # the kill's random moment, not a wait for anything
            os.kill(node_pid(session.proc.pid, node), signal.SIGKILL)
            said = f"[session] restarted {node} (1 of 3): it died with exit status -9 (SIGKILL)"
            session.wait_for_output(said, timeout=120)
            if node in RECEIVERS:  # its gap is known once it publishes again
                session.wait_for_output(f"[session] {node} publishes again:", timeout=120)
        code = session.wait(300)
    out = session.output
    assert code == 0, f"{plan}\n{failed_nodes_logs(out)}"
    assert "Traceback" not in out, plan
    folder = session_folder(out)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["outcome"] == "finished" and summary["node_lost"] is None, plan
    restarts = summary["restarts"]
    assert sorted(r["node"] for r in restarts) == sorted(RESTARTABLE), plan
    # down_s is session time: a clock held for the loop may stand still while a node restarts.
    assert all(r["exit_status"] == -9 and r["restart"] == 1 and r["restarted_t"] >= r["died_t"]
               for r in restarts), restarts
    assert all(summary["nodes"][n]["restarts"] == 1 and summary["nodes"][n]["exit_status"] == 0
               for n in RESTARTABLE), summary["nodes"]
    for node in RECEIVERS:  # its closing line counts its last process only, and says so
        line = next(x for x in out.splitlines() if x.startswith(f"[session] {node}: "))
        assert "(counted since its restart 1; " in line, line
    for node in RESTARTABLE:
        log = (folder / "logs" / f"{node}.log").read_text()
        assert f"[session] --- {node} died with exit status -9 (SIGKILL): restart 1 of 3" in log, node
    report = json.loads((folder / "report.json").read_text())
    shown = [e["node"] for e in report["session_events"] if e["event"] == "node_restarted"]
    assert sorted(shown) == sorted(RESTARTABLE), (plan, report["session_events"])

    bag = bag_messages(folder / "bag")
    events = bag[topics.SESSION_EVENTS]
    assert sorted(e["node"] for e in events if e["event"] == "node_restarted") == sorted(RESTARTABLE), plan
    for node, (topic, rate) in RECEIVERS.items():
        (gap,) = [e for e in events if e["event"] == "receiver_gap" and e["node"] == node]
        (record,) = [r for r in restarts if r["node"] == node]
        assert record["gap"] == {"last_before": gap["last_before"], "first_after": gap["first_after"],
                                 "missing": gap["missing"]}
        stamps = np.concatenate(bag[topic])
        start, in_flight = gap_start_in_bag(stamps, rate, gap, max(len(f) for f in bag[topic]))
        lost = check_counter(stamps, rate, [(start, gap["first_after"])])
        # The bag misses what the gap says, no less, and at most the one frame in flight at the kill.
        assert lost == gap["missing"] + in_flight, (plan, node, lost, in_flight, gap)


def gap_start_in_bag(stamps: np.ndarray, rate: float, gap: dict, frame_samples: int) -> tuple[float, int]:
    """Where a killed receiver's gap begins in the bag, and the samples before the launcher's
    ``last_before`` that the bag misses too.

    The launcher and the recorder are two subscribers of the receiver: the frame it was publishing
    when SIGKILL came can reach one and not the other (DDS repairs a lost delivery only while the
    writer lives). So the bag may also lack the last frame the launcher saw, never more than that:
    at most ``frame_samples`` (the topic's largest frame), all of them right up to ``last_before``.
    """
    before = stamps[stamps <= gap["last_before"] + 1e-9]
    assert before.size, ("no sample before the gap in the bag", gap)
    in_flight = round((gap["last_before"] - float(before[-1])) * rate)
    assert in_flight <= frame_samples, (
        f"the bag misses {in_flight} sample(s) up to the gap's last_before {gap['last_before']!r}, "
        f"more than one frame ({frame_samples})")
    return float(before[-1]), in_flight


@pytest.mark.parametrize(("node", "options", "why", "reason"), [
    ("qt_physio_coach", [], "an essential node: the session cannot go on without it", "essential"),
    ("qt_controller", ["--max-restarts", "0"], "after 0 restart(s), the limit (--max-restarts 0)",
     "restart limit"),
])
def test_a_lost_node_ends_the_session_with_one_error_line_and_a_complete_bag(
        short_session: list[str], node: str, options: list[str], why: str, reason: str) -> None:
    with NodeProcess("hri_physio_session", *short_session, "--speed", "10", "--no-ecg", *options,
                     env=session_env()) as session:
        session.wait_for_output("/04:30 calibration", timeout=180)  # the routine runs (its first line)
        os.kill(node_pid(session.proc.pid, node), signal.SIGKILL)
        code = session.wait(300)
    out = session.output
    assert code == 1, out
    errors = [line for line in out.splitlines() if line.startswith("hri_physio_session: error:")]
    assert errors == [f"hri_physio_session: error: {node} died with exit status -9 (SIGKILL), {why}"], out
    assert "Traceback" not in out
    folder = session_folder(out)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["outcome"] == "failed" and summary["exit_status"] == 1 and summary["restarts"] == []
    assert summary["node_lost"]["node"] == node and summary["node_lost"]["reason"] == reason
    assert summary["problem"] == errors[0].removeprefix("hri_physio_session: error: ")
    # Everything else stopped cleanly: the recorder closed its bag, which opens and holds the loss.
    others = {name: n["exit_status"] for name, n in summary["nodes"].items() if name != node}
    assert set(others.values()) == {0}, others
    (lost,) = bag_messages(folder / "bag")[topics.SESSION_EVENTS]
    assert (lost["event"], lost["node"], lost["exit_status"]) == ("node_died", node, -9)
    assert lost["reason"] == reason
    report = json.loads((folder / "report.json").read_text())
    assert report["bag_complete"] is True
    assert [e["event"] for e in report["session_events"]] == ["node_died"]

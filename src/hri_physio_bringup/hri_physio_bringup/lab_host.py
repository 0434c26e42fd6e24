"""One host of a lab other than the station: ``hri_physio_session --lab <file> --role sensor|robot``.

It starts the role's nodes (:func:`hri_physio_bringup.plan.for_role`) with the lab's ROS domain,
discovery and LSL configuration, restarts a restartable node that dies (the same policy as a
single-host session, :mod:`hri_physio_bringup.supervision`), and publishes a heartbeat on
``/lab/hosts`` every half second of wall time, which the station shows ("robot host ... is up") and
watches (an outage is an event in the station's bag). It runs until the station says its session
has ended (``/lab/session``, latched), or until Ctrl-C; then it stops its nodes cleanly and writes
``summary.json`` into its own folder (``<participant>_<role>_<date-time>/``: logs, configs).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from datetime import datetime
from typing import Any

from hri_physio_bridge import topics
from hri_physio_bridge.launcher import ProcessGroup
from hri_physio_bridge.ros_tools import BackgroundNode
from hri_physio_bridge.stop_signals import install_stop_handlers
from hri_physio_bridge.waiting import wait_until
from hri_physio_bringup.console import PlainConsole, SessionConsole, VerboseConsole
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.hosts import HEARTBEAT_PERIOD, SESSION_ENDED, heartbeat
from hri_physio_bringup.isolation import DomainClaim
from hri_physio_bringup.lab import Lab, describe
from hri_physio_bringup.options import SessionConfig
from hri_physio_bringup.plan import SessionPlan
from hri_physio_bringup.supervision import Loss, Supervisor, restarts_text, status_text


def heartbeat_qos() -> Any:
    """Heartbeats: the newest counts, an old one is worth nothing (best effort, shallow)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


class HostBeacon(BackgroundNode):
    """Publishes this host's heartbeat; notices the station's end of the session."""

    def __init__(self, lab: Lab, role: str) -> None:
        from std_msgs.msg import String

        from hri_physio_bridge.qos import latched_qos

        super().__init__(f"lab_{role}")
        self._string, self.lab, self.role = String, lab, role
        self.ended = threading.Event()
        self.pub = self.node.create_publisher(String, topics.LAB_HOSTS, heartbeat_qos())

        def on_session(msg: String) -> None:
            try:
                data = json.loads(msg.data)
            except ValueError:
                return
            if isinstance(data, dict) and data.get("event") == SESSION_ENDED and data.get("lab") == lab.lab:
                self.ended.set()

        self.node.create_subscription(String, topics.LAB_SESSION, on_session, latched_qos())
        self.start()

    def beat(self, nodes: dict[str, bool]) -> None:
        self.pub.publish(self._string(data=heartbeat(self.lab, self.role, nodes, time.time())))


def host_summary(lab: Lab, role: str, folder: SessionFolder, started: datetime, claim: DomainClaim,
                 group: ProcessGroup, node_codes: dict[str, int], restarts: list[dict[str, Any]],
                 outcome: str, code: int | None, problem: str | None, env: dict[str, str]) -> dict[str, Any]:
    procs = {p.name: p for p in group.procs}
    return {
        "lab": lab.lab, "role": role, "host": lab.host_of(role), "address": lab.address_of(role),
        "folder": str(folder.path.resolve()),
        "started": started.isoformat(timespec="seconds"),
        "ended": None if outcome == "running" else datetime.now().isoformat(timespec="seconds"),
        "outcome": outcome, "exit_status": code, "problem": problem,
        "ros_domain": claim.domain, "discovery": env, "lsl_config": "lsl_api.cfg",
        "clock": "every ROS node here runs on the station's /clock (use_sim_time); a simulated strap "
                 "stamps its LSL samples on that clock too",
        "restarts": restarts,
        "nodes": {name: {"script": p.argv[0].rsplit("/", 1)[-1], "log": f"logs/{name}.log",
                         "exit_status": node_codes.get(name), "teardown_fault": p.teardown_fault,
                         "restarts": sum(r["node"] == name for r in restarts)} for name, p in procs.items()},
    }


def run_host(options: SessionConfig, lab: Lab, plan: SessionPlan, folder: SessionFolder, claim: DomainClaim,
             started: datetime, env: dict[str, str]) -> int:
    """Run this host's nodes until the station's session ends (or a stop); the exit status."""
    from hri_physio_bringup.session import Outcome, start_nodes

    role = options.role
    out = Outcome()
    stop = install_stop_handlers(lambda name: setattr(out, "stopped_by", name))
    console: SessionConsole = (VerboseConsole(sys.stdout, options.progress_every) if options.verbose
                               else PlainConsole(sys.stdout, options.progress_every))
    group = ProcessGroup(on_line=console.node_line)
    console.say(describe(lab, role))
    console.say(f"[lab] {role}: {', '.join(n.name for n in plan.nodes)}; folder {folder.display()}; "
                f"running until the station's session ends (or Ctrl-C)")
    supervisor = Supervisor(options.max_restarts)
    beacon: HostBeacon | None = None
    t0 = time.monotonic()
    ended = False

    def summary(outcome: str, code: int | None) -> None:
        restarts = [r.record() for r in supervisor.records]
        folder.write_summary(host_summary(lab, role, folder, started, claim, group, out.node_codes, restarts,
                                          outcome, code, out.problem, env))

    summary("running", None)
    try:
        beacon = HostBeacon(lab, role)
        start_nodes(group, plan, folder)
        next_beat = 0.0

        def step() -> bool:
            nonlocal next_beat
            now = time.monotonic() - t0
            for p in list(group.procs):
                code = p.returncode
                if code is None or supervisor.pending(p.name):
                    continue
                decision = supervisor.died(p.name, code, now, p.error_line() if code > 0 else "")
                if isinstance(decision, Loss):
                    out.fail(decision.problem(supervisor.max_restarts))
                    return True
            for record in supervisor.due():
                old = next(p for p in group.procs if p.name == record.node)
                group.restart(old, f"[lab] --- {record.node} died with exit status "
                              f"{status_text(record.exit_status)}: restart {record.restart} of "
                              f"{supervisor.max_restarts}, same command line; its output continues here ---")
                supervisor.started(record, now)
                console.say(record.line(supervisor.max_restarts))
            if now >= next_beat:
                assert beacon is not None
                beacon.beat({p.name: p.returncode is None for p in group.procs})
                next_beat = now + HEARTBEAT_PERIOD
            return beacon is not None and beacon.ended.is_set()

        ended = wait_until(step, None, stop=stop, poll=0.05) and out.problem is None
        if ended:
            console.say("[lab] the station's session has ended: stopping this host's nodes")
    finally:
        if out.stopped_by:
            console.say(f"{out.stopped_by}: stopping this host's nodes")
        out.node_codes = group.stop()
        for fault in group.teardown_faults():
            console.say(f"[lab] warning: {fault}")
        if beacon is not None:
            beacon.stop_spinning()
        restarts = [r.record() for r in supervisor.records]
        if restarts:
            console.say(restarts_text(restarts))
        waiting = set(supervisor.awaiting_restart())
        bad = {name: c for name, c in out.node_codes.items() if c != 0 and name not in waiting}
        if bad and out.code == 0:
            out.fail(f"node exit statuses {bad}")
        outcome = "failed" if out.code else ("finished" if ended else "stopped")
        summary(outcome, out.code)
        if out.problem:
            print(f"hri_physio_session: error: {out.problem}", file=sys.stderr, flush=True)
        console.say(f"[lab] {role} host done ({outcome}); folder {folder.display()}")
        if beacon is not None:
            beacon.close()  # last: a teardown stuck in the middleware ends the process (shut_down_ros)
    return out.code

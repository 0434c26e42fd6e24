"""A lab of three hosts made of network namespaces: sensor, robot and station, each running
``hri_physio_session --lab <file> --role <its role>`` on an address of its own, joined by a bridge.

Root only (namespaces, veth pairs, a bridge): skipped with the reason where the machine does not
allow them. Every namespace is unique to the run and removed afterwards, also on failure. The
processes in the namespaces run the DDS middleware on UDP only: namespaces share ``/dev/shm``,
computers do not, and a lab's traffic must cross the lab's links.

1. A shortened session across the three hosts: every strap sample reaches the station's bag
   (counter check of HR and ECG), the coach's commands reach the robot host and are answered from
   there, the report is written, and the two other hosts end when the station's session ends. A
   fourth namespace on the same bridge, not in the lab file, with ordinary (subnet-wide) discovery,
   sees none of the lab's topics or streams.
2. Another lab: two hosts (the strap's laptop is the station too, the robot has its own) with
   ``discovery: subnet``, where that outsider does see the ROS topics (not the strap's LSL streams:
   the lab's LSL session id is its own). The robot host's link is taken down for 10 s mid-session:
   the coach carries on, the robot side is heard again and performs commands after it, no strap
   sample is lost, and the outage is in the bag, the report and summary.json.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from helpers import NodeProcess, session_env, wait_until
from helpers.netns import NetnsLab, existing_namespaces, unavailable_reason
from helpers.routines import FOUR_AND_A_HALF_MINUTES, short_routine
from helpers.session_bags import RECEIVERS, bag_messages, check_counter, failed_nodes_logs, session_folder
from hri_physio_bridge import topics
from hri_physio_bringup.isolation import DomainClaim, DomainInUse, claim_domain, claim_lab_domain

REASON = unavailable_reason()
pytestmark = [pytest.mark.ros, pytest.mark.lsl, pytest.mark.session,
              pytest.mark.skipif(REASON is not None, reason=f"no network-namespace lab here: {REASON}")]

#: Topologies: which host runs each role, and the lab's discovery.
THREE_HOSTS = ({"sensor": "sensor", "robot": "robot", "station": "station"}, "peers")
#: The outage test's lab: the strap's laptop is the station too, the robot has a host of its own.
TWO_HOSTS_SUBNET = ({"sensor": "laptop", "robot": "robot", "station": "laptop"}, "subnet")
OUTSIDER = "outsider"  # on the lab's bridge, not in the lab file
STARTUP = 400.0  # wall seconds: three launchers and a dozen nodes on a busy 2-core machine
SESSION = 600.0
OUTAGE = 10.0


@contextlib.contextmanager
def lab_domain() -> Iterator[int]:
    """A ROS domain free on this machine, held (shared, as a lab's roles hold it) for the test."""
    for _ in range(50):
        probe = claim_domain(None, {"pid": os.getpid(), "role": "lab test"})
        domain = probe.domain
        probe.release()
        try:
            held: DomainClaim = claim_lab_domain(domain, "test", {"pid": os.getpid(), "role": "lab test"})
        except DomainInUse:
            continue  # taken between the probe and the claim: another
        try:
            yield domain
        finally:
            held.release()
        return
    raise AssertionError("no free ROS domain for the lab test")


def write_lab(path: Path, net: NetnsLab, domain: int, device: str, roles: dict[str, str],
              discovery: str) -> Path:
    path.write_text(yaml.safe_dump({
        "lab": f"nslab-{net.tag}", "ros_domain": domain, "device_id": device, "discovery": discovery,
        "hosts": {host: net.address(host) for host in set(roles.values())}, "roles": roles}))
    return path


#: What an outsider on the lab's network finds: ROS topics (ordinary subnet-wide discovery in the lab's
#: domain) and LSL streams (link scope), as JSON.
PROBE = """
import json, sys, time
import pylsl, rclpy
rclpy.init()
node = rclpy.create_node("outsider")
seen, end = set(), time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
    seen |= {name for name, _types in node.get_topic_names_and_types()}
streams = sorted(info.name() for info in pylsl.resolve_streams(5.0))
print(json.dumps({"topics": sorted(seen), "streams": streams}))
"""


def probe_as_outsider(tmp_path: Path, net: NetnsLab, domain: int, seconds: float) -> dict[str, list[str]]:
    cfg = tmp_path / "outsider_lsl_api.cfg"
    cfg.write_text("[multicast]\nResolveScope = link\n[ports]\nPortRange = 128\n[log]\nlevel = -1\n")
    env = session_env(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", ROS_STATIC_PEERS="",
                      FASTDDS_BUILTIN_TRANSPORTS="UDPv4", LSLAPICFG=str(cfg))
    done = subprocess.run(net.command(OUTSIDER, [sys.executable, "-c", PROBE, str(seconds)]), env=env,
                          capture_output=True, text=True, timeout=seconds + 120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def string_messages(bag: Path, wanted: set[str]) -> list[tuple[str, int, str]]:
    """(topic, receive ns, text) of every String message on ``wanted``, in recording order."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, log_ns, raw in reader.messages(connections=conns):
            out.append((conn.topic, log_ns, reader.deserialize(raw, conn.msgtype).data))
    return out


def role_folder(out: Path, role: str) -> Path:
    (folder,) = [p for p in out.iterdir() if p.is_dir()] if out.is_dir() else []
    assert (folder / "summary.json").is_file(), (role, folder)
    return folder


class Lab:
    """The three launchers in their namespaces, their outputs, their folders."""

    def __init__(self, tmp_path: Path, net: NetnsLab, lab_file: Path, options: list[str],
                 roles: dict[str, str], domain: int) -> None:
        self.tmp_path, self.net, self.domain = tmp_path, net, domain
        env = session_env(FASTDDS_BUILTIN_TRANSPORTS="UDPv4")
        self.procs: dict[str, NodeProcess] = {}
        for role in ("robot", "sensor", "station"):
            self.procs[role] = NodeProcess(
                "hri_physio_session", "--lab", str(lab_file), "--role", role, *options,
                "--out", str(tmp_path / f"out-{role}"), env=env,
                prefix=tuple(net.command(roles[role], [])))

    def output(self, role: str) -> str:
        return self.procs[role].output

    def all_output(self) -> str:
        return "\n".join(f"===== {role} =====\n{failed_nodes_logs(p.output)}"
                         for role, p in self.procs.items())

    def folder(self, role: str) -> Path:
        return role_folder(self.tmp_path / f"out-{role}", role)

    def close(self) -> None:
        for proc in self.procs.values():
            proc.__exit__(None, None, None)


@pytest.fixture
def topology(request: pytest.FixtureRequest) -> tuple[dict[str, str], str]:
    return getattr(request, "param", THREE_HOSTS)


@pytest.fixture
def net(topology: tuple[dict[str, str], str]) -> Iterator[NetnsLab]:
    roles, _discovery = topology
    lab = NetnsLab([*dict.fromkeys(roles.values()), OUTSIDER])
    try:
        lab.create()
        yield lab
    finally:
        errors = lab.remove()
        left = existing_namespaces(lab.tag)
        assert not errors and not left, (errors, left)


def run_lab(tmp_path: Path, net: NetnsLab, session_tag: str, options: list[str], during: Any = None,
            topology: tuple[dict[str, str], str] = THREE_HOSTS) -> tuple[Lab, dict[str, int]]:
    """Start the three roles, run ``during(lab)`` once the session runs, wait for every role's end."""
    roles, discovery = topology
    with lab_domain() as domain:
        lab_file = write_lab(tmp_path / "lab.yaml", net, domain, f"SIM{session_tag}", roles, discovery)
        routine = short_routine(tmp_path, FOUR_AND_A_HALF_MINUTES)
        lab = Lab(tmp_path, net, lab_file, [*routine, "--speed", "10", *options], roles, domain)
        try:
            station = lab.procs["station"]
            wait_until(lambda: "[session] system ready" in station.output or station.proc.poll() is not None,
                       STARTUP, lambda: f"the station to start the session\n{lab.all_output()}")
            assert "[session] system ready" in station.output, lab.all_output()
            if during is not None:
                during(lab)
            codes = {"station": station.wait(SESSION)}
            # The other hosts end on their own: the station's latched end of the session reaches them.
            for role in ("robot", "sensor"):
                codes[role] = lab.procs[role].wait(180)
        finally:
            lab.close()
    return lab, codes


def check_every_strap_sample_in_the_bag(bag: Path) -> dict[str, list]:
    messages = bag_messages(bag)
    assert not [e for e in messages[topics.SESSION_EVENTS] if e["event"] == "receiver_gap"]
    for topic, rate in RECEIVERS.values():
        stamps = np.concatenate(messages[topic])
        assert len(stamps) > 100 * rate, (topic, len(stamps))  # minutes of the strap, not a trickle
        try:
            # The station adds LSL's clock correction to the strap's stamps; under load one estimate
            # can differ from the last by more than 1 % of the ECG's period (77 us at 130 Hz): a
            # quarter period still tells every sample from its neighbours.
            assert check_counter(stamps, rate, [], off_grid=0.25) == 0
        except AssertionError as exc:
            summary = json.loads((bag.parent / "summary.json").read_text())
            raise AssertionError(f"{topic}: {exc}\nreceivers: {summary['session'].get('receivers')}\n"
                                 f"restarts: {summary.get('restarts')}") from None
    return messages


def check_the_labs_settings(lab: Lab, topology: tuple[dict[str, str], str], outsider: dict[str, list[str]],
                            outages: int) -> Path:
    """What every lab test checks: each host up and ended by the station, each summary, the ROS and LSL
    settings the lab file gave, what an outsider on the network sees. Returns the station's folder."""
    roles, discovery = topology
    address = {role: lab.net.address(host) for role, host in roles.items()}
    station_out = lab.output("station")
    for role in ("sensor", "robot"):
        assert f"[lab] {role} host {roles[role]} ({address[role]}) is up:" in station_out, station_out
        assert "[lab] the station's session has ended" in lab.output(role), lab.output(role)
        summary = json.loads((lab.folder(role) / "summary.json").read_text())
        assert summary["outcome"] == "finished" and summary["address"] == address[role]
    lab_topics = {topics.COACH_STATE, topics.QT_COMMANDS, topics.POLAR_H10_HR}
    if discovery == "peers":  # not in the lab file: ordinary discovery finds nothing of it
        assert not lab_topics & set(outsider["topics"]), outsider
    else:  # subnet discovery: multicast on the subnet, so a host on it does see the lab's ROS topics
        assert {topics.COACH_STATE, topics.POLAR_H10_HR} <= set(outsider["topics"]), outsider
    # An LSL tool on the network (the default session id) does not list the lab's strap.
    assert not [s for s in outsider["streams"] if "PolarH10" in s], outsider

    folder = session_folder(station_out)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["outcome"] == "finished", lab.all_output()  # the coach carried on to the routine's end
    assert set(summary["nodes"]) == {"physio_recorder", "hr_receiver", "ecg_receiver", "neurokit_processor",
                                     "qt_physio_coach"}  # the station's share only
    ros = summary["lab"]["ros"]
    assert ros["ROS_AUTOMATIC_DISCOVERY_RANGE"] == ("LOCALHOST" if discovery == "peers" else "SUBNET")
    others = {address["robot"], address["sensor"]} - {address["station"]}
    assert sorted(ros["ROS_STATIC_PEERS"].split(";")) == sorted(others)
    assert len(summary["lab"]["outages"]) == outages, summary["lab"]["outages"]
    assert set(summary["lab"]["clock_offsets"]["wall_offset_upper_bound_s"]) == {"sensor", "robot"}
    # The receivers applied LSL's time correction (about 0 here: namespaces share the kernel's clock).
    corrections = summary["lab"]["clock_offsets"]["lsl_time_correction"]
    assert set(corrections) == {"hr_receiver", "ecg_receiver"}
    for correction in corrections.values():
        assert correction["applied"] is True and correction["measurements"] >= 1, corrections
        assert abs(correction["offset_s"]) < 0.05, corrections
    cfg = (folder / "lsl_api.cfg").read_text()
    assert f"ResolveScope = {'machine' if discovery == 'peers' else 'link'}" in cfg
    assert address["sensor"] in cfg
    assert (folder / "report.json").is_file() and (folder / "report.html").is_file()
    return folder


def test_a_session_across_the_lab_gets_every_strap_sample_and_drives_the_robot_host(
        tmp_path: Path, net: NetnsLab, session_tag: str) -> None:
    outsider: dict[str, list[str]] = {}

    def look_from_outside(lab: Lab) -> None:
        outsider.update(probe_as_outsider(tmp_path, net, lab.domain, 10.0))

    started = time.monotonic()
    lab, codes = run_lab(tmp_path, net, session_tag, [], look_from_outside, THREE_HOSTS)
    print(f"lab session across namespaces: {time.monotonic() - started:.0f} s of wall time")
    assert codes == {"station": 0, "robot": 0, "sensor": 0}, lab.all_output()
    assert "unreachable" not in lab.output("station"), lab.output("station")
    folder = check_the_labs_settings(lab, THREE_HOSTS, outsider, outages=0)

    check_every_strap_sample_in_the_bag(folder / "bag")
    wanted = {topics.QT_COMMANDS, topics.QT_REPLIES, topics.QT_MOCK_EVENTS, topics.AUDIO_STATUS}
    recorded = string_messages(folder / "bag", wanted)
    commands = [text for topic, _ns, text in recorded if topic == topics.QT_COMMANDS]
    replies = [json.loads(text) for topic, _ns, text in recorded if topic == topics.QT_REPLIES]
    performed = [text for topic, _ns, text in recorded if topic == topics.QT_MOCK_EVENTS]
    assert len(commands) >= 10, commands
    # Every command crossed to the robot host and its answer came back (qt_controller runs there only).
    assert len(replies) == len(commands), (len(replies), len(commands))
    assert len(performed) >= len(commands) // 2, (len(performed), len(commands))
    robot_logs = lab.folder("robot") / "logs"
    assert (robot_logs / "qt_controller.log").is_file() and (robot_logs / "mock_qt_robot.log").is_file()


@pytest.mark.parametrize("topology", [TWO_HOSTS_SUBNET], indirect=True, ids=["two-hosts-subnet"])
def test_the_robot_host_unplugged_for_10_s_the_coach_carries_on_and_the_outage_is_recorded(
        tmp_path: Path, net: NetnsLab, session_tag: str, topology: tuple[dict[str, str], str]) -> None:
    outage: dict[str, float] = {}
    outsider: dict[str, list[str]] = {}

    def unplug(lab: Lab) -> None:
        station = lab.procs["station"]
        wait_until(lambda: "calibration" in station.output, 120, "the routine to run")
        # An outsider on the network looks meanwhile (the lab's other hosts are still there to see).
        look = threading.Thread(target=lambda: outsider.update(probe_as_outsider(tmp_path, net, lab.domain,
                                                                                  10.0)))
        look.start()
        outage["down"] = time.monotonic()
        net.link("robot", up=False)
        try:
            wait_until(lambda: "robot host robot" in station.output and "is unreachable" in station.output,
                       OUTAGE + 20, lambda: f"the station to miss the robot host\n{station.output}")
            remaining = OUTAGE - (time.monotonic() - outage["down"])
            if remaining > 0:
                time.sleep(remaining)  # the outage's length is the test's input, not a wait for anything
        finally:
            net.link("robot", up=True)
            outage["up"] = time.monotonic()
        wait_until(lambda: "is back after" in station.output, 120,
                   lambda: f"the station to hear the robot host again\n{station.output}")
        look.join(180)

    lab, codes = run_lab(tmp_path, net, session_tag, [], during=unplug, topology=topology)
    assert outage["up"] - outage["down"] >= OUTAGE
    assert codes == {"station": 0, "robot": 0, "sensor": 0}, lab.all_output()
    folder = check_the_labs_settings(lab, topology, outsider, outages=1)
    summary = json.loads((folder / "summary.json").read_text())
    (gone,) = summary["lab"]["outages"]
    assert gone["role"] == "robot" and gone["back_t"] > gone["unreachable_t"]
    assert gone["down_wall_s"] >= OUTAGE - 1, gone

    recorded = string_messages(folder / "bag", {topics.SESSION_EVENTS, topics.QT_MOCK_EVENTS,
                                                topics.QT_REPLIES})
    events = [(ns, json.loads(text)) for topic, ns, text in recorded if topic == topics.SESSION_EVENTS]
    (lost_ns, lost), = [(ns, e) for ns, e in events if e["event"] == "host_unreachable"]
    (back_ns, back), = [(ns, e) for ns, e in events if e["event"] == "host_back"]
    assert lost["role"] == back["role"] == "robot" and back_ns > lost_ns
    # The robot side came back: it performed and answered commands after the outage.
    assert [ns for topic, ns, _ in recorded if topic == topics.QT_MOCK_EVENTS and ns > back_ns]
    assert [ns for topic, ns, _ in recorded if topic == topics.QT_REPLIES and ns > back_ns]
    # The strap was never cut off: every HR and ECG sample is in the bag.
    check_every_strap_sample_in_the_bag(folder / "bag")
    report = json.loads((folder / "report.json").read_text())
    shown = [e["event"] for e in report["session_events"]]
    assert "host_unreachable" in shown and "host_back" in shown, report["session_events"]


def test_the_namespace_lab_is_removed_after_a_failure_and_after_a_half_made_lab() -> None:
    net = NetnsLab(["a", "b"])
    with pytest.raises(RuntimeError, match="a test failing inside the lab"), net:
        assert len(existing_namespaces(net.tag)) == 3  # the switch and the two hosts
        raise RuntimeError("a test failing inside the lab")
    assert existing_namespaces(net.tag) == []
    half = NetnsLab(["a", "no/such"])  # the second host's namespace cannot be made
    with pytest.raises(subprocess.CalledProcessError), half:
        pass
    assert half.made == [] and existing_namespaces(half.tag) == []

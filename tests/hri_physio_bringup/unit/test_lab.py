"""A lab of several hosts: the lab file, the discovery and LSL configuration each role gets, the
domain claim of a lab's roles, the station's watch over the other hosts, each role's nodes (no ROS)."""

from __future__ import annotations

import configparser
import json
from datetime import datetime
from pathlib import Path

import pytest
import yaml

from hri_physio_bridge.config import ConfigError
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.hosts import HostWatch, heartbeat, parse_heartbeat
from hri_physio_bringup.isolation import DomainInUse, claim_domain, claim_lab_domain
from hri_physio_bringup.lab import (
    ROLES,
    LabError,
    dds_ports,
    describe,
    load_lab,
    lsl_config,
    parse_lab,
    ros_environment,
)
from hri_physio_bringup.options import SessionConfig
from hri_physio_bringup.plan import (
    AUDIO,
    COACH,
    CONTROLLER,
    ECG_RECEIVER,
    HR_RECEIVER,
    MOCK,
    PARTICIPANT,
    POLAR_STREAMER,
    PROCESSOR,
    RECORDER,
    VIDEO,
    for_role,
    listener_role,
    plan_session,
)

THREE = {"lab": "thesis", "ros_domain": 42, "device_id": "SIMLAB1",
         "hosts": {"laptop": "192.168.50.10", "robot-pc": "192.168.50.11", "station": "192.168.50.12"},
         "roles": {"sensor": "laptop", "robot": "robot-pc", "station": "station"}}


def lab_file(tmp_path: Path, data: object, name: str = "lab.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def read_cfg(text: str) -> configparser.ConfigParser:
    cfg = configparser.ConfigParser()
    cfg.read_string(text)
    return cfg


def known_peers(cfg: configparser.ConfigParser) -> list[str]:
    value = cfg["lab"]["KnownPeers"].strip()
    assert value.startswith("{") and value.endswith("}"), value  # liblsl's list syntax
    return [p.strip() for p in value[1:-1].split(",") if p.strip()]


def test_a_lab_file_is_read_with_its_hosts_roles_and_defaults(tmp_path: Path) -> None:
    lab = load_lab(lab_file(tmp_path, {k: v for k, v in THREE.items() if k != "device_id"}))
    assert lab.lab == "thesis" and lab.ros_domain == 42 and lab.discovery == "peers"
    assert lab.device_id == "SIMLAB"
    assert lab.address_of("robot") == "192.168.50.11" and lab.host_of("sensor") == "laptop"
    assert lab.peers("station") == ["192.168.50.10", "192.168.50.11"]


@pytest.mark.parametrize("role", ROLES)
def test_each_role_reaches_exactly_the_other_hosts_by_ros_static_peers(role: str) -> None:
    lab = parse_lab(THREE)
    env = ros_environment(lab, role)
    own = lab.address_of(role)
    others = sorted(set(THREE["hosts"].values()) - {own})
    assert env["ROS_DOMAIN_ID"] == "42"
    # Multicast discovery stays on the host; the lab's other hosts are reached by unicast only.
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert sorted(env["ROS_STATIC_PEERS"].split(";")) == others


@pytest.mark.parametrize("role", ROLES)
def test_each_role_gets_an_lsl_config_resolving_on_its_host_and_asking_the_lab_hosts(role: str) -> None:
    lab = parse_lab(THREE)
    cfg = read_cfg(lsl_config(lab, role))
    assert cfg["multicast"]["ResolveScope"] == "machine"
    assert sorted(known_peers(cfg)) == sorted(set(THREE["hosts"].values()) - {lab.address_of(role)})
    assert int(cfg["ports"]["BasePort"]) == 16572 and int(cfg["ports"]["PortRange"]) >= 16
    assert cfg["lab"]["SessionID"] == "hri-physio-thesis"  # the same on every host of the lab


def test_subnet_discovery_is_opt_in_and_widens_both_ros_and_lsl() -> None:
    lab = parse_lab({**THREE, "discovery": "subnet"})
    assert ros_environment(lab, "station")["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert read_cfg(lsl_config(lab, "station"))["multicast"]["ResolveScope"] == "link"
    assert "the subnet" in describe(lab, "station")


def test_two_roles_on_one_host_are_not_each_others_peers_and_unused_hosts_are_nobodys() -> None:
    lab = parse_lab({**THREE, "hosts": {**THREE["hosts"], "spare": "192.168.50.99"},
                     "roles": {"sensor": "laptop", "robot": "station", "station": "station"}})
    assert lab.peers("station") == ["192.168.50.10"]
    assert lab.peers("robot") == ["192.168.50.10"]
    assert lab.peers("sensor") == ["192.168.50.12"]
    assert known_peers(read_cfg(lsl_config(lab, "sensor"))) == ["192.168.50.12"]
    assert lab.roles_on("station") == ["robot", "station"]


def test_the_packaged_example_lab_file_is_valid() -> None:
    from helpers import ROOT

    lab = load_lab(ROOT / "config" / "lab.example.yaml")
    assert set(lab.roles) == set(ROLES)


@pytest.mark.parametrize(("data", "expected"), [
    ({**THREE, "ros_domain": 500}, "ros_domain: Input should be less than or equal to 232"),
    ({k: v for k, v in THREE.items() if k != "ros_domain"}, "ros_domain: missing"),
    ({**THREE, "roles": {"sensor": "laptop", "robot": "robot-pc"}},
     "every role needs a host, missing station"),
    ({**THREE, "roles": {**THREE["roles"], "robot": "nao"}},
     "robot runs on 'nao', which is not among the hosts"),
    ({**THREE, "roles": {**THREE["roles"], "tablet": "laptop"}}, "roles.tablet"),
    ({**THREE, "hosts": {**THREE["hosts"], "robot-pc": "192.168.50.10"}},
     "have the same address 192.168.50.10"),
    ({**THREE, "hosts": {**THREE["hosts"], "laptop": "300.1.1.1"}}, "laptop: an IPv4 address or a host name"),
    ({**THREE, "discovery": "everywhere"}, "discovery: Input should be 'peers' or 'subnet'"),
    ({**THREE, "device_id": "a b"}, "device_id: letters, digits"),
    ({**THREE, "rosdomain": 3}, "rosdomain: not a lab file key"),
    ([1, 2], "expected a mapping of lab keys, got list"),
])
def test_a_bad_lab_file_is_one_line_naming_the_file_and_the_field(tmp_path: Path, data: object,
                                                                    expected: str) -> None:
    path = lab_file(tmp_path, data)
    with pytest.raises(LabError) as err:
        load_lab(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"lab file {path}: "), message
    assert expected in message, message


def test_a_lab_file_that_is_not_yaml_or_is_missing_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(LabError, match=r"not valid YAML \(line 3\)"):
        load_lab(lab_file(tmp_path, "lab: x\nhosts: {a: 1\n  b: 2}\n"))
    with pytest.raises(LabError, match="No such file"):
        load_lab(tmp_path / "nowhere.yaml")


def test_the_dds_ports_of_a_domain_for_a_firewall_rule() -> None:
    assert dds_ports(0) == (7400, 7649)
    assert dds_ports(42) == (17900, 18149)


def test_the_roles_of_one_lab_share_its_domain_a_role_runs_once_and_a_session_cannot_take_it(
        tmp_path: Path) -> None:
    sensor = claim_lab_domain(42, "sensor", {"pid": 1, "role": "lab thesis sensor"}, tmp_path)
    robot = claim_lab_domain(42, "robot", {"pid": 2, "role": "lab thesis robot"}, tmp_path)
    try:
        with pytest.raises(DomainInUse, match="the lab's robot role \\(ROS domain 42\\) already runs"):
            claim_lab_domain(42, "robot", {"pid": 3}, tmp_path)
        with pytest.raises(DomainInUse, match=r"ROS domain 42 .* is in use by another lab thesis robot"):
            claim_domain(42, {"pid": 4}, tmp_path)
        picked = claim_domain(None, {"pid": 5}, tmp_path, candidates=[41, 42, 43])
        assert picked.domain in (41, 43)
        picked.release()
    finally:
        sensor.release()
        robot.release()
    claim_domain(42, {"pid": 6}, tmp_path).release()  # free again once the lab's roles end


def test_a_lab_role_is_refused_while_a_single_host_session_holds_the_domain(tmp_path: Path) -> None:
    session = claim_domain(42, {"pid": 7, "started": "now", "folder": "f", "role": "session"}, tmp_path)
    try:
        with pytest.raises(DomainInUse, match=r"ros_domain\) is in use by another session \(pid 7"):
            claim_lab_domain(42, "station", {"pid": 8}, tmp_path)
    finally:
        session.release()
    # Refused without keeping anything: the role's lock was let go, so the role can start now.
    claim_lab_domain(42, "station", {"pid": 9}, tmp_path).release()


def test_the_station_says_when_each_host_is_up_unreachable_and_back() -> None:
    lab = parse_lab(THREE)
    watch = HostWatch(lab, timeout=4.0)
    assert sorted(watch.waiting_for()) == ["robot host robot-pc (192.168.50.11)",
                                           "sensor host laptop (192.168.50.10)"]
    robot = parse_heartbeat(heartbeat(lab, "robot", {MOCK: True, CONTROLLER: True}, 1000.0), lab)
    sensor = parse_heartbeat(heartbeat(lab, "sensor", {PARTICIPANT: True}, 1000.0), lab)
    assert robot is not None and sensor is not None
    [(line, event)] = watch.heard(robot, wall=10.0, t=0.0)
    assert line == "[lab] robot host robot-pc (192.168.50.11) is up: mock_qt_robot, qt_controller"
    assert event is None and not watch.all_up()
    assert watch.heard(robot, wall=10.5, t=0.0) == []  # said once
    watch.heard(sensor, wall=11.0, t=0.0)
    assert watch.all_up()
    for wall in (11.5, 12.0, 12.5, 13.0, 13.5, 14.0, 14.5):  # the sensor keeps beating, the robot is gone
        watch.heard(sensor, wall=wall, t=wall)
        assert watch.check(wall, t=wall) == []
    [(line, event)] = watch.check(14.6, t=20.0)
    assert "robot host robot-pc (192.168.50.11) is unreachable" in line
    assert event == {"t": 20.0, "event": "host_unreachable", "node": "robot host robot-pc (192.168.50.11)",
                     "role": "robot", "host": "robot-pc", "reason": "no heartbeat for 4 s of wall time"}
    watch.heard(sensor, wall=17.0, t=25.0)
    assert watch.check(18.0, t=30.0) == []  # said once
    [(line, event)] = watch.heard(robot, wall=25.0, t=45.0)
    assert line.startswith("[lab] robot host robot-pc (192.168.50.11) is back after 14.4 s of wall time")
    assert event is not None and event["event"] == "host_back" and event["down_s"] == 25.0
    assert watch.outages == [{"role": "robot", "host": "robot-pc", "address": "192.168.50.11",
                              "unreachable_t": 20.0, "back_t": 45.0, "down_wall_s": 14.4}]
    assert watch.report()["robot"]["up_at_end"] is True


def test_heartbeats_of_another_lab_or_not_json_are_ignored() -> None:
    lab = parse_lab(THREE)
    other = parse_lab({**THREE, "lab": "other"})
    assert parse_heartbeat(heartbeat(other, "robot", {}, 1.0), lab) is None
    assert parse_heartbeat("not json", lab) is None
    assert parse_heartbeat(json.dumps({"lab": "thesis", "role": "tablet", "nodes": {}}), lab) is None


def plan_of(tmp_path: Path, **options):
    opts = SessionConfig.from_mapping(options, "test")
    folder = SessionFolder.plan(tmp_path / "sessions", "P-1", datetime(2026, 5, 4, 10, 30))
    return plan_session(opts, folder, "SIMLAB1")


def test_each_role_runs_its_share_of_the_nodes_and_together_they_run_them_all(tmp_path: Path) -> None:
    whole = plan_of(tmp_path)
    shares = {role: [n.name for n in for_role(whole, role).nodes] for role in ROLES}
    assert shares == {"sensor": [PARTICIPANT], "robot": [MOCK, CONTROLLER, AUDIO, VIDEO],
                      "station": [RECORDER, HR_RECEIVER, ECG_RECEIVER, PROCESSOR, COACH]}
    assert sorted(n for share in shares.values() for n in share) == sorted(n.name for n in whole.nodes)
    # The station still waits for every host's nodes to listen before it starts the session.
    station = for_role(whole, "station")
    assert station.listeners == whole.listeners
    assert {listener_role(node) for _topic, node in station.listeners} == set(ROLES)
    polar = plan_of(tmp_path, source="polar:0A1B2C3D")
    assert [n.name for n in for_role(polar, "sensor").nodes] == [POLAR_STREAMER]


def test_in_a_lab_the_receivers_apply_lsl_time_correction(tmp_path: Path) -> None:
    """The strap's samples come from the sensor host's LSL clock: the station's receivers add liblsl's
    time correction (?sync=1); on one host they keep the stamps as they are."""
    lab_file = tmp_path / "lab.yaml"
    lab_file.write_text("any: file\n")  # plan_session does not read it
    for options, query in (({}, ""), ({"lab": str(lab_file), "role": "station"}, "?sync=1")):
        plan = plan_of(tmp_path, **options)
        assert plan.node(HR_RECEIVER).config.input == f"lsl:PolarH10/SIMLAB1/HR{query}"
        assert plan.node(ECG_RECEIVER).config.input == f"lsl:PolarH10/SIMLAB1/ECG{query}"


@pytest.mark.parametrize(("options", "expected"), [
    ({"role": "robot"}, "needs both --lab <lab file> and --role"),
    ({"lab": "lab.yaml"}, "--lab needs --role sensor|robot|station"),
    ({"lab": "nowhere.yaml", "role": "robot"}, "lab: nowhere.yaml does not exist"),
])
def test_lab_options_go_together(options: dict, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected.replace("|", "\\|")):
        SessionConfig.from_mapping(options, "command line")


def test_a_bad_lab_file_ends_the_launcher_with_one_line_before_anything_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hri_physio_bringup.session import main

    path = lab_file(tmp_path, {**THREE, "roles": {"sensor": "laptop"}})
    code = main(["--lab", str(path), "--role", "robot", "--out", str(tmp_path / "sessions")])
    assert code == 2
    assert capsys.readouterr().err.strip() == (
        f"hri_physio_session: error: lab file {path}: roles: every role needs a host, missing robot, station")
    assert not (tmp_path / "sessions").exists()

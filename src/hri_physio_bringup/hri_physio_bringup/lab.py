"""A lab of several computers: the lab file, each host's role, and the discovery it opens (no rclpy).

A lab file (YAML) names the hosts and which role each plays::

    lab: thesis-lab
    ros_domain: 42                 # the same ROS domain on every host of the lab
    discovery: peers               # peers (default): ROS 2 finds only the hosts named here
                                   # subnet: the whole subnet (multicast), for labs that need it
    device_id: SIMLAB              # the strap's id in the LSL stream names (simulated strap)
    hosts:                         # name: IPv4 address (or a resolvable host name)
      laptop: 192.168.50.10
      robot-pc: 192.168.50.11
      station: 192.168.50.12
    roles:                         # role: the host that runs it (two roles may share a host)
      sensor: laptop
      robot: robot-pc
      station: station

``hri_physio_session --lab lab.yaml --role sensor|robot|station`` then runs one host's part:

* **sensor**: the strap side (the simulated participant, or ``polar_streamer``), publishing on LSL;
* **robot**: ``qt_controller``, ``mock_qt_robot``, ``audio_streamer``, ``video_streamer``;
* **station**: the receivers, the processor, the coach, the recorder, and the session's clock.

Discovery is opened only as far as the lab file says, and only for a command given ``--lab``:
without it nothing changes (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, LSL ``ResolveScope =
machine``). With ``discovery: peers`` ROS 2 keeps its multicast discovery on the host and reaches
the other hosts of the lab by unicast (``ROS_STATIC_PEERS``); LSL keeps its multicast on the host
and asks the lab's other hosts directly (``KnownPeers`` in a generated ``lsl_api.cfg``, with a
``SessionID`` of the lab's own so that LSL tools elsewhere on the network do not list its streams). With
``discovery: subnet`` both also use multicast on the local subnet (ROS ``SUBNET``, LSL ``link``).
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

ROLES = ("sensor", "robot", "station")
Role = Literal["sensor", "robot", "station"]
#: liblsl's first port and the range a lab's generated configuration gives (2 ports per outlet).
LSL_BASE_PORT = 16572
LSL_PORT_RANGE = 128
#: Fast DDS's ports for a domain (RTPS well-known ports: 7400 + 250 * domain, +2 participant ids).
DDS_PORT_BASE, DDS_DOMAIN_GAIN = 7400, 250
_HOST_NAME = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})")
_LAB_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


class LabError(ValueError):
    """A lab file that cannot be used (the message is one line naming the file and the field)."""


class Lab(BaseModel):
    """A lab file, checked."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    lab: str = Field("lab", description="the lab's name (in folder names and console lines)")
    ros_domain: int = Field(ge=0, le=232, description="the ROS domain every host of the lab uses")
    discovery: Literal["peers", "subnet"] = "peers"
    device_id: str = Field("SIMLAB", description="the strap's id in the LSL stream names")
    hosts: dict[str, str]
    roles: dict[Role, str]

    @field_validator("lab")
    @classmethod
    def _lab_name(cls, value: str) -> str:
        if not _LAB_NAME.fullmatch(value):
            raise ValueError(f"letters, digits, '_', '.', '-' (up to 64), got {value!r}")
        return value

    @field_validator("device_id")
    @classmethod
    def _device(cls, value: str) -> str:
        if not value or not value.replace("-", "").replace("_", "").isalnum():
            raise ValueError(f"letters, digits, '-' and '_' only, got {value!r}")
        return value

    @field_validator("hosts")
    @classmethod
    def _hosts(cls, value: dict[str, str]) -> dict[str, str]:
        if not value:
            raise ValueError("name at least one host")
        addresses: dict[str, str] = {}
        for name, address in value.items():
            address = str(address).strip()
            if not _valid_address(address):
                raise ValueError(f"{name}: an IPv4 address or a host name, got {address!r}")
            if address in addresses:
                raise ValueError(f"{name} and {addresses[address]} have the same address {address}")
            addresses[address] = name
        return {name: str(address).strip() for name, address in value.items()}

    @model_validator(mode="after")
    def _roles(self) -> Lab:
        missing = [role for role in ROLES if role not in self.roles]
        if missing:
            raise ValueError(f"roles: every role needs a host, missing {', '.join(missing)}")
        for role, host in self.roles.items():
            if host not in self.hosts:
                raise ValueError(f"roles: {role} runs on {host!r}, which is not among the hosts "
                                 f"({', '.join(self.hosts)})")
        return self

    def host_of(self, role: str) -> str:
        return self.roles[role]  # type: ignore[index]

    def address_of(self, role: str) -> str:
        return self.hosts[self.host_of(role)]

    def peers(self, role: str) -> list[str]:
        """The addresses of the lab's other hosts, as seen from ``role``'s host (its own left out)."""
        own = self.host_of(role)
        used = set(self.roles.values())
        return [address for name, address in self.hosts.items() if name != own and name in used]

    def roles_on(self, host: str) -> list[str]:
        return [role for role in ROLES if self.roles.get(role) == host]  # type: ignore[call-overload]


def _valid_address(text: str) -> bool:
    try:
        return isinstance(ipaddress.ip_address(text), ipaddress.IPv4Address)
    except ValueError:
        return bool(_HOST_NAME.fullmatch(text)) and not text.replace(".", "").isdigit()


def _first_problem(exc: ValidationError) -> str:
    error = exc.errors()[0]
    where = ".".join(str(p) for p in error["loc"])
    message = str(error["msg"]).removeprefix("Value error, ")
    if error["type"] == "missing":
        message = "missing"
    elif error["type"] == "extra_forbidden":
        message = f"not a lab file key (keys: {', '.join(Lab.model_fields)})"
    return f"{where}: {message}" if where else message


def parse_lab(data: Any, source: str = "lab file") -> Lab:
    """A lab from parsed YAML (raises :class:`LabError` with one line)."""
    if not isinstance(data, dict):
        raise LabError(f"{source}: expected a mapping of lab keys, got {type(data).__name__}")
    try:
        return Lab.model_validate(data)
    except ValidationError as exc:
        raise LabError(f"{source}: {_first_problem(exc)}") from None


def load_lab(path: Path | str) -> Lab:
    """Read and check a lab file (raises :class:`LabError` with one line)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise LabError(f"lab file {path}: {exc.strerror or exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "not YAML"
        raise LabError(f"lab file {path}: not valid YAML{where}: {problem}") from None
    return parse_lab(data, f"lab file {path}")


def ros_environment(lab: Lab, role: str) -> dict[str, str]:
    """The ROS 2 variables for ``role``'s processes: the lab's domain, discovery reaching its hosts only."""
    peers = lab.peers(role)
    return {
        "ROS_DOMAIN_ID": str(lab.ros_domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET" if lab.discovery == "subnet" else "LOCALHOST",
        "ROS_STATIC_PEERS": ";".join(peers),
    }


def lsl_config(lab: Lab, role: str) -> str:
    """The ``lsl_api.cfg`` for ``role``'s processes: the strap's streams resolved on the lab's hosts."""
    scope = "link" if lab.discovery == "subnet" else "machine"
    peers = ", ".join(lab.peers(role))
    return (
        f"; liblsl configuration generated by hri_physio_session for lab {lab.lab}, role {role}\n"
        f"; ({lab.host_of(role)}, {lab.address_of(role)}). LSL streams are resolved on this host and\n"
        f"; asked for on the lab's other hosts by unicast (KnownPeers)"
        f"{'; multicast reaches the local link' if scope == 'link' else ', no further'}.\n"
        "[multicast]\n"
        f"ResolveScope = {scope}\n"
        "\n; Only streams of this session id are resolved: an LSL tool elsewhere on the network (the\n"
        "; default id) does not list the lab's strap. liblsl has no access control: a firewall does that.\n"
        "[lab]\n"
        f"SessionID = {session_id(lab)}\n"
        f"KnownPeers = {{{peers}}}\n"
        "\n; Outlets take 2 ports each from BasePort on; a resolver asks each known peer on every port\n"
        "; of the range, so the lab's range is kept to what a strap host needs (64 outlets).\n"
        "[ports]\n"
        f"BasePort = {LSL_BASE_PORT}\n"
        f"PortRange = {LSL_PORT_RANGE}\n"
        "\n[log]\nlevel = -1\n"
    )


def session_id(lab: Lab) -> str:
    """The LSL session id of the lab's streams (liblsl resolves only streams of its own session id)."""
    return f"hri-physio-{lab.lab}"


def dds_ports(domain: int) -> tuple[int, int]:
    """The UDP ports Fast DDS uses for ``domain`` (first, last), for a firewall rule."""
    first = DDS_PORT_BASE + DDS_DOMAIN_GAIN * domain
    return first, first + DDS_DOMAIN_GAIN - 1


def describe(lab: Lab, role: str) -> str:
    """One line: what this host is in the lab and whom it talks to."""
    peers = lab.peers(role)
    reach = ", ".join(f"{name} {addr}" for name, addr in lab.hosts.items() if addr in peers)
    reach = reach or "no other host"
    scope = "the subnet and " if lab.discovery == "subnet" else ""
    return (f"[lab] {lab.lab}: this host is {lab.host_of(role)} ({lab.address_of(role)}), role {role}; "
            f"ROS domain {lab.ros_domain}, discovery reaches {scope}{reach}")

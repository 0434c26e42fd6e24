"""A test lab of network namespaces: a few "hosts" joined by veth pairs on a bridge (root only).

Every name is unique to the run (``hp<pid><random>``), so a run never touches another's lab, and
:meth:`NetnsLab.remove` deletes every namespace it made, whatever happened: each host's veth
pair and the bridge live inside the lab's namespaces and go with them. The bridge sits in a
namespace of its own (the "switch"), so the machine's own network is never touched; a host's
link is taken down and up on the switch's side.

Namespaces share the machine's file systems (``/tmp``, ``/dev/shm``): unlike separate computers,
processes in two of them could still meet through shared memory, so a lab test runs the DDS
middleware on UDP only (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``).
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
from dataclasses import dataclass, field

SUBNET = "10.27.0"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=30)


def unavailable_reason() -> str | None:
    """Why this machine cannot make a namespace lab (None: it can): checked by making one namespace."""
    if shutil.which("ip") is None:
        return "the 'ip' command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root (run the test as root, or in a container with CAP_SYS_ADMIN)"
    probe = f"hpprobe{secrets.token_hex(3)}"
    made = _ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"'ip netns add' is not allowed here: {made.stderr.strip() or made.returncode}"
    try:
        veth = _ip("-n", probe, "link", "add", "a0", "type", "veth", "peer", "name", "b0", check=False)
        if veth.returncode != 0:
            return f"veth pairs are not allowed here: {veth.stderr.strip()}"
        bridge = _ip("-n", probe, "link", "add", "br0", "type", "bridge", check=False)
        if bridge.returncode != 0:
            return f"bridges are not allowed here: {bridge.stderr.strip()}"
    finally:
        _ip("netns", "del", probe, check=False)
    return None


@dataclass
class NetnsLab:
    """Hosts (namespaces) with an address each on one bridged subnet; :meth:`remove` undoes it all."""

    hosts: list[str]
    tag: str = field(default_factory=lambda: f"hp{os.getpid() % 100000}{secrets.token_hex(2)}")
    made: list[str] = field(default_factory=list)  # namespaces created, in order

    @property
    def switch(self) -> str:
        return f"{self.tag}-sw"

    def namespace(self, host: str) -> str:
        return f"{self.tag}-{host}"

    def address(self, host: str) -> str:
        return f"{SUBNET}.{self.hosts.index(host) + 1}"

    def _port(self, host: str) -> str:
        return f"p{self.hosts.index(host)}"  # the host's link, on the switch's side

    def create(self) -> NetnsLab:
        _ip("netns", "add", self.switch)
        self.made.append(self.switch)
        sw = ("-n", self.switch)
        _ip(*sw, "link", "set", "lo", "up")
        _ip(*sw, "link", "add", "br0", "type", "bridge")
        _ip(*sw, "link", "set", "br0", "up")
        for host in self.hosts:
            ns = self.namespace(host)
            _ip("netns", "add", ns)
            self.made.append(ns)
            port = self._port(host)
            # Made inside the switch's namespace, then one end moved into the host's: nothing in the root's.
            _ip(*sw, "link", "add", port, "type", "veth", "peer", "name", "eth0")
            _ip(*sw, "link", "set", "eth0", "netns", ns)
            _ip(*sw, "link", "set", port, "master", "br0")
            _ip(*sw, "link", "set", port, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "addr", "add", f"{self.address(host)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "multicast", "on")
            # Multicast (DDS and LSL discovery on the host, or the subnet) leaves by the lab's link.
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
        return self

    def command(self, host: str, argv: list[str]) -> list[str]:
        """``argv`` run inside ``host``'s namespace."""
        return ["ip", "netns", "exec", self.namespace(host), *argv]

    def link(self, host: str, up: bool) -> None:
        """Take ``host``'s link down (unplugged) or up again."""
        _ip("-n", self.switch, "link", "set", self._port(host), "up" if up else "down")

    def remove(self) -> list[str]:
        """Delete every namespace this lab made (its links go with them); the errors, if any."""
        errors = []
        for ns in reversed(self.made):
            done = _ip("netns", "del", ns, check=False)
            if done.returncode != 0 and "No such file" not in done.stderr:
                errors.append(f"{ns}: {done.stderr.strip()}")
        self.made.clear()
        return errors

    def __enter__(self) -> NetnsLab:
        try:
            return self.create()
        except BaseException:
            self.remove()
            raise

    def __exit__(self, *exc: object) -> None:
        self.remove()


def existing_namespaces(tag: str) -> list[str]:
    """Namespaces whose name starts with ``tag`` (a test checks that none is left)."""
    listed = _ip("netns", "list", check=False).stdout.split("\n")
    return [line.split()[0] for line in listed if line.strip() and line.split()[0].startswith(tag)]

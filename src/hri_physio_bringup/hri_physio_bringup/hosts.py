"""Which hosts of a lab are up, as the station sees them (no rclpy; wall time passed in).

Every host of a lab other than the station runs ``hri_physio_session --role sensor|robot``, whose
launcher publishes a heartbeat on ``/lab/hosts`` every :data:`HEARTBEAT_PERIOD` seconds of wall
time (JSON: role, host, address, its nodes and whether each runs). The station's launcher feeds
each heartbeat to :class:`HostWatch`, which says when a host comes up, when it has not been heard
for :data:`HOST_TIMEOUT` seconds (``host_unreachable``: a link down, a host stopped) and when it is
heard again (``host_back``, with how long it was away). Heartbeats run on wall time, so a session
clock held for the loop never looks like a lost host.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from hri_physio_bringup.lab import Lab

HEARTBEAT_PERIOD = 0.5
#: Wall seconds without a host's heartbeat before it counts as unreachable.
HOST_TIMEOUT = 4.0
#: The event on /session/events that tells the other hosts the station's session has ended.
SESSION_ENDED = "session_ended"


def heartbeat(lab: Lab, role: str, nodes: dict[str, bool], wall: float) -> str:
    """A host launcher's heartbeat (JSON text)."""
    return json.dumps({"lab": lab.lab, "role": role, "host": lab.host_of(role),
                       "address": lab.address_of(role), "nodes": nodes, "wall": round(wall, 3)})


def parse_heartbeat(text: str, lab: Lab) -> dict[str, Any] | None:
    """A heartbeat of this lab (None: not JSON, another lab's, or a role the lab does not have)."""
    try:
        data = json.loads(text)
    except ValueError:
        return None
    if not isinstance(data, dict) or data.get("lab") != lab.lab or data.get("role") not in lab.roles:
        return None
    if not isinstance(data.get("nodes"), dict):
        return None
    return data


@dataclass
class HostState:
    role: str
    host: str
    address: str
    last_wall: float = math.nan
    up: bool = False
    nodes: dict[str, bool] = field(default_factory=dict)
    down_wall: float = math.nan  # when it was found unreachable
    down_t: float = math.nan


@dataclass
class HostWatch:
    """The station's view of the lab's other hosts."""

    lab: Lab
    own_role: str = "station"
    timeout: float = HOST_TIMEOUT
    hosts: dict[str, HostState] = field(default_factory=dict)
    outages: list[dict[str, Any]] = field(default_factory=list)  # closed and open, for summary.json

    def __post_init__(self) -> None:
        for role in self.lab.roles:
            if role != self.own_role:
                self.hosts[role] = HostState(role, self.lab.host_of(role), self.lab.address_of(role))

    def _label(self, state: HostState) -> str:
        return f"{state.role} host {state.host} ({state.address})"

    def heard(self, data: dict[str, Any], wall: float, t: float) -> list[tuple[str, dict[str, Any] | None]]:
        """A heartbeat arrived: (console line, event for /session/events or None) pairs to say."""
        state = self.hosts.get(str(data.get("role")))
        if state is None:
            return []
        state.nodes = {str(k): bool(v) for k, v in data["nodes"].items()}
        was_up, state.last_wall = state.up, wall
        if was_up:
            return []
        state.up = True
        running = ", ".join(n for n, ok in state.nodes.items() if ok) or "no node yet"
        if math.isnan(state.down_wall):
            return [(f"[lab] {self._label(state)} is up: {running}", None)]
        away_wall, away_t = wall - state.down_wall + self.timeout, t - state.down_t
        outage = self.outages[-1]
        outage.update(back_t=t, down_wall_s=round(away_wall, 3))
        state.down_wall = state.down_t = math.nan
        event = {"t": t, "event": "host_back", "node": self._label(state), "role": state.role,
                 "host": state.host, "down_s": round(away_t, 3), "down_wall_s": round(away_wall, 3)}
        line = f"[lab] {self._label(state)} is back after {away_wall:.1f} s of wall time: {running}"
        return [(line, event)]

    def check(self, wall: float, t: float) -> list[tuple[str, dict[str, Any] | None]]:
        """Hosts not heard for the timeout: (console line, event) pairs to say."""
        said = []
        for state in self.hosts.values():
            if not state.up or wall - state.last_wall <= self.timeout:
                continue
            state.up, state.down_wall, state.down_t = False, wall, t
            self.outages.append({"role": state.role, "host": state.host, "address": state.address,
                                 "unreachable_t": t, "back_t": None, "down_wall_s": None})
            event = {"t": t, "event": "host_unreachable", "node": self._label(state), "role": state.role,
                     "host": state.host, "reason": f"no heartbeat for {self.timeout:g} s of wall time"}
            said.append((f"[lab] {self._label(state)} is unreachable: no heartbeat for "
                         f"{self.timeout:g} s (the session carries on)", event))
        return said

    def all_up(self) -> bool:
        return all(state.up for state in self.hosts.values())

    def waiting_for(self) -> list[str]:
        return [self._label(s) for s in self.hosts.values() if not s.up]

    def report(self) -> dict[str, Any]:
        """What summary.json says of the lab's hosts."""
        return {role: {"host": s.host, "address": s.address, "up_at_end": s.up, "nodes": s.nodes}
                for role, s in self.hosts.items()}

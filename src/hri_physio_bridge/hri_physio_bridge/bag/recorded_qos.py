"""QoS profiles as rosbag2 stores them, and the QoS the recorder and replayer pick.

rosbag2 (metadata version 9, Jazzy) stores each publisher's offered QoS as a mapping
with policy *names* (``keep_last``, ``reliable``...) and durations as ``{sec, nsec}``.
This module is rclpy-free: it reads any object with the attributes of
``rclpy.qos.QoSProfile`` (policies as ints or IntEnums, durations with ``nanoseconds``)
and returns plain dicts; the node shells turn dicts back into ``QoSProfile``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
LIVELINESS = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown", 5: "best_available"}

#: rmw's "infinite" duration (RMW_DURATION_INFINITE), as rosbag2 writes it.
INFINITE_NS = 2**63 - 1
DURATION_KEYS = ("deadline", "lifespan", "liveliness_lease_duration")


def _duration(value: Any) -> dict[str, int]:
    ns = int(getattr(value, "nanoseconds", value))
    ns = min(max(ns, 0), INFINITE_NS)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def duration_ns(value: Mapping[str, int]) -> int:
    return int(value["sec"]) * 1_000_000_000 + int(value["nsec"])


def _name(table: dict[int, str], value: Any) -> str:
    if isinstance(value, str):
        return value.lower()
    return table.get(int(value), "unknown")


def qos_to_dict(profile: Any) -> dict[str, Any]:
    """One offered profile (rclpy ``QoSProfile``-like) as rosbag2's v9 mapping."""
    return {
        "history": _name(HISTORY, profile.history),
        "depth": int(profile.depth),
        "reliability": _name(RELIABILITY, profile.reliability),
        "durability": _name(DURABILITY, profile.durability),
        "deadline": _duration(profile.deadline),
        "lifespan": _duration(profile.lifespan),
        "liveliness": _name(LIVELINESS, profile.liveliness),
        "liveliness_lease_duration": _duration(profile.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(profile.avoid_ros_namespace_conventions),
    }


def _value(table: dict[int, str], name: str) -> int:
    for key, text in table.items():
        if text == name:
            return key
    raise ValueError(f"unknown QoS policy value {name!r}; expected one of {sorted(table.values())}")


def policy_values(profile: Mapping[str, Any]) -> dict[str, int]:
    """The integer policy values of a stored profile (for building a ``QoSProfile``)."""
    return {
        "history": _value(HISTORY, str(profile["history"])),
        "reliability": _value(RELIABILITY, str(profile["reliability"])),
        "durability": _value(DURABILITY, str(profile["durability"])),
        "liveliness": _value(LIVELINESS, str(profile["liveliness"])),
    }


def adapted_qos(offered: Iterable[Mapping[str, Any]], depth: int) -> dict[str, Any]:
    """The QoS to subscribe to (record) or publish with (replay), given the offered profiles.

    Like rosbag2: reliable only if every publisher offers reliable (a reliable subscription
    would not match a best-effort publisher), transient-local only if every publisher offers
    it (so late joiners get the latched sample). Keep-last with a deep queue so bursts fit.
    """
    offered = list(offered)  # nothing known: reliable, volatile (rclpy's default)
    reliable = all(p.get("reliability") == "reliable" for p in offered)
    latched = bool(offered) and all(p.get("durability") == "transient_local" for p in offered)
    return {
        "history": "keep_last",
        "depth": int(depth),
        "reliability": "reliable" if reliable else "best_effort",
        "durability": "transient_local" if latched else "volatile",
    }

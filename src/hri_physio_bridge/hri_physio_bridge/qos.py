"""The QoS profiles of the system's topics, defined once (node layer: imports rclpy)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def frame_qos(depth: int = 1000) -> QoSProfile:
    """Sample frames: reliable, the last ``depth`` kept for a slow subscriber."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE)


def latched_qos() -> QoSProfile:
    """State snapshots (e.g. /coach/state): the last one reaches a late subscriber."""
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def command_qos() -> QoSProfile:
    """Command and control lines: every line must arrive, also in a burst (KEEP_ALL, reliable).

    Reliable KEEP_ALL makes a fast publisher wait for a slow subscriber instead of losing lines;
    the receiving node drains them into its own queue at once.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1, reliability=ReliabilityPolicy.RELIABLE)


def event_qos(depth: int = 2000) -> QoSProfile:
    """Event and status streams (JSON Strings): reliable, deep enough for a burst of events."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE)

"""Declare a node's options as ROS parameters (defaults < YAML/CLI options < --ros-args)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node


def split_list(value: Any) -> list[str]:
    """A list option given as a YAML list or as comma-separated text."""
    if value is None:
        return []
    if isinstance(value, str):
        return [v.strip() for v in value.split(",") if v.strip()]
    return [str(v).strip() for v in value if str(v).strip()]


def declare_options(
    node: Node, defaults: Mapping[str, Any], given: Mapping[str, Any], descriptions: Mapping[str, str]
) -> dict[str, Any]:
    """Declare one parameter per option and return the effective values.

    List options are declared with dynamic typing (default: comma-separated text) so a params
    file may hold either a YAML list or a string; they come back as lists.
    """
    out: dict[str, Any] = {}
    for key, default in defaults.items():
        value = given.get(key, default)
        desc = descriptions.get(key, "")
        if isinstance(default, list):
            node.declare_parameter(
                key, ",".join(split_list(value)), ParameterDescriptor(description=desc, dynamic_typing=True)
            )
            out[key] = split_list(node.get_parameter(key).value)
        else:
            if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if type(value) is not type(default):
                raise ValueError(f"option {key} must be {type(default).__name__}, got {value!r}")
            node.declare_parameter(key, value, ParameterDescriptor(description=desc))
            out[key] = node.get_parameter(key).value
    return out

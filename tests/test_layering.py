"""The layering rule cannot be bypassed by forgetting a module: every module is classified.

Logic modules (listed in .importlinter's "logic" contract, which ``lint-imports`` in scripts/test
checks) import no ROS, LSL or BLE runtime; runtime shells (nodes, launchers, transports) are listed
here. A new module must be put in exactly one of the two.
"""

from __future__ import annotations

import configparser
import fnmatch
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Modules allowed to import rclpy / std_msgs / pylsl / bleak: thin shells around the logic.
RUNTIME_SHELLS = (
    "*.nodes", "*.nodes.*",
    "hri_physio_bridge.node_runner", "hri_physio_bridge.ros_frames", "hri_physio_bridge.ros_tools",
    "hri_physio_bridge.qos", "hri_physio_bridge.demo", "hri_physio_bridge.launcher",
    "hri_physio_bridge.streamers", "hri_physio_bridge.streamers.factory",
    "hri_physio_bridge.streamers.ros", "hri_physio_bridge.streamers.lsl",
    "hri_physio_bridge.bag", "hri_physio_bridge.bag.*",
    "hri_physio_bridge.polar", "hri_physio_bridge.polar.bleak_ble", "hri_physio_bridge.polar.lsl_output",
    "hri_physio_coach.session",
    "qt_controller.qt_robot", "qt_controller.qt_controller", "qt_controller.qt_services",
)


def _contract(name: str) -> configparser.SectionProxy:
    parser = configparser.ConfigParser()
    parser.read(ROOT / ".importlinter")
    return parser[f"importlinter:contract:{name}"]


def _modules() -> list[str]:
    found = []
    for package_dir in sorted((ROOT / "src").glob("*/*/__init__.py")):
        package = package_dir.parent
        if package.parent.name != package.name:
            continue
        for path in sorted(package.rglob("*.py")):
            parts = path.relative_to(package.parent).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if len(parts) > 1:  # the top-level package itself is only a namespace
                found.append(".".join(parts))
    return found


def test_every_module_is_logic_or_a_runtime_shell() -> None:
    logic = {line.strip() for line in _contract("logic")["source_modules"].splitlines() if line.strip()}
    roots = {line.strip() for line in _contract("packages")["layers"].replace("|", "\n").splitlines()}
    unclassified = []
    for module in _modules():
        if module.split(".")[0] not in roots:
            unclassified.append(f"{module} (its package is in no layer of the 'packages' contract)")
            continue
        in_logic = any(module == m or module.startswith(m + ".") for m in logic)
        in_shell = any(fnmatch.fnmatch(module, p) for p in RUNTIME_SHELLS)
        if in_logic == in_shell:
            where = "both lists" if in_logic else "neither list"
            unclassified.append(f"{module} ({where})")
    assert not unclassified, (
        "classify each module once: logic -> .importlinter [logic] source_modules, runtime shell -> "
        "RUNTIME_SHELLS in this file:\n  " + "\n  ".join(unclassified)
    )

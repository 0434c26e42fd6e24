"""Every package is a valid ament_python package: what colcon installs is declared in its setup.cfg.

``ros2 run`` and the ament index find a package by its ``resource/<name>`` marker and its
package.xml under share/, and its console scripts under lib/<name>/. Editable installs (as here)
do not install data files, so this reads what a full ROS 2 build would install.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from glob import glob
from pathlib import Path

import pytest
from setuptools.config.setupcfg import read_configuration

from helpers import ROOT

PACKAGES = sorted(p.parent.name for p in ROOT.glob("src/*/package.xml"))


def test_every_package_directory_is_a_package() -> None:
    assert sorted(p.parent.name for p in ROOT.glob("src/*/setup.cfg")) == PACKAGES
    assert len(PACKAGES) >= 5


@pytest.mark.parametrize("name", PACKAGES)
def test_setup_cfg_declares_what_ament_needs(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = ROOT / "src" / name
    monkeypatch.chdir(pkg)  # setup.cfg paths and globs are relative to the package, as for colcon
    config = read_configuration(pkg / "setup.cfg")
    assert config["metadata"]["name"] == name
    assert ET.parse(pkg / "package.xml").getroot().findtext("name") == name
    assert ET.parse(pkg / "package.xml").getroot().findtext("export/build_type") == "ament_python"
    data = {dest: [f for pattern in files for f in (glob(pattern) or [pattern])]
            for dest, files in config["options"]["data_files"]}
    assert data["share/ament_index/resource_index/packages"] == [f"resource/{name}"]
    assert set(data[f"share/{name}"]) >= {"package.xml", "README.md"}
    for files in data.values():
        for f in files:
            assert (pkg / f).is_file(), f"{name}: setup.cfg installs {f}, which does not exist"
    assert (pkg / name / "__init__.py").is_file()
    assert name in config["options"]["packages"]
    scripts = config["options"]["entry_points"]["console_scripts"]
    assert scripts and all(f"= {name}." in line for line in scripts), scripts
    assert "lib/" + name in (pkg / "setup.cfg").read_text()  # ros2 run looks for scripts in lib/<name>


#: The rosdep key of every third-party module the packages import (pip-only ones end in -pip).
ROSDEP_KEYS = {
    "rclpy": "rclpy", "std_msgs": "std_msgs", "std_srvs": "std_srvs", "sensor_msgs": "sensor_msgs",
    "rosgraph_msgs": "rosgraph_msgs", "rcl_interfaces": "rcl_interfaces",
    "builtin_interfaces": "builtin_interfaces", "ament_index_python": "ament_index_python",
    "numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml", "pandas": "python3-pandas",
    "psutil": "python3-psutil", "pydantic": "python3-pydantic", "matplotlib": "python3-matplotlib",
    "cv2": "python3-opencv", "soundfile": "python3-soundfile", "zstandard": "python3-zstandard",
    "tqdm": "python3-tqdm", "dask": "python3-dask", "distributed": "python3-distributed",
    "pylsl": "python3-pylsl-pip", "neurokit2": "python3-neurokit2-pip", "bleak": "python3-bleak-pip",
    "rosbags": "python3-rosbags-pip", "mcap": "python3-mcap-pip", "wfdb": "python3-wfdb-pip",
    "rich": "python3-rich-pip", "sounddevice": "python3-sounddevice-pip", "librosa": "python3-librosa-pip",
    "foxglove": "python3-foxglove-sdk-pip",
}


def _imported_top_modules(package: Path) -> set[str]:
    """Every top-level module a package's code imports: at module level, inside functions, or by
    ``importlib.import_module("name")`` (a runtime loaded only when used, e.g. the sound card's)."""
    import ast

    found: set[str] = set()
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr == "import_module" and node.args
                  and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
                found.add(node.args[0].value.split(".")[0])
    return found


@pytest.mark.parametrize("name", PACKAGES)
def test_package_xml_lists_every_import_and_nothing_else(name: str) -> None:
    import sys

    pkg = ROOT / "src" / name
    imported = _imported_top_modules(pkg / name) - set(sys.stdlib_module_names) - {name, "__future__"}
    unknown = sorted(m for m in imported if m not in ROSDEP_KEYS and m not in PACKAGES)
    assert not unknown, f"{name} imports {unknown}: add their rosdep keys to ROSDEP_KEYS and to package.xml"
    needed = {m if m in PACKAGES else ROSDEP_KEYS[m] for m in imported}
    root = ET.parse(pkg / "package.xml").getroot()
    declared = {e.text for e in root.findall("exec_depend")} | {e.text for e in root.findall("depend")}
    assert not needed - declared, f"{name}/package.xml lacks {sorted(needed - declared)}"
    unused = sorted(declared - needed)
    assert not unused, f"{name}/package.xml declares {unused}, which it never imports"

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

ROOT = Path(__file__).resolve().parents[1]
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

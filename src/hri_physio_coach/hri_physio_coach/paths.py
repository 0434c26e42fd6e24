"""Where the packaged configuration lives: next to the package (source or editable install)
or in the ament share directory (a colcon install on a full ROS 2)."""

from __future__ import annotations

from pathlib import Path

PACKAGE = "hri_physio_coach"
CONFIG_FILE = "coach.yaml"
ROUTINE_FILE = "exercise_routine.yaml"


def config_dir() -> Path:
    source = Path(__file__).resolve().parent.parent / "config"
    if source.is_dir():
        return source
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(PACKAGE)) / "config"
    except (ImportError, LookupError, ValueError):
        return source


def default_config_file() -> Path:
    return config_dir() / CONFIG_FILE


def default_routine_file() -> Path:
    return config_dir() / ROUTINE_FILE

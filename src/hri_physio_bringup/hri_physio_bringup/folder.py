"""One folder per session: everything a researcher hands in, in one place (no rclpy).

``<out>/<participant id>_<YYYY-mm-dd_HH-MM-SS>/`` holds

* ``bag/`` - the rosbag2 (MCAP) recording of every topic;
* ``logs/<node>.log`` - every node's full output;
* ``configs/<node>.yaml`` - the resolved configuration each node started with (passed to it
  with ``--conf``, so what is kept is what ran);
* ``csv/`` - the receivers' CSV logs, when asked for;
* ``summary.json`` - what ran and how it ended (written even when the session was stopped);
* the report (``report.json``, ``report.html``, figures) written at the end.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from hri_physio_bridge.json_files import strict_json, write_text_atomic

BAG_DIR = "bag"
LOG_DIR = "logs"
CONFIG_DIR = "configs"
CSV_DIR = "csv"
SUMMARY_FILE = "summary.json"
TIME_FORMAT = "%Y-%m-%d_%H-%M-%S"


@dataclass(frozen=True)
class SessionFolder:
    path: Path

    @classmethod
    def plan(cls, parent: Path | str, participant: str, started: datetime) -> SessionFolder:
        """The folder a session starting now would get (not created: nothing exists before validation).

        A second session of the same participant in the same second gets ``_2``, ``_3``, ...
        """
        base = f"{participant}_{started.strftime(TIME_FORMAT)}"
        parent = Path(parent)
        path, n = parent / base, 1
        while path.exists():
            n += 1
            path = parent / f"{base}_{n}"
        return cls(path)

    def create(self) -> None:
        """Make the folder and its sub-folders; a folder that appeared meanwhile is never reused.

        FileExistsError only when another session took the name; a parent that is not a directory is
        NotADirectoryError (an OSError naming it)."""
        for parent in (self.path.parent, *self.path.parent.parents):
            if parent.exists() and not parent.is_dir():
                raise NotADirectoryError(20, "is a file, not a directory", str(parent))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.mkdir()  # FileExistsError: another session took the name
        for sub in (LOG_DIR, CONFIG_DIR):
            (self.path / sub).mkdir()

    @property
    def bag(self) -> Path:
        return self.path / BAG_DIR

    @property
    def csv_dir(self) -> Path:
        return self.path / CSV_DIR

    @property
    def summary_file(self) -> Path:
        return self.path / SUMMARY_FILE

    def log_file(self, node: str) -> Path:
        return self.path / LOG_DIR / f"{node}.log"

    def config_file(self, node: str) -> Path:
        return self.path / CONFIG_DIR / f"{node}.yaml"

    def write_config(self, node: str, text: str) -> Path:
        path = self.config_file(node)
        path.write_text(text, encoding="utf-8")
        return path

    def write_summary(self, summary: dict[str, Any]) -> Path:
        """``summary.json``, replaced atomically (a reader never sees half a file)."""
        return write_text_atomic(self.summary_file, strict_json(summary, indent=2) + "\n")

    def display(self, cwd: Path | None = None) -> str:
        """The folder's path as the user should type it (relative to ``cwd`` when inside it)."""
        cwd = Path.cwd() if cwd is None else cwd
        try:
            return str(self.path.resolve().relative_to(cwd.resolve()))
        except ValueError:
            return str(self.path.resolve())

"""The sources of an earlier commit, to run a benchmark on them side by side with the working tree."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def source_tree(ref: str, into: Path) -> dict[str, str]:
    """The sources of git commit ``ref`` under ``into``; the environment that runs them (those sources
    first on PYTHONPATH; the console scripts and the installed environment stay the same)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, "src"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    packages = sorted(str(p.parent) for p in (into / "src").glob("*/setup.cfg"))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*packages, env["PYTHONPATH"]] if env.get("PYTHONPATH") else packages)
    return env

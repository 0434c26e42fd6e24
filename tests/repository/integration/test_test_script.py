"""scripts/test ends a run whose pytest worker crashed as a failure, instead of waiting forever.

A segfault in a worker (a native library's bug, say) is a failed test, not a stuck CI job: with
``--dist loadfile``, pytest-xdist 3.8 replacing the crashed worker can leave every worker idle and
the run waiting until CI's own limit. The toy suite below is one that did wait forever so.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from helpers import ROOT

PASSING = "def test_one():\n    pass\n\n\ndef test_two():\n    pass\n"
CRASHING = """import os
import resource
import signal


def test_crash():
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # no core file left behind
    os.kill(os.getpid(), signal.SIGSEGV)


def test_after_the_crash():
    pass
"""


def test_a_crashed_worker_ends_the_run_as_a_failure(tmp_path: Path) -> None:
    toy = tmp_path / "toy"
    toy.mkdir()
    (toy / "test_a_crash.py").write_text(CRASHING)
    for name in ("b", "c", "d"):
        (toy / f"test_{name}_passing.py").write_text(PASSING)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "HRI_PHYSIO_TEST"))}
    env["HRI_PHYSIO_TEST_WORKERS"] = "1"
    # --rootdir: test ids relative to the toy suite wherever the repository is (pytest otherwise roots
    # them at the common ancestor of the toy suite and the repository, e.g. /tmp for a clone there).
    run = subprocess.run(["bash", str(ROOT / "scripts" / "test"), str(toy), "-p", "no:cacheprovider",
                          "--rootdir", str(toy), "--junitxml", str(tmp_path / "junit.xml")],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=240)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "crashed while running 'test_a_crash.py::test_crash'" in run.stdout, run.stdout
    assert "restarting disabled" in run.stdout, run.stdout

"""The test session's isolation settings hold for the whole session."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path


def test_session_holds_its_ros_domain_and_stays_on_this_machine() -> None:
    domain = int(os.environ["ROS_DOMAIN_ID"])
    assert 1 <= domain <= 101
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    lock = Path(tempfile.gettempdir()) / f"hri_physio_test_domain_{domain}.lock"
    probe = ("import fcntl, sys\n"
             f"h = open({str(lock)!r}, 'w')\n"
             "try:\n    fcntl.flock(h, fcntl.LOCK_EX | fcntl.LOCK_NB)\nexcept OSError:\n    sys.exit(3)\n")
    # Another test session trying the same domain is turned away.
    assert subprocess.run([sys.executable, "-c", probe], timeout=30).returncode == 3

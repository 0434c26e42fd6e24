"""Test-session isolation: own ROS domain (claimed), own LSL stream names, localhost only.

The environment is fixed at import time, before any test imports rclpy, so
every node and every subprocess of this session sees the same settings.
"""

from __future__ import annotations

import fcntl
import os
import random
import sys
import tempfile
import uuid
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests/helpers.py
VENV = Path(sys.prefix)



def _claim_domain_id() -> int:
    """A ROS domain no other test session on this machine holds (1-101; 0 is a live system's default).

    Always chosen here, never inherited: tests must not talk to a system the user is running.
    The claim is an flock on a file in the temp dir, released when this process exits.
    """
    ids = list(range(1, 102))
    random.SystemRandom().shuffle(ids)
    for domain in ids:
        handle = open(Path(tempfile.gettempdir()) / f"hri_physio_test_domain_{domain}.lock", "w")  # noqa: SIM115
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _DOMAIN_LOCKS.append(handle)  # keep it open (and locked) for the whole session
        return domain
    raise RuntimeError("every ROS domain 1-101 is held by another test session on this machine")


_DOMAIN_LOCKS: list = []
os.environ["ROS_DOMAIN_ID"] = str(_claim_domain_id())
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
if str(VENV) not in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in (str(VENV), os.environ.get("AMENT_PREFIX_PATH", "")) if p
    )
os.environ.setdefault("LSLAPICFG", str(ROOT / "config" / "lsl_api.cfg"))
os.environ["PYTHONUNBUFFERED"] = "1"

#: Unique per test session: prefix every LSL stream name with it.
SESSION_TAG = uuid.uuid4().hex[:8]


@pytest.fixture(scope="session")
def session_tag() -> str:
    return SESSION_TAG


@pytest.fixture
def lsl_name(request: pytest.FixtureRequest) -> str:
    """A stream-name prefix no other test (or test run) uses."""
    return f"test{SESSION_TAG}/{request.node.name[:40]}/{uuid.uuid4().hex[:6]}"


@pytest.fixture
def ros_context():
    """An initialised rclpy context of its own, shut down after the test."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        if context.ok():
            rclpy.shutdown(context=context)


def venv_bin(name: str) -> str:
    return str(VENV / "bin" / name)


def ros_env() -> dict[str, str]:
    """Environment for node subprocesses: this session's isolation settings."""
    return dict(os.environ)

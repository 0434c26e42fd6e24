"""Test-process isolation and tiers.

Isolation: each test process (the main one, or each pytest-xdist worker) claims a ROS domain of
its own, prefixes its LSL stream names with a tag of its own and stays on this machine. The
environment is fixed at import time, before any test imports rclpy, so every node and every
subprocess of this process sees the same settings.

Tiers: a test's tier is its path. ``tests/<package>/unit/`` holds logic tests (no ROS, LSL or
node processes); ``tests/<package>/integration/`` tests real nodes, rclpy and pylsl, and its
tests are marked ``integration`` here (``scripts/test --fast`` leaves them out).
"""

from __future__ import annotations

import os
import sys
import tempfile
import uuid
from datetime import datetime
from pathlib import Path

import pytest

from hri_physio_bringup.isolation import DomainClaim, claim_domain, holder_info

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
sys.path.insert(0, str(TESTS))  # the helpers package
VENV = Path(sys.prefix)



def _claim_domain() -> DomainClaim:
    """A ROS domain no other session or test run on this machine holds (1-101; 0 is a live system's default).

    Always chosen here, never inherited: tests must not talk to a system the user is running. The
    claim is the sessions' own (``hri_physio_bringup.isolation``), held until this process exits, so
    sessions and test runs (each pytest-xdist worker is one) never pick each other's domain.
    """
    info = holder_info(Path(tempfile.gettempdir()), datetime.now().isoformat(timespec="seconds"),
                       role=f"test run ({os.environ.get('PYTEST_XDIST_WORKER', 'main')})")
    return claim_domain(None, info)


#: Held (locked) for the whole test process.
DOMAIN = _claim_domain()
os.environ["ROS_DOMAIN_ID"] = str(DOMAIN.domain)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
if str(VENV) not in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in (str(VENV), os.environ.get("AMENT_PREFIX_PATH", "")) if p
    )
os.environ.setdefault("LSLAPICFG", str(ROOT / "config" / "lsl_api.cfg"))
os.environ["PYTHONUNBUFFERED"] = "1"

#: Unique per test process: prefix every LSL stream name with it.
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


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tier is the path: everything under an ``integration`` folder is marked ``integration``.

    Integration tests run first (a parallel run then starts its longest work at once instead of
    ending on it); scripts/test runs the whole-session tests on their own, one after another.
    """
    def rank(item: pytest.Item) -> int:
        return 0 if "integration" in item.path.relative_to(TESTS).parts else 1

    for item in items:
        if rank(item) == 0:
            item.add_marker(pytest.mark.integration)
    items.sort(key=rank)  # stable: the order within each rank is pytest's


def venv_bin(name: str) -> str:
    return str(VENV / "bin" / name)


def ros_env() -> dict[str, str]:
    """Environment for node subprocesses: this session's isolation settings."""
    return dict(os.environ)

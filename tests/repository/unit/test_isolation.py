"""The test process's isolation settings hold for the whole process."""

from __future__ import annotations

import os

import pytest

from hri_physio_bringup.isolation import DomainInUse, claim_domain


def test_the_test_process_holds_its_ros_domain_and_stays_on_this_machine() -> None:
    domain = int(os.environ["ROS_DOMAIN_ID"])
    assert 1 <= domain <= 101
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    # Anything else on this machine asking for the same domain (a session, another test run) is
    # turned away, and is told that a test run holds it.
    held_by_us = rf"ROS domain {domain} .* in use by another test run \(\w+\) \(pid {os.getpid()},"
    with pytest.raises(DomainInUse, match=held_by_us):
        claim_domain(domain, {"pid": 1, "started": "now", "folder": "elsewhere"})

"""Two sessions on one machine: the ROS domain claim and the per-session LSL device id (no ROS)."""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

from hri_physio_bringup.isolation import (
    DOMAIN_LOCK,
    DomainInUse,
    claim_domain,
    new_device_id,
    parse_domain,
)

INFO = {"pid": 4242, "started": "2026-05-04T10:30:00", "folder": "/data/sessions/P-1_2026-05-04_10-30-00"}


def test_a_requested_domain_is_claimed_and_names_its_holder_in_the_lock_file(tmp_path: Path) -> None:
    claim = claim_domain(17, INFO, lock_dir=tmp_path)
    try:
        assert (claim.domain, claim.chosen) == (17, False)
        assert json.loads((tmp_path / DOMAIN_LOCK.format(17)).read_text()) == INFO
    finally:
        claim.release()


def test_a_second_claim_of_a_held_domain_is_refused_naming_the_other_session(tmp_path: Path) -> None:
    first = claim_domain(17, INFO, lock_dir=tmp_path)
    try:
        with pytest.raises(DomainInUse) as refused:
            claim_domain(17, {"pid": 1, "started": "now", "folder": "elsewhere"}, lock_dir=tmp_path)
        text = str(refused.value)
        assert "ROS domain 17" in text and "pid 4242" in text and "2026-05-04T10:30:00" in text
        assert INFO["folder"] in text and "\n" not in text
        # The refused claim left the holder's information as it was.
        assert json.loads((tmp_path / DOMAIN_LOCK.format(17)).read_text()) == INFO
    finally:
        first.release()
    again = claim_domain(17, INFO, lock_dir=tmp_path)  # free once released
    again.release()


def test_a_free_domain_skips_the_domains_other_processes_hold_and_names_them(tmp_path: Path) -> None:
    session = claim_domain(1, INFO, lock_dir=tmp_path)
    test_run = claim_domain(2, {**INFO, "pid": 77, "role": "test run (gw1)"}, lock_dir=tmp_path)
    try:
        picked = claim_domain(None, INFO, lock_dir=tmp_path, candidates=[1, 2, 3], rng=random.Random(0))
        assert (picked.domain, picked.chosen) == (3, True)
        with pytest.raises(DomainInUse, match="every ROS domain 1-3"):
            claim_domain(None, INFO, lock_dir=tmp_path, candidates=[1, 2, 3])
        # A domain asked for by number names its holder, whatever it is.
        with pytest.raises(DomainInUse, match=r"in use by another test run \(gw1\) \(pid 77,"):
            claim_domain(2, INFO, lock_dir=tmp_path)
        picked.release()
    finally:
        session.release()
        test_run.release()


def test_two_sessions_picking_free_domains_never_get_the_same(tmp_path: Path) -> None:
    claims = [claim_domain(None, INFO, lock_dir=tmp_path, candidates=range(1, 6)) for _ in range(5)]
    try:
        assert sorted(c.domain for c in claims) == [1, 2, 3, 4, 5]
    finally:
        for c in claims:
            c.release()


@pytest.mark.parametrize("text,expected", [(None, None), ("", None), (" 7 ", 7), ("0", 0), ("232", 232)])
def test_ros_domain_id_from_the_environment(text: str | None, expected: int | None) -> None:
    assert parse_domain(text) == expected


@pytest.mark.parametrize("text", ["x", "1.5", "-1", "233"])
def test_a_bad_ros_domain_id_is_a_clear_error(text: str) -> None:
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        parse_domain(text)


def test_device_ids_are_per_session() -> None:
    rng = random.Random(5)
    ids = {new_device_id(rng) for _ in range(200)}
    assert len(ids) == 200
    assert all(len(i) == 9 and i.startswith("SIM") and i[3:].isalnum() for i in ids)
    assert new_device_id() != new_device_id()

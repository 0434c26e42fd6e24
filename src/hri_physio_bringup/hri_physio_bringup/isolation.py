"""Keeping two sessions on one machine apart: a claimed ROS domain and LSL names of their own (no rclpy).

ROS 2 nodes in the same domain on one host see each other's topics, and LSL resolves stream
names machine-wide, so two sessions started side by side would share /clock, the coach's topics
and the simulated strap. Each session therefore

* claims a ROS domain with an ``flock`` on a lock file in the temp directory (released by the
  kernel when the session's process ends, however it ends). The holder writes its pid, start
  time, folder and role into the file, so a process refused a domain can say who holds it. A
  domain the user chose (``ROS_DOMAIN_ID``) is claimed as well: two sessions told to use the same
  one cannot both run. Without a choice a free domain is picked. Anything else that needs a ROS
  domain of its own on this machine (a test run, a tool) claims it with :func:`claim_domain`
  too, so every claimant sees every other;
* names its simulated strap's LSL streams with a per-session device id (:func:`new_device_id`).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import random
import secrets
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

#: Domains a session picks from: 0 is a live system's default, 101 the highest id whose ports
#: stay clear of Linux's ephemeral range.
FREE_DOMAINS = range(1, 102)
DOMAIN_LOCK = "hri_physio_domain_{}.lock"


class DomainInUse(RuntimeError):
    """The ROS domain asked for is held by another session (the message names it)."""


@dataclass(frozen=True)
class Holder:
    """Who holds a domain, as its lock file says."""

    pid: int | None = None
    started: str | None = None
    folder: str | None = None
    role: str = "session"

    @classmethod
    def read(cls, handle: IO[str]) -> Holder:
        handle.seek(0)
        try:
            data = json.loads(handle.read() or "{}")
        except ValueError:
            return cls()
        if not isinstance(data, dict):
            return cls()
        pid = data.get("pid")
        role = data.get("role")
        return cls(pid if isinstance(pid, int) else None, data.get("started"), data.get("folder"),
                   role if isinstance(role, str) and role else "session")

    def describe(self) -> str:
        if self.pid is None:
            return "another session (it has not said which yet)"
        return (f"another {self.role} (pid {self.pid}, started {self.started or '?'}, "
                f"folder {self.folder or '?'})")


@dataclass
class DomainClaim:
    """A ROS domain held by this process until :meth:`release` (or the process's end)."""

    domain: int
    chosen: bool  # True: picked here; False: the user's ROS_DOMAIN_ID
    handles: list[IO[str]] = field(default_factory=list, repr=False)

    def release(self) -> None:
        for handle in self.handles:
            with contextlib.suppress(OSError):
                fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        self.handles.clear()


def _try_lock(path: Path) -> tuple[IO[str] | None, Holder | None]:
    """(an open, locked handle, None), or (None, who holds it) when another process does."""
    try:
        handle = open(path, "a+", encoding="utf-8")  # noqa: SIM115 - kept open while the lock is held
    except OSError:
        return None, Holder()  # e.g. another user's lock file: treat the domain as taken
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = Holder.read(handle)
        handle.close()
        return None, holder
    return handle, None


def _write_holder(handle: IO[str], info: dict[str, Any]) -> None:
    handle.seek(0)
    handle.truncate()
    handle.write(json.dumps(info))
    handle.flush()


def parse_domain(text: str | None) -> int | None:
    """The user's ``ROS_DOMAIN_ID`` (None when unset or empty); ValueError when it is not a domain id."""
    if text is None or not text.strip():
        return None
    try:
        value = int(text.strip())
    except ValueError:
        raise ValueError(f"ROS_DOMAIN_ID must be a whole number, got {text!r}") from None
    if not 0 <= value <= 232:
        raise ValueError(f"ROS_DOMAIN_ID must be in 0-232, got {value}")
    return value


def claim_domain(requested: int | None, info: dict[str, Any], lock_dir: Path | None = None,
                 candidates: Iterable[int] = FREE_DOMAINS, rng: random.Random | None = None) -> DomainClaim:
    """Claim ``requested`` (raises :class:`DomainInUse` naming the holder) or a free domain.

    ``info`` (pid, start time, folder) is written into the lock file for others to read.
    """
    directory = Path(lock_dir) if lock_dir is not None else Path(tempfile.gettempdir())
    if requested is not None:
        handle, holder = _try_lock(directory / DOMAIN_LOCK.format(requested))
        if handle is None:
            assert holder is not None
            raise DomainInUse(f"ROS domain {requested} (ROS_DOMAIN_ID) is in use by {holder.describe()}; "
                              "unset ROS_DOMAIN_ID to let the session pick a free domain, or export another")
        _write_holder(handle, info)
        return DomainClaim(requested, chosen=False, handles=[handle])
    order = list(candidates)
    (rng or random.SystemRandom()).shuffle(order)  # two sessions started together rarely try the same first
    for domain in order:
        handle, _ = _try_lock(directory / DOMAIN_LOCK.format(domain))
        if handle is None:
            continue
        _write_holder(handle, info)
        return DomainClaim(domain, chosen=True, handles=[handle])
    raise DomainInUse(f"every ROS domain {order and min(order)}-{order and max(order)} is held by another "
                      "session or test run on this machine")


def new_device_id(rng: random.Random | None = None) -> str:
    """A simulated strap's device id of its own: ``SIM`` + 6 hex digits (LSL names stay apart)."""
    value = rng.getrandbits(24) if rng is not None else secrets.randbits(24)
    return f"SIM{value:06X}"


def holder_info(folder: Path, started: str, role: str = "session") -> dict[str, Any]:
    """What a claim writes into its lock file for others to read (this process is the holder)."""
    return {"pid": os.getpid(), "started": started, "folder": str(folder), "role": role}


LAB_ROLE_LOCK = "hri_physio_domain_{}_{}.lock"


def claim_lab_domain(domain: int, role: str, info: dict[str, Any],
                     lock_dir: Path | None = None) -> DomainClaim:
    """Claim ``domain`` for one role of a lab (raises :class:`DomainInUse` naming the holder).

    The roles of one lab share their domain, also when two of them run on one machine: each holds
    the domain's lock shared (so a single-host session cannot pick it meanwhile) and its role's
    lock exclusively (so a role does not run twice on one machine).
    """
    directory = Path(lock_dir) if lock_dir is not None else Path(tempfile.gettempdir())
    role_handle, holder = _try_lock(directory / LAB_ROLE_LOCK.format(domain, role))
    if role_handle is None:
        assert holder is not None
        raise DomainInUse(f"the lab's {role} role (ROS domain {domain}) already runs on this machine: "
                          f"{holder.describe()}")
    _write_holder(role_handle, info)
    try:
        shared = open(directory / DOMAIN_LOCK.format(domain), "a+", encoding="utf-8")  # noqa: SIM115
    except OSError as exc:
        role_handle.close()
        raise DomainInUse(f"ROS domain {domain}: cannot open its lock file ({exc.strerror})") from None
    try:
        fcntl.flock(shared, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        holder = Holder.read(shared)
        shared.close()
        role_handle.close()
        raise DomainInUse(f"ROS domain {domain} (the lab file's ros_domain) is in use by "
                          f"{holder.describe()}; stop it or give the lab another domain") from None
    _write_holder(shared, info)  # what a session refused the domain says (the last role to start)
    return DomainClaim(domain, chosen=False, handles=[role_handle, shared])

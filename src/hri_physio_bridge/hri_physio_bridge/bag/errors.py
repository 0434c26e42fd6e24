"""Errors of the bag package: every one is meant to be shown to a user as one line."""

from __future__ import annotations


class BagError(Exception):
    """A bag cannot be written, read, repaired or played; the message says why."""


class BagExistsError(BagError):
    """The output bag already exists: recordings are never overwritten."""


class IncompleteBagError(BagError):
    """The bag's writer did not finish (no summary or no metadata.yaml); repair it first."""

"""Bringing up a whole HRI Physio session: the launcher, its plan, console, folder and isolation."""

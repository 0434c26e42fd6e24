"""Shortened packaged routines, for session tests whose length is not what they check."""

from __future__ import annotations

from pathlib import Path

import yaml

from helpers import SRC

PACKAGED_ROUTINE = SRC / "hri_physio_coach" / "config" / "exercise_routine.yaml"

#: Activities kept per phase kind: (index in the packaged phase, duration in s or None to keep it).
Keep = dict[str, list[tuple[int, float | None]]]

#: 4.5 minutes: 1 min calibration, 1 min marching, 1.5 min lateral knees, 1 min step-up.
FOUR_AND_A_HALF_MINUTES: Keep = {"calibration": [(0, None)], "warm_up": [(0, 60)],
                                 "conditioning": [(1, 90)], "cool_down": [(0, 60)]}
#: 10 minutes with every kind of conditioning activity and the predictive policy's plan (420 s) in it.
TEN_MINUTES: Keep = {"calibration": [(0, None)], "warm_up": [(1, None)],
                     "conditioning": [(0, None), (1, None), (2, None), (3, None)], "cool_down": [(1, 60)]}


def short_routine(folder: Path, keep: Keep, calib_time: float = 60) -> list[str]:
    """Write routine.yaml and coach.yaml into ``folder``; the session options that use them."""
    routine = yaml.safe_load(PACKAGED_ROUTINE.read_text())
    for phase in routine["phases"]:
        activities = []
        for index, seconds in keep[phase["kind"]]:
            activity = dict(phase["activities"][index])
            if seconds is not None:
                activity["duration"] = seconds
            activities.append(activity)
        phase["activities"] = activities
    (folder / "routine.yaml").write_text(yaml.safe_dump(routine))
    (folder / "coach.yaml").write_text(f"calib_time: {calib_time:g}\n")
    return ["--routine", str(folder / "routine.yaml"), "--conf", str(folder / "coach.yaml")]


def routine_seconds(keep: Keep, calib_time: float = 60) -> float:
    """The length of a shortened routine (sim seconds)."""
    routine = yaml.safe_load(PACKAGED_ROUTINE.read_text())
    total = 0.0
    for phase in routine["phases"]:
        for index, seconds in keep[phase["kind"]]:
            duration = phase["activities"][index]["duration"] if seconds is None else seconds
            total += calib_time if duration == "calib_time" else float(duration)
    return total

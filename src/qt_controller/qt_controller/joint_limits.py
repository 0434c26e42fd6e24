"""QT robot parts, joints and position limits (degrees).

The QT robot has eight joints in three parts. Commands address a part and give one
value per joint in the order below (the order of QT's ``*_position/command`` topics).
The limits are those of the QTrobot documentation, rounded inwards; a lab whose robot
differs overrides them with the ``joint_limits`` option (see :func:`parse_limit_overrides`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

#: Part name in the command protocol -> joint names in command order.
PARTS: dict[str, tuple[str, ...]] = {
    "head": ("HeadYaw", "HeadPitch"),
    "rightarm": ("RightShoulderPitch", "RightShoulderRoll", "RightElbowRoll"),
    "leftarm": ("LeftShoulderPitch", "LeftShoulderRoll", "LeftElbowRoll"),
}

#: Spellings accepted for a part (case-insensitive); the value is the canonical name.
PART_ALIASES: dict[str, str] = {
    "head": "head",
    "rightarm": "rightarm",
    "right_arm": "rightarm",
    "leftarm": "leftarm",
    "left_arm": "leftarm",
}

#: QT topic stem of each part: /qt_robot/<stem>_position/command.
PART_TOPIC_STEM: dict[str, str] = {"head": "head", "rightarm": "right_arm", "leftarm": "left_arm"}

#: The part names QT's motor services use (qt_motors_controller).
PART_QT_NAME: dict[str, str] = {"head": "head", "rightarm": "right_arm", "leftarm": "left_arm"}

ALL_JOINTS: tuple[str, ...] = tuple(j for joints in PARTS.values() for j in joints)

#: joint -> (min, max) in degrees.
DEFAULT_LIMITS: dict[str, tuple[float, float]] = {
    "HeadYaw": (-60.0, 60.0),
    "HeadPitch": (-25.0, 25.0),
    "RightShoulderPitch": (-140.0, 140.0),
    "RightShoulderRoll": (-75.0, 5.0),
    "RightElbowRoll": (-80.0, -5.0),
    "LeftShoulderPitch": (-140.0, 140.0),
    "LeftShoulderRoll": (-75.0, 5.0),
    "LeftElbowRoll": (-80.0, -5.0),
}

#: Rest pose (degrees): head straight, arms down along the body.
HOME: dict[str, float] = {
    "HeadYaw": 0.0,
    "HeadPitch": 0.0,
    "RightShoulderPitch": -90.0,
    "RightShoulderRoll": -60.0,
    "RightElbowRoll": -30.0,
    "LeftShoulderPitch": 90.0,
    "LeftShoulderRoll": -60.0,
    "LeftElbowRoll": -30.0,
}


class JointLimitError(ValueError):
    """A command would move a joint outside its range (or names an unknown part/joint)."""


def canonical_part(name: str) -> str:
    """``'leftArm'`` -> ``'leftarm'``; raises :class:`JointLimitError` for an unknown part."""
    part = PART_ALIASES.get(name.strip().lower())
    if part is None:
        raise JointLimitError(f"unknown part {name!r}; expected one of: head, leftarm, rightarm")
    return part


@dataclass(frozen=True)
class JointLimits:
    """Position limits of every joint; checks whole-part commands before they are sent."""

    limits: Mapping[str, tuple[float, float]]

    @classmethod
    def default(cls) -> JointLimits:
        return cls(dict(DEFAULT_LIMITS))

    def with_overrides(self, overrides: Mapping[str, tuple[float, float]]) -> JointLimits:
        merged = dict(self.limits)
        merged.update(overrides)
        return JointLimits(merged)

    def check_part(self, part: str, values: Sequence[float]) -> list[float]:
        """Validate one command for ``part``; returns the values as floats.

        Raises :class:`JointLimitError` naming the first joint that is out of range.
        """
        part = canonical_part(part)
        joints = PARTS[part]
        if len(values) != len(joints):
            raise JointLimitError(
                f"{part} takes {len(joints)} values ({', '.join(joints)}), got {len(values)}"
            )
        out = [float(v) for v in values]
        for joint, value in zip(joints, out, strict=True):
            self.check_joint(joint, value)
        return out

    def check_joint(self, joint: str, value: float) -> None:
        if joint not in self.limits:
            raise JointLimitError(f"unknown joint {joint!r}")
        lo, hi = self.limits[joint]
        if not math.isfinite(value) or not lo <= value <= hi:
            raise JointLimitError(f"{joint} {value:g} deg is outside its range [{lo:g}, {hi:g}]")


def parse_limit_overrides(spec: str) -> dict[str, tuple[float, float]]:
    """Parse ``"HeadYaw:-50:50,HeadPitch:-10:20"`` (the form a ROS string parameter can hold)."""
    out: dict[str, tuple[float, float]] = {}
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        fields = item.split(":")
        if len(fields) != 3:
            raise JointLimitError(f"joint limit {item!r} must look like Joint:min:max")
        joint, lo_text, hi_text = fields
        if joint not in DEFAULT_LIMITS:
            raise JointLimitError(f"joint limit for unknown joint {joint!r}; known: {', '.join(ALL_JOINTS)}")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            raise JointLimitError(f"joint limit {item!r}: min and max must be numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise JointLimitError(f"joint limit {item!r}: need finite min < max")
        out[joint] = (lo, hi)
    return out

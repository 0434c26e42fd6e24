"""QT gesture keyframe files: parsing, interpolation and the duration/speed maths.

A gesture file (XML, the layout of QT's recorded gestures, kept simple) names the joints
it moves and lists keyframes with their time in seconds from the start::

    <gesture>
      <name>arms_forward</name>
      <parts><part>right_arm</part><part>left_arm</part></parts>
      <joints><joint>RightShoulderPitch</joint> ... </joints>
      <points>
        <point time="0.0">-90 -60 -30 ...</point>   <!-- one value (degrees) per joint -->
        ...
      </points>
    </gesture>

Played at speed ``s`` a gesture lasts ``duration / s``; at elapsed time ``e`` the joints are
at the keyframes linearly interpolated at gesture time ``e * s``.
"""

from __future__ import annotations

import bisect
import importlib.resources
import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from qt_controller.joint_limits import DEFAULT_LIMITS, JointLimitError, JointLimits

PACKAGE = "qt_controller"


class GestureError(ValueError):
    """A gesture file that cannot be used, or a gesture that does not exist."""


@dataclass(frozen=True)
class Gesture:
    name: str
    joints: tuple[str, ...]
    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]
    source: str = ""

    @property
    def duration(self) -> float:
        """Recorded duration in seconds (time of the last keyframe)."""
        return self.times[-1]

    def duration_at(self, speed: float) -> float:
        if not (math.isfinite(speed) and speed > 0):
            raise GestureError(f"gesture speed must be a positive number, got {speed!r}")
        return self.duration / speed

    def positions_at(self, elapsed: float, speed: float = 1.0) -> dict[str, float]:
        """Joint positions (degrees) ``elapsed`` seconds after starting at ``speed``."""
        t = min(max(elapsed * speed, 0.0), self.duration)
        i = bisect.bisect_right(self.times, t)
        if i >= len(self.times):
            row = self.positions[-1]
        else:
            t0, t1 = self.times[i - 1], self.times[i]
            a = (t - t0) / (t1 - t0)
            p0, p1 = self.positions[i - 1], self.positions[i]
            row = tuple(x0 + a * (x1 - x0) for x0, x1 in zip(p0, p1, strict=True))
        return dict(zip(self.joints, row, strict=True))

    @property
    def final_positions(self) -> dict[str, float]:
        return dict(zip(self.joints, self.positions[-1], strict=True))


def _text(elem: ET.Element | None) -> str:
    return (elem.text or "").strip() if elem is not None else ""


def parse_gesture_xml(text: str, source: str = "<string>", limits: JointLimits | None = None) -> Gesture:
    """Parse and validate one gesture file's text."""
    limits = limits or JointLimits(DEFAULT_LIMITS)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise GestureError(f"{source}: not valid XML: {exc}") from None
    if root.tag != "gesture":
        raise GestureError(f"{source}: root element must be <gesture>, not <{root.tag}>")
    name = _text(root.find("name"))
    if not name or len(name.split()) != 1:
        raise GestureError(f"{source}: <name> must be one word, got {name!r}")
    joints = tuple(_text(j) for j in root.findall("joints/joint"))
    if not joints:
        raise GestureError(f"{source}: no <joints><joint> listed")
    if len(set(joints)) != len(joints):
        raise GestureError(f"{source}: a joint is listed twice in {list(joints)}")
    for j in joints:
        if j not in limits.limits:
            raise GestureError(f"{source}: unknown joint {j!r}")
    times: list[float] = []
    rows: list[tuple[float, ...]] = []
    for k, point in enumerate(root.findall("points/point")):
        where = f"{source}: point {k + 1}"
        try:
            t = float(point.get("time", ""))
            row = tuple(float(v) for v in _text(point).split())
        except ValueError:
            raise GestureError(f"{where}: time and positions must be numbers") from None
        if not math.isfinite(t) or (times and t <= times[-1]) or t < 0:
            raise GestureError(f"{where}: times must be finite, start at 0 and increase (got {t:g})")
        if len(row) != len(joints):
            raise GestureError(f"{where}: {len(row)} values for {len(joints)} joints")
        for j, v in zip(joints, row, strict=True):
            try:
                limits.check_joint(j, v)
            except JointLimitError as exc:
                raise GestureError(f"{where}: {exc}") from None
        times.append(t)
        rows.append(row)
    if len(times) < 2:
        raise GestureError(f"{source}: a gesture needs at least two points")
    if times[0] != 0.0:
        raise GestureError(f"{source}: the first point must be at time 0, not {times[0]:g}")
    return Gesture(name, joints, tuple(times), tuple(rows), source)


def load_gesture_file(path: str | Path, limits: JointLimits | None = None) -> Gesture:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise GestureError(f"cannot read gesture file {p}: {exc.strerror or exc}") from None
    return parse_gesture_xml(text, str(p), limits)


def default_gesture_dir() -> Path:
    """The gestures shipped with this package (importlib.resources, else the ament share)."""
    try:
        here = Path(str(importlib.resources.files(PACKAGE + ".gesture_files")))
        if any(here.glob("*.xml")):
            return here
    except (ModuleNotFoundError, TypeError):
        pass
    from ament_index_python.packages import get_package_share_directory  # full ROS 2 installs

    return Path(get_package_share_directory(PACKAGE)) / "gestures"


class GestureLibrary:
    """Gestures by name (case-insensitive), loaded from one or more directories of *.xml."""

    def __init__(self, gestures: Iterable[Gesture] = ()) -> None:
        self._by_name: dict[str, Gesture] = {}
        for g in gestures:
            self.add(g)

    def add(self, gesture: Gesture) -> None:
        key = gesture.name.lower()
        if key in self._by_name:
            raise GestureError(
                f"gesture {gesture.name!r} defined twice: {self._by_name[key].source} and {gesture.source}"
            )
        self._by_name[key] = gesture

    @classmethod
    def from_dirs(cls, dirs: Iterable[str | Path], limits: JointLimits | None = None) -> GestureLibrary:
        lib = cls()
        for d in dirs:
            path = Path(d)
            if not path.is_dir():
                raise GestureError(f"gesture directory {path} does not exist")
            for f in sorted(path.glob("*.xml")):
                lib.add(load_gesture_file(f, limits))
        return lib

    def get(self, name: str) -> Gesture:
        g = self._by_name.get(name.lower())
        if g is None:
            raise GestureError(f"unknown gesture {name!r}; known: {', '.join(self.names) or 'none'}")
        return g

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name.lower() in self._by_name

    @property
    def names(self) -> list[str]:
        return sorted(g.name for g in self._by_name.values())

    def as_mapping(self) -> Mapping[str, Gesture]:
        return dict(self._by_name)

"""QT facial expressions: the names the robot knows and how a command names them.

QT shows an expression from a file named ``QT/<name>`` on its face screen. The command
protocol accepts the short name (``set emotion happy``) or the full one (``QT/happy``).
The catalogue below is QT's standard set; a lab with its own expression files extends it
with the ``emotions`` option of qt_controller and mock_qt_robot.
"""

from __future__ import annotations

from collections.abc import Iterable

PREFIX = "QT/"

STANDARD_EMOTIONS: tuple[str, ...] = (
    "QT/afraid",
    "QT/angry",
    "QT/blowing_raspberry",
    "QT/breathing_exercise",
    "QT/brushing_teeth",
    "QT/calming_down",
    "QT/confused",
    "QT/cry",
    "QT/dirty_face",
    "QT/disgusted",
    "QT/happy",
    "QT/happy_blinking",
    "QT/kiss",
    "QT/neutral",
    "QT/puffing_the_cheeks",
    "QT/sad",
    "QT/scream",
    "QT/showing_smile",
    "QT/shy",
    "QT/surprise",
    "QT/talking",
    "QT/yawn",
)


def qt_emotion_name(name: str) -> str:
    """``'happy'`` -> ``'QT/happy'``; a name that already has a folder is kept as it is."""
    name = name.strip()
    return name if "/" in name else PREFIX + name.lower()


class EmotionCatalogue:
    """The expressions a robot can show; lookups accept short or full names."""

    def __init__(self, names: Iterable[str] = STANDARD_EMOTIONS) -> None:
        self._names = {qt_emotion_name(n).lower(): qt_emotion_name(n) for n in names if n.strip()}

    def resolve(self, name: str) -> str | None:
        """The robot's name for ``name``, or None when the robot has no such expression."""
        return self._names.get(qt_emotion_name(name).lower())

    @property
    def names(self) -> list[str]:
        return sorted(self._names.values())

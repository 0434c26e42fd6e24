"""What the name of a media file says: the music tempo (BPM) in an audio name.

The coach plays one audio file per step of its speed ladder, named with its tempo
(``exercise_{}`` + suffix ``125`` -> ``./audio/exercise_125.wav``); the simulated participant
reads the tempo back from the name it hears. Both use :func:`tempo_from_name`, so the rule is
written once:

- only the file's base name counts (no directory, no alphabetic extension such as ``.wav``);
- a number next to ``bpm`` wins (``125bpm``, ``bpm_110``);
- otherwise the last number in the name, which is where the ladder's suffix goes;
- only numbers within :data:`TEMPO_RANGE` are tempos (``song2``, ``2024_mix`` are not);
- no such number: None (``relaxing``).
"""

from __future__ import annotations

import re

#: Music tempos a name may carry, in BPM (slow ballads to fast running music).
TEMPO_RANGE = (30.0, 300.0)

_NUMBER = re.compile(r"(?<![\d.])\d+(?:\.\d+)?(?![\d.])")
_TAGGED = re.compile(r"(\d+(?:\.\d+)?)\s*[_-]?\s*bpm|bpm\s*[_:=-]?\s*(\d+(?:\.\d+)?)", re.IGNORECASE)
_EXTENSION = re.compile(r"\.[A-Za-z][A-Za-z0-9]*$")


def base_name(name: str) -> str:
    """``name`` without its directories and its alphabetic extension (``a/b_125.wav`` -> ``b_125``)."""
    last = re.split(r"[/\\]", name.strip())[-1]
    return _EXTENSION.sub("", last)


def _plausible(text: str) -> float | None:
    value = float(text)
    return value if TEMPO_RANGE[0] <= value <= TEMPO_RANGE[1] else None


def tempo_from_name(name: str) -> float | None:
    """The music tempo (BPM) an audio name or ladder suffix carries, or None if it names none.

    ``"125"``, ``"exercise_125"``, ``"./audio/exercise_125.wav"``, ``"beat:125"``,
    ``"125bpm.wav"`` and ``"track2_bpm125.ogg"`` all give 125.0; ``"relaxing"`` gives None.
    """
    stem = base_name(str(name))
    for match in _TAGGED.finditer(stem):
        tempo = _plausible(match.group(1) or match.group(2))
        if tempo is not None:
            return tempo
    for text in reversed(_NUMBER.findall(stem)):
        tempo = _plausible(text)
        if tempo is not None:
            return tempo
    return None

"""The speed ladder: paired gesture speeds and music tempos, moved one step at a time.

The seed's coach.yaml lists gesture speeds (``speed_modifier``) and music tempo suffixes
(``audio_suffix``, appended to the exercise audio name) of equal length; one index selects
both, and it never leaves the list.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

from hri_physio_coach.media_names import tempo_from_name


class SpeedLadder:
    """Gesture speed and music tempo, one index into equal-length lists."""

    def __init__(self, speeds: Sequence[float], suffixes: Sequence[str], start_index: int = 0) -> None:
        if not speeds:
            raise ValueError("the speed ladder is empty: speed_modifier needs at least one speed")
        if len(speeds) != len(suffixes):
            raise ValueError(
                f"speed_modifier has {len(speeds)} steps but audio_suffix has {len(suffixes)}: "
                "each gesture speed needs its music tempo"
            )
        clean = [float(s) for s in speeds]
        if any(not math.isfinite(s) or s <= 0 for s in clean):
            raise ValueError(f"gesture speeds must be finite and > 0, got {list(speeds)}")
        if any(b <= a for a, b in itertools.pairwise(clean)):
            raise ValueError(f"gesture speeds must increase step by step, got {clean}")
        if not 0 <= start_index < len(clean):
            raise ValueError(f"start index {start_index} is outside the ladder [0, {len(clean) - 1}]")
        self.speeds: tuple[float, ...] = tuple(clean)
        self.suffixes: tuple[str, ...] = tuple(str(s) for s in suffixes)
        self.index = start_index

    def __len__(self) -> int:
        return len(self.speeds)

    @property
    def speed(self) -> float:
        return self.speeds[self.index]

    @property
    def suffix(self) -> str:
        return self.suffixes[self.index]

    @property
    def tempo(self) -> float | None:
        return tempo_from_name(self.suffix)

    @property
    def at_top(self) -> bool:
        return self.index == len(self.speeds) - 1

    @property
    def at_bottom(self) -> bool:
        return self.index == 0

    def can_step(self, delta: int) -> bool:
        return 0 <= self.index + delta < len(self.speeds)

    def step(self, delta: int) -> bool:
        """Move by ``delta`` steps if that stays on the ladder; True when the index changed."""
        if delta == 0 or not self.can_step(delta):
            return False
        self.index += delta
        return True

    def state(self) -> dict[str, object]:
        return {"index": self.index, "speed": self.speed, "suffix": self.suffix, "tempo": self.tempo}

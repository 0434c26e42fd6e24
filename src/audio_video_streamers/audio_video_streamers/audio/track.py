"""A decoded, ready-to-loop audio source.

A track loops forever. Its loop keeps the track's exact length (so a track cut on bar lines
keeps its beat across the loop); where the end does not meet the start, ``declick`` seconds
of raised-cosine fade-out before the loop point and fade-in after it remove the click. The
first pass starts at full level. Sources built to loop (the beat, the pad) need no declick.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Track:
    samples: np.ndarray  # (frames, channels) float32
    rate: int
    source: str  # the request that named it
    kind: str
    tempo: float | None = None
    declick: float = 0.0  # s of fade on each side of the loop point
    info: dict = field(default_factory=dict)  # source-specific status fields (e.g. the stretch ratio)

    def __post_init__(self) -> None:
        if self.samples.ndim != 2 or len(self.samples) == 0:
            raise ValueError(f"a track needs (frames, channels) samples, got shape {self.samples.shape}")
        frames = len(self.samples)
        ramp = min(round(self.declick * self.rate), frames // 4)
        # Half a raised cosine from 0 to 1 over ``ramp`` frames (excluding both ends' exact zero).
        fade_in = 0.5 - 0.5 * np.cos(np.pi * (np.arange(ramp) + 0.5) / max(ramp, 1))
        object.__setattr__(self, "_ramp", fade_in.astype(np.float32))

    @property
    def frames(self) -> int:
        return len(self.samples)

    @property
    def channels(self) -> int:
        return self.samples.shape[1]

    @property
    def duration(self) -> float:
        return self.frames / self.rate

    @property
    def nbytes(self) -> int:
        return int(self.samples.nbytes)

    def read(self, start: int, count: int) -> np.ndarray:
        """``count`` frames from absolute position ``start`` (frames since the track began)."""
        out = np.empty((count, self.channels), dtype=np.float32)
        ramp: np.ndarray = self._ramp  # type: ignore[attr-defined]
        r, frames = len(ramp), self.frames
        done, pos = 0, start % frames
        while done < count:  # contiguous pieces, wrapping at the loop point
            n = min(count - done, frames - pos)
            piece = out[done:done + n]
            piece[:] = self.samples[pos:pos + n]
            if r:
                lo = max(pos, frames - r)  # fade out before every loop point
                if lo < pos + n:
                    piece[lo - pos:] *= ramp[::-1][lo - (frames - r):pos + n - (frames - r), None]
                if pos < r and start + done >= frames:  # fade in after it (not on the first pass)
                    hi = min(pos + n, r)
                    piece[: hi - pos] *= ramp[pos:hi, None]
            done += n
            pos = 0
        return out

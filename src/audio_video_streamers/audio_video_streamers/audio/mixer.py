"""The mixer: voices with equal-power fades, so a new track cross-fades with the old one.

Each voice has a level that moves linearly towards its target (0 or 1) over ``fade`` seconds;
its gain is ``sin(level * pi/2)``, so two uncorrelated tracks cross-fade at constant loudness.
A new track starts at level 0 towards 1 while every other voice heads to 0 from wherever it
is (a request during a fade continues smoothly). ``fade`` 0 swaps at the next block.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from audio_video_streamers.audio.track import Track
from audio_video_streamers.status import State

MAX_VOICES = 6  # beyond this, the quietest fading voice is dropped (a burst of requests)


@dataclass
class Voice:
    track: Track
    level: float
    target: float
    position: int = 0  # frames played since the track started

    @property
    def settled(self) -> bool:
        return self.level == self.target


class Mixer:
    def __init__(self, rate: int, channels: int, fade: float) -> None:
        self.rate, self.channels, self.fade = rate, channels, fade
        self.voices: list[Voice] = []

    # --- requests ----------------------------------------------------------------------------
    def start(self, track: Track) -> None:
        """Fade ``track`` in and everything else out."""
        if track.rate != self.rate or track.channels != self.channels:
            raise ValueError(f"track is {track.rate} Hz x {track.channels}, mixer {self.rate} Hz x "
                             f"{self.channels}")
        for voice in self.voices:
            voice.target = 0.0
        self.voices.append(Voice(track, level=0.0 if self.fade > 0 else 1.0, target=1.0))
        if self.fade <= 0:
            self.voices = [self.voices[-1]]
        while len(self.voices) > MAX_VOICES:
            quietest = min(self.voices[:-1], key=lambda v: v.level)
            self.voices.remove(quietest)

    def stop(self) -> None:
        """Fade everything out."""
        for voice in self.voices:
            voice.target = 0.0
        if self.fade <= 0:
            self.voices.clear()

    # --- rendering ---------------------------------------------------------------------------
    def render(self, frames: int) -> np.ndarray:
        """The next ``frames`` frames of the mix, (frames, channels) float32 in [-1, 1]."""
        out = np.zeros((frames, self.channels), dtype=np.float32)
        step = 1.0 / (self.fade * self.rate) if self.fade > 0 else 1.0
        for voice in self.voices:
            block = voice.track.read(voice.position, frames)
            voice.position += frames
            if voice.settled:
                if voice.level == 1.0:
                    out += block
                continue
            direction = 1.0 if voice.target > voice.level else -1.0
            levels = voice.level + direction * step * np.arange(1, frames + 1)
            levels = np.clip(levels, 0.0, 1.0) if direction > 0 else np.clip(levels, voice.target, 1.0)
            gains = np.sin(levels * (np.pi / 2)).astype(np.float32)
            out += block * gains[:, None]
            voice.level = float(levels[-1])
            if abs(voice.level - voice.target) < 1e-9:
                voice.level = voice.target
        self.voices = [v for v in self.voices if not (v.settled and v.level == 0.0)]
        np.clip(out, -1.0, 1.0, out=out)
        return out

    # --- state -------------------------------------------------------------------------------
    @property
    def current(self) -> Voice | None:
        """The voice heading to full level (the newest), if any."""
        for voice in reversed(self.voices):
            if voice.target == 1.0:
                return voice
        return None

    @property
    def state(self) -> State:
        if not self.voices:
            return State.STOPPED
        if all(v.settled for v in self.voices):
            return State.PLAYING
        return State.FADING

    def fading_out(self) -> list[str]:
        return [v.track.source for v in self.voices if v.target == 0.0]

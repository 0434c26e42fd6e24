"""The built-in sources, synthesised so the coach needs no media files.

- :func:`exercise_beat`: a kick on every beat (the first of each bar a little stronger), a light
  hi-hat on the off-beats and a soft clap on beats 2 and 4. The loop is a whole number of bars
  and every hit sits on the sample nearest its exact time, so the tempo holds across loops
  (the loop length is rounded to a frame: under 1 ppm at any tempo).
- :func:`relaxing_pad`: a slow, breathing A-major pad whose partials all complete whole cycles in
  the loop, so it loops seamlessly.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

BEATS_PER_BAR = 4
BARS_PER_LOOP = 8
PAD_LOOP = 16.0  # s


def _kick(rate: int, length: float = 0.25) -> np.ndarray:
    """A pitched-down sine thump: 110 -> 45 Hz, fast attack, exponential decay."""
    t = np.arange(int(length * rate)) / rate
    freq = 45.0 + 65.0 * np.exp(-t / 0.03)
    phase = 2 * np.pi * np.cumsum(freq) / rate
    env = np.exp(-t / 0.07) * np.minimum(1.0, t / 0.002)
    return np.sin(phase) * env


def _noise_hit(rate: int, length: float, decay: float, band: tuple[float, float] | float,
               rng: np.random.Generator) -> np.ndarray:
    n = int(length * rate)
    t = np.arange(n) / rate
    if isinstance(band, tuple):
        sos = signal.butter(4, band, btype="bandpass", fs=rate, output="sos")
    else:
        sos = signal.butter(4, band, btype="highpass", fs=rate, output="sos")
    noise = signal.sosfilt(sos, rng.standard_normal(n))
    noise /= np.max(np.abs(noise)) or 1.0
    return noise * np.exp(-t / decay) * np.minimum(1.0, t / 0.001)


def _place(out: np.ndarray, hit: np.ndarray, at: int, gain: float) -> None:
    """Add ``hit`` at frame ``at``, wrapping past the end (the loop continues into its start)."""
    n = min(len(hit), len(out))
    end = at + n
    if end <= len(out):
        out[at:end] += gain * hit[:n]
    else:
        split = len(out) - at
        out[at:] += gain * hit[:split]
        out[: n - split] += gain * hit[split:n]


def exercise_beat(bpm: float, rate: int = 44100, channels: int = 2, seed: int = 7) -> np.ndarray:
    """``BARS_PER_LOOP`` bars of the exercise beat at ``bpm``, (frames, channels) float32."""
    beats = BEATS_PER_BAR * BARS_PER_LOOP
    period = 60.0 * rate / bpm  # frames per beat (not an integer in general)
    frames = round(beats * period)
    rng = np.random.default_rng(seed)
    kick = _kick(rate)
    hat = _noise_hit(rate, 0.05, 0.012, 7000.0, rng)
    clap = _noise_hit(rate, 0.15, 0.04, (900.0, 2500.0), rng)
    mono = np.zeros(frames)
    for beat in range(beats):
        at = round(beat * period) % frames
        _place(mono, kick, at, 0.62 if beat % BEATS_PER_BAR == 0 else 0.5)
        if beat % BEATS_PER_BAR in (1, 3):
            _place(mono, clap, at, 0.12)
        _place(mono, hat, round((beat + 0.5) * period) % frames, 0.08)
    mono = np.clip(mono, -0.95, 0.95)
    return np.repeat(mono[:, None], channels, axis=1).astype(np.float32)


def relaxing_pad(rate: int = 44100, channels: int = 2, loop: float = PAD_LOOP) -> np.ndarray:
    """A calm chord that swells over 8 s, ``loop`` s long and seamless, (frames, channels) float32."""
    frames = round(loop * rate)
    t = np.arange(frames) / rate
    step = 1.0 / loop  # every partial completes whole cycles in the loop

    def snap(f: float) -> float:
        return round(f / step) * step

    chord = (110.0, 164.81, 220.0, 277.18, 329.63)  # A2 E3 A3 C#4 E4
    left = np.zeros(frames)
    right = np.zeros(frames)
    for i, f in enumerate(chord):
        amp = 1.0 / (1 + i)
        for detune, pan in ((-step * 2, 0.7), (step * 2, 0.3)):
            tone = amp * np.sin(2 * np.pi * snap(f + detune) * t + i)
            left += pan * tone
            right += (1 - pan) * tone
    swell = 0.65 + 0.35 * np.sin(2 * np.pi * t / (loop / 2))  # two breaths per loop
    stereo = np.stack([left, right], axis=1) * swell[:, None]
    stereo *= 0.3 / np.max(np.abs(stereo))
    if channels == 1:
        stereo = stereo.mean(axis=1, keepdims=True)
    elif channels > 2:
        stereo = np.concatenate([stereo, np.zeros((frames, channels - 2))], axis=1)
    return stereo.astype(np.float32)

"""Where the mix goes: the sound card (sounddevice), a null sink paced by a clock, and a WAV recorder.

- :class:`DeviceSink`: the real output device through sounddevice (PortAudio); its blocking
  write paces playback at the device's rate.
- :class:`NullSink`: no device; consumes samples at the rate of an injected clock (wall time,
  or ROS time under use_sim_time), keeping ``lead`` s ahead like a device buffer.
- :class:`RecordingSink`: wraps either and writes exactly what was handed to it to a WAV file.

:func:`open_sink` picks one from the ``sink`` option: ``auto`` (the device when PortAudio and
an output device exist, else the null sink with one info line), ``device``, ``null``.
"""

from __future__ import annotations

import importlib
import logging
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import ClassVar, Protocol

import numpy as np
import soundfile as sf

from audio_video_streamers.pacing import Clock, ClockTicks, Pacer, Schedule, Sleeper, wait_on_event


class SinkError(RuntimeError):
    """The requested output cannot be opened (one line)."""


class AudioSink(Protocol):
    rate: int
    channels: int
    kind: str  # "device" | "null"

    def write(self, block: np.ndarray, stop: threading.Event) -> bool:
        """Play ``block`` (frames, channels); False when ``stop`` ended the wait first."""

    def close(self) -> None: ...


class NullSink:
    """Consumes samples at the injected clock's rate, ``lead`` s ahead of it."""

    kind = "null"

    def __init__(self, rate: int, channels: int, clock: Clock, *, lead: float = 0.1,
                 max_lag: float = 1.0, sleep: Sleeper = wait_on_event,
                 ticks: ClockTicks | None = None) -> None:
        self.rate, self.channels = rate, channels
        self.schedule = Schedule(Pacer(clock, sleep=sleep, ticks=ticks), lead=lead, max_lag=max_lag)
        self.frames_played = 0

    def write(self, block: np.ndarray, stop: threading.Event) -> bool:
        if not self.schedule.wait_next(len(block) / self.rate, stop):
            return False
        self.frames_played += len(block)
        return True

    @property
    def resyncs(self) -> int:
        return self.schedule.resyncs

    def close(self) -> None:
        pass


def load_sounddevice() -> ModuleType:
    """The sounddevice module; OSError when PortAudio is missing (as on a headless machine)."""
    return importlib.import_module("sounddevice")


class DeviceSink:
    """The sound card through sounddevice; ``backend`` is the sounddevice module (a fake in tests)."""

    kind = "device"

    def __init__(self, backend: ModuleType, rate: int, channels: int, *, device: str = "",
                 block: int = 1024, latency: float = 0.1) -> None:
        self.rate, self.channels, self.backend = rate, channels, backend
        dev: int | str | None = int(device) if device.isdigit() else (device or None)
        try:
            info = backend.query_devices(dev, "output")
            backend.check_output_settings(device=dev, channels=channels, samplerate=rate, dtype="float32")
            self.stream = backend.OutputStream(samplerate=rate, channels=channels, dtype="float32",
                                               device=dev, blocksize=block, latency=latency)
            self.stream.start()
        except (backend.PortAudioError, ValueError) as exc:
            raise SinkError(f"audio device {device or 'default'}: {str(exc).strip() or type(exc).__name__}") \
                from None
        self.name = str(info.get("name", dev)) if isinstance(info, dict) else str(dev)
        self.underruns = 0
        self.frames_played = 0

    def write(self, block: np.ndarray, stop: threading.Event) -> bool:
        if stop.is_set():
            return False
        if self.stream.write(np.ascontiguousarray(block, dtype=np.float32)):
            self.underruns += 1
        self.frames_played += len(block)
        return True

    def close(self) -> None:
        try:
            self.stream.stop()
        finally:
            self.stream.close()


class RecordingSink:
    """Plays through ``inner`` and appends every block it played to a WAV file."""

    SUBTYPES: ClassVar[dict[str, str]] = {"pcm16": "PCM_16", "float": "FLOAT"}

    def __init__(self, inner: AudioSink, path: Path, fmt: str = "pcm16", flush_every: float = 1.0) -> None:
        self.inner, self.path = inner, path
        self.rate, self.channels, self.kind = inner.rate, inner.channels, inner.kind
        if not path.parent.is_dir():
            raise SinkError(f"record_wav: directory {path.parent} does not exist")
        try:
            self.file = sf.SoundFile(str(path), "w", samplerate=inner.rate, channels=inner.channels,
                                     subtype=self.SUBTYPES[fmt], format="WAV")
        except (sf.LibsndfileError, RuntimeError, OSError) as exc:
            raise SinkError(f"record_wav: cannot write {path}: {exc}") from None
        self._flush_frames = max(1, int(flush_every * inner.rate))
        self._since_flush = 0
        self.frames_recorded = 0
        self._lock = threading.Lock()

    def write(self, block: np.ndarray, stop: threading.Event) -> bool:
        if not self.inner.write(block, stop):
            return False
        with self._lock:
            if self.file.closed:
                return False
            self.file.write(block)
            self.frames_recorded += len(block)
            self._since_flush += len(block)
            if self._since_flush >= self._flush_frames:
                self.file.flush()
                self._since_flush = 0
        return True

    def close(self) -> None:
        try:
            self.inner.close()
        finally:
            with self._lock:
                if not self.file.closed:
                    self.file.close()

    def __getattr__(self, name: str) -> object:
        return getattr(self.inner, name)


def open_sink(mode: str, rate: int, channels: int, clock: Clock, log: logging.Logger, *,
              device: str = "", block: int = 1024, latency: float = 0.1, record_wav: str = "",
              record_format: str = "pcm16", ticks: ClockTicks | None = None,
              backend_loader: Callable[[], ModuleType] = load_sounddevice) -> AudioSink:
    """The sink the options ask for (see the module docstring); :class:`SinkError` if it cannot open."""
    sink: AudioSink | None = None
    if mode in ("auto", "device"):
        try:
            backend = backend_loader()
        except OSError as exc:
            if mode == "device":
                raise SinkError(f"sink device: sounddevice cannot load PortAudio ({exc})") from None
            log.info(f"no sound output (PortAudio: {exc}): playing into the null sink")
        else:
            try:
                sink = DeviceSink(backend, rate, channels, device=device, block=block, latency=latency)
            except SinkError as exc:
                if mode == "device":
                    raise
                log.info(f"no usable sound output ({exc}): playing into the null sink")
            else:
                log.info(f"playing on the sound device {sink.name}")
    if sink is None:
        sink = NullSink(rate, channels, clock, lead=latency, ticks=ticks)
    if record_wav:
        sink = RecordingSink(sink, Path(record_wav).expanduser(), record_format)
        log.info(f"recording what is played to {record_wav}")
    return sink

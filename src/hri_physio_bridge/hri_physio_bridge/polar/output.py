"""Where the session's samples and markers go: the :class:`Sink` interface and an in-memory sink.

The real sink is :class:`hri_physio_bridge.polar.lsl_output.LslSink` (pylsl outlets); tests use
:class:`MemorySink`. Streams are declared once and stay open across reconnections, so a
consumer's inlet never sees its stream disappear while the strap reconnects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol


@dataclass(frozen=True)
class OutputStream:
    key: str  # ecg, acc, ..., or "markers"
    name: str  # LSL name, e.g. PolarH10/A1B2C3D4/ECG
    type: str  # LSL type: ECG, ACC, HR, RR, PPG, PPI, Markers
    channels: tuple[str, ...]
    units: tuple[str, ...]
    nominal_rate: float  # Hz, 0 = irregular
    source_id: str
    #: string channel (markers) instead of float64
    text: bool = False
    device: dict[str, str] = field(default_factory=dict)


class Sink(Protocol):
    def open(self, stream: OutputStream) -> None: ...

    def reopen(self, stream: OutputStream) -> None:
        """Declare an opened stream anew (its rate was corrected): the old declaration goes away."""
        ...

    def push(self, key: str, stamps: list[float], rows: list[list[float]]) -> None: ...

    def marker(self, key: str, stamp: float, text: str) -> None: ...

    def consumers(self, key: str) -> bool: ...

    def close(self) -> None: ...


class MemorySink:
    """Keeps every declared stream, sample and marker (tests, dry runs)."""

    def __init__(self) -> None:
        self.streams: dict[str, OutputStream] = {}
        self.samples: dict[str, list[tuple[float, list[float]]]] = {}
        self.markers: list[tuple[float, str]] = []
        self.reopened: list[OutputStream] = []
        self.closed = False

    def open(self, stream: OutputStream) -> None:
        self.streams[stream.key] = stream
        self.samples.setdefault(stream.key, [])

    def reopen(self, stream: OutputStream) -> None:
        if stream.key not in self.streams:
            raise KeyError(f"stream {stream.key} was not opened")
        self.reopened.append(stream)
        self.streams[stream.key] = stream

    def push(self, key: str, stamps: list[float], rows: list[list[float]]) -> None:
        if key not in self.streams:
            raise KeyError(f"stream {key} was not opened")
        self.samples[key].extend(zip(stamps, rows, strict=True))

    def marker(self, key: str, stamp: float, text: str) -> None:
        self.markers.append((stamp, text))

    def consumers(self, key: str) -> bool:
        return False

    def close(self) -> None:
        self.closed = True

    # helpers for tests
    def stamps(self, key: str) -> list[float]:
        return [t for t, _ in self.samples.get(key, [])]

    def values(self, key: str) -> list[list[float]]:
        return [row for _, row in self.samples.get(key, [])]

    def events(self) -> list[dict[str, Any]]:
        import json

        return [json.loads(text) for _, text in self.markers]

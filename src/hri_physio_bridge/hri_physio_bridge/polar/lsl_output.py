"""The Polar streamer's LSL side: one LSL output streamer per stream plus a marker stream.

Outlets are made the one way the project makes them,
:meth:`hri_physio_bridge.streamers.lsl.LslStreamer.open_output`: they are created when a stream is
first started and live until the streamer exits, so consumers keep their inlets through
reconnections. Every sample is pushed with its own timestamp (the session's per-sample mapping
onto ``pylsl.local_clock()``); channel labels, units and the device are in the stream description.
"""

from __future__ import annotations

import time

import numpy as np

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.polar.output import OutputStream
from hri_physio_bridge.streamers.base import StreamSpec
from hri_physio_bridge.streamers.lsl import LINGER, LslStreamer


def stream_spec(stream: OutputStream) -> StreamSpec:
    """What an LSL outlet declares for one of the session's streams."""
    return StreamSpec(
        name=stream.name, type=stream.type, channel_count=len(stream.channels),
        nominal_rate=stream.nominal_rate, dtype="string" if stream.text else "float64",
        source_id=stream.source_id, channels=stream.channels, units=stream.units,
        device=tuple(stream.device.items()),
    )


class LslSink:
    """A :class:`~hri_physio_bridge.polar.output.Sink` on real LSL outlets."""

    def __init__(self, max_buffered: int = 360) -> None:
        self.max_buffered = max_buffered
        self._outlets: dict[str, LslStreamer] = {}
        self.streams: dict[str, OutputStream] = {}

    def open(self, stream: OutputStream) -> None:
        if stream.key in self._outlets:
            return
        outlet = LslStreamer(stream.name, max_buflen=self.max_buffered)
        outlet.open_output(stream_spec(stream))
        self._outlets[stream.key] = outlet
        self.streams[stream.key] = stream

    def reopen(self, stream: OutputStream) -> None:
        """A new outlet with the stream's corrected declaration (same name and source id)."""
        old = self._outlets.pop(stream.key, None)
        if old is not None:
            old.close(linger=0.0)
        self.open(stream)

    def push(self, key: str, stamps: list[float], rows: list[list[float]]) -> None:
        frame = Frame(np.asarray(stamps, dtype=np.float64), np.asarray(rows, dtype=np.float64),
                      self.streams[key].channels)
        self._outlets[key].publish(frame)

    def marker(self, key: str, stamp: float, text: str) -> None:
        outlet = self._outlets.get(key)
        if outlet is not None:
            values = np.array([[text]], dtype=object)
            outlet.publish(Frame(np.array([stamp]), values, self.streams[key].channels))

    def consumers(self, key: str) -> bool:
        outlet = self._outlets.get(key)
        return bool(outlet is not None and outlet.has_consumers())

    def close(self) -> None:
        # One moment for connected inlets to take the last chunks of every outlet, then close them all.
        if any(outlet.has_consumers() for outlet in self._outlets.values()):
            time.sleep(LINGER)
        for outlet in self._outlets.values():
            outlet.close(linger=0.0)
        self._outlets.clear()

"""The Polar streamer's LSL side: one pylsl outlet per stream plus a marker outlet.

Outlets are created when a stream is first started and live until the streamer exits, so
consumers keep their inlets through reconnections. Every sample is pushed with its own
timestamp (the session's per-sample mapping onto ``pylsl.local_clock()``); channel labels,
units and the device are in the stream description.
"""

from __future__ import annotations

import time

import pylsl

from hri_physio_bridge.polar.output import OutputStream


class LslSink:
    """A :class:`~hri_physio_bridge.polar.output.Sink` on real pylsl outlets."""

    def __init__(self, max_buffered: int = 360) -> None:
        self.max_buffered = max_buffered
        self._outlets: dict[str, pylsl.StreamOutlet] = {}
        self.streams: dict[str, OutputStream] = {}

    def open(self, stream: OutputStream) -> None:
        if stream.key in self._outlets:
            return
        info = pylsl.StreamInfo(
            name=stream.name,
            type=stream.type,
            channel_count=len(stream.channels),
            nominal_srate=stream.nominal_rate,
            channel_format=pylsl.cf_string if stream.text else pylsl.cf_double64,
            source_id=stream.source_id,
        )
        desc = info.desc()
        channels = desc.append_child("channels")
        for label, unit in zip(stream.channels, stream.units, strict=True):
            ch = channels.append_child("channel")
            ch.append_child_value("label", label)
            ch.append_child_value("unit", unit)
            ch.append_child_value("type", stream.type)
        device = desc.append_child("acquisition")
        for key, value in stream.device.items():
            device.append_child_value(key, value)
        self._outlets[stream.key] = pylsl.StreamOutlet(info, chunk_size=0, max_buffered=self.max_buffered)
        self.streams[stream.key] = stream

    def push(self, key: str, stamps: list[float], rows: list[list[float]]) -> None:
        outlet = self._outlets[key]
        if len(rows) == 1:
            outlet.push_sample(rows[0], stamps[0])
        else:
            outlet.push_chunk(rows, timestamp=stamps)

    def marker(self, key: str, stamp: float, text: str) -> None:
        outlet = self._outlets.get(key)
        if outlet is not None:
            outlet.push_sample([text], stamp)

    def consumers(self, key: str) -> bool:
        outlet = self._outlets.get(key)
        return bool(outlet is not None and outlet.have_consumers())

    def close(self) -> None:
        if any(outlet.have_consumers() for outlet in self._outlets.values()):
            time.sleep(0.2)  # liblsl has no flush: give connected inlets a moment to take the last chunk
        self._outlets.clear()

"""Frames of samples and the frame layout, with no ROS import.

A frame is N samples x C channels with one source timestamp (LSL clock, seconds)
per sample. On ROS 2 it travels as a ``std_msgs/Float64MultiArray`` with two
labelled dims, ``samples`` and ``channels``; column 0 holds the timestamps and
the ``channels`` label lists ``t,<ch1>,<ch2>...`` (docs/ARCHITECTURE.md).
:func:`encode_layout` / :func:`decode_layout` are the only code that knows this layout;
``ros_frames`` puts their result into and out of the message types.

String (marker) streams travel as ``std_msgs/String`` holding one JSON object
``{"t": <timestamp>, "data": <text>}`` per sample (:func:`encode_marker`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

SAMPLES_LABEL = "samples"
CHANNELS_LABEL = "channels"
TIME_LABEL = "t"


class FrameFormatError(ValueError):
    """A message or array does not have the frame layout of DESIGN.md."""


def default_channel_names(count: int) -> tuple[str, ...]:
    return tuple(f"ch{i + 1}" for i in range(count))


@dataclass
class Frame:
    """N samples x C channels with a source timestamp per sample."""

    timestamps: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        self.timestamps = np.asarray(self.timestamps, dtype=np.float64).reshape(-1)
        values = np.asarray(self.values)
        if values.ndim == 1:
            values = values.reshape(-1, 1)
        if values.ndim != 2:
            raise FrameFormatError(f"frame values must be 2-D (samples x channels), got {values.ndim}-D")
        if values.shape[0] != self.timestamps.shape[0]:
            raise FrameFormatError(
                f"frame has {values.shape[0]} samples but {self.timestamps.shape[0]} timestamps"
            )
        self.values = values
        if not self.channels:
            self.channels = default_channel_names(values.shape[1])
        self.channels = tuple(self.channels)
        if len(self.channels) != values.shape[1]:
            raise FrameFormatError(
                f"frame has {values.shape[1]} channels but {len(self.channels)} channel names"
            )

    @property
    def num_samples(self) -> int:
        return int(self.timestamps.shape[0])

    @property
    def num_channels(self) -> int:
        return int(self.values.shape[1])

    def __len__(self) -> int:
        return self.num_samples

    @property
    def is_string(self) -> bool:
        return self.values.dtype.kind in ("U", "S", "O")

    def slice(self, start: int, stop: int) -> Frame:
        return Frame(self.timestamps[start:stop], self.values[start:stop], self.channels)

    @staticmethod
    def concat(frames: Sequence[Frame]) -> Frame:
        if not frames:
            raise ValueError("cannot concatenate zero frames")
        return Frame(
            np.concatenate([f.timestamps for f in frames]),
            np.concatenate([f.values for f in frames]),
            frames[0].channels,
        )


class Dim(NamedTuple):
    """One ``MultiArrayDimension`` of the layout."""

    label: str
    size: int
    stride: int


def encode_layout(frame: Frame) -> tuple[list[Dim], np.ndarray]:
    """The two dims and the flat float64 data (column 0 = timestamps) of a numeric frame.

    Integer channels are carried as float64, exact up to 2**53.
    """
    if frame.is_string:
        raise FrameFormatError("string frames travel as std_msgs/String markers, not Float64MultiArray")
    n, c = frame.num_samples, frame.num_channels
    table = np.empty((n, c + 1), dtype=np.float64)
    table[:, 0] = frame.timestamps
    table[:, 1:] = frame.values
    dims = [
        Dim(SAMPLES_LABEL, n, n * (c + 1)),
        Dim(CHANNELS_LABEL + ":" + ",".join((TIME_LABEL, *frame.channels)), c + 1, c + 1),
    ]
    return dims, table.ravel()


def _parse_channels_label(label: str, size: int) -> tuple[str, ...]:
    kind, sep, names = label.partition(":")
    if kind != CHANNELS_LABEL:
        raise FrameFormatError(f"second dim label must start with '{CHANNELS_LABEL}', got {label!r}")
    if not sep:
        return default_channel_names(size - 1)
    parts = tuple(names.split(","))
    if len(parts) != size or parts[0] != TIME_LABEL:
        raise FrameFormatError(
            f"channels label {label!r} must list '{TIME_LABEL}' then {size - 1} channel names"
        )
    return parts[1:]


def decode_layout(dims: Sequence[tuple[str, int, int]], data_offset: int, data: Sequence[float]) -> Frame:
    """The frame described by a message's dims, data offset and data (see :func:`encode_layout`)."""
    if len(dims) != 2 or dims[0][0] != SAMPLES_LABEL:
        labels = [d[0] for d in dims]
        raise FrameFormatError(
            f"expected 2 dims labelled '{SAMPLES_LABEL}' and '{CHANNELS_LABEL}', got {labels}"
        )
    n, width = int(dims[0][1]), int(dims[1][1])
    if width < 1:
        raise FrameFormatError("a frame needs at least the timestamp column")
    channels = _parse_channels_label(dims[1][0], width)
    offset = int(data_offset)
    values = np.asarray(data, dtype=np.float64)
    if values.shape[0] - offset != n * width:
        raise FrameFormatError(
            f"layout says {n} samples x {width} columns but data holds {values.shape[0] - offset} values"
        )
    table = values[offset:].reshape(n, width)
    return Frame(table[:, 0].copy(), table[:, 1:].copy(), channels)


def encode_marker(timestamp: float, data: str) -> str:
    """One string sample as the JSON text ``{"t": ..., "data": ...}``."""
    return json.dumps({"t": float(timestamp), "data": str(data)})


def decode_marker(text: str) -> tuple[float, str]:
    try:
        obj = json.loads(text)
        t = float(obj["t"])
        data = obj["data"]
    except (ValueError, TypeError, KeyError) as exc:
        raise FrameFormatError(
            f'marker must be JSON {{"t": <seconds>, "data": <text>}}, got {text[:80]!r}'
        ) from exc
    if not math.isfinite(t):
        raise FrameFormatError(f"marker timestamp must be finite, got {t}")
    return t, str(data)

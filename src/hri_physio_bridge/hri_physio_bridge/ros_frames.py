"""Frames on ROS 2: the std_msgs side of the frame layout (``frames`` holds the layout itself).

``frame_to_msg`` / ``msg_to_frame`` put a :class:`~hri_physio_bridge.frames.Frame` into and out of
a ``std_msgs/Float64MultiArray``; string samples travel as ``std_msgs/String`` markers.
"""

from __future__ import annotations

from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from hri_physio_bridge.frames import (
    Frame,
    FrameFormatError,
    decode_layout,
    decode_marker,
    encode_layout,
    encode_marker,
)


def frame_to_msg(frame: Frame) -> Float64MultiArray:
    """Encode a numeric frame as a Float64MultiArray (column 0 = timestamps)."""
    dims, data = encode_layout(frame)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=d.label, size=d.size, stride=d.stride) for d in dims]
    msg.layout.data_offset = 0
    msg.data = data
    return msg


def msg_to_frame(msg: Float64MultiArray) -> Frame:
    """Decode a Float64MultiArray produced by :func:`frame_to_msg`."""
    dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
    return decode_layout(dims, msg.layout.data_offset, msg.data)


def marker_to_msg(timestamp: float, data: str) -> String:
    """Encode one string sample as a JSON ``{"t": ..., "data": ...}`` String."""
    return String(data=encode_marker(timestamp, data))


def msg_to_marker(msg: String) -> tuple[float, str]:
    return decode_marker(msg.data)


def string_frame_to_msgs(frame: Frame) -> list[String]:
    """One String message per sample of a (single-channel) string frame."""
    if frame.num_channels != 1:
        raise FrameFormatError(f"string streams have one channel, this frame has {frame.num_channels}")
    return [marker_to_msg(t, v) for t, v in zip(frame.timestamps, frame.values[:, 0], strict=True)]

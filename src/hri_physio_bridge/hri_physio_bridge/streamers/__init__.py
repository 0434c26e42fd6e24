"""Streamers: one interface, several transports, chosen by URI (see factory)."""

from hri_physio_bridge.streamers.base import (
    OpenCancelled,
    Streamer,
    StreamerError,
    StreamLostError,
    StreamMismatchError,
    StreamNotFoundError,
    StreamSpec,
    canonical_dtype,
    numpy_dtype,
)
from hri_physio_bridge.streamers.factory import create_streamer, register, split_uri

__all__ = [
    "OpenCancelled",
    "StreamLostError",
    "StreamMismatchError",
    "StreamNotFoundError",
    "StreamSpec",
    "Streamer",
    "StreamerError",
    "canonical_dtype",
    "create_streamer",
    "numpy_dtype",
    "register",
    "split_uri",
]

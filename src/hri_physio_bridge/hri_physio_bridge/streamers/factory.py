"""Pick a streamer from a URI-like string: ``lsl:...``, ``ros:...``, ``csv:...``.

New transports (UDP, MQTT, ...) register a constructor with :func:`register`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hri_physio_bridge.streamers.base import Streamer

StreamerConstructor = Callable[..., Streamer]
_REGISTRY: dict[str, StreamerConstructor] = {}


def register(scheme: str, constructor: StreamerConstructor) -> None:
    _REGISTRY[scheme] = constructor


def _lsl(address: str, *, max_chunk: int = 1024, **_: Any) -> Streamer:
    from hri_physio_bridge.streamers.lsl import LslStreamer

    return LslStreamer(address, max_chunk=max_chunk)


def _csv(address: str, *, max_chunk: int = 1024, **_: Any) -> Streamer:
    from hri_physio_bridge.streamers.csv_stream import CsvStreamer

    return CsvStreamer(address, max_chunk=max_chunk)


def _ros(address: str, *, node: Any = None, depth: int | None = None, **_: Any) -> Streamer:
    from hri_physio_bridge.streamers.ros import RosStreamer

    return RosStreamer(address, node=node) if depth is None else RosStreamer(address, node=node, depth=depth)


register("lsl", _lsl)
register("csv", _csv)
register("ros", _ros)


def split_uri(uri: str) -> tuple[str, str]:
    scheme, sep, address = str(uri).partition(":")
    if not sep or not scheme:
        raise ValueError(
            f"stream address {uri!r} has no scheme; write <scheme>:<address> with scheme one of "
            f"{', '.join(sorted(_REGISTRY))} (e.g. lsl:PolarH10/1234/ECG, ros:/physio/polar_h10/ecg, "
            f"csv:session/ecg.csv)"
        )
    scheme = scheme.lower()
    if scheme not in _REGISTRY:
        raise ValueError(
            f"unknown stream scheme {scheme!r} in {uri!r}; known schemes: {', '.join(sorted(_REGISTRY))}"
        )
    if not address:
        raise ValueError(f"stream address {uri!r} is empty after '{scheme}:'")
    return scheme, address


def create_streamer(uri: str, **options: Any) -> Streamer:
    """Build the streamer for ``uri``. Options: ``node`` and ``depth`` (for ros:), ``max_chunk``."""
    scheme, address = split_uri(uri)
    return _REGISTRY[scheme](address, **options)


def needs_ros_node(uri: str) -> bool:
    return split_uri(uri)[0] == "ros"

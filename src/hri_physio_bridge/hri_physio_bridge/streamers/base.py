"""The streamer interface every transport (LSL, ROS 2, CSV, ...) implements."""

from __future__ import annotations

import abc
import threading
from dataclasses import dataclass, field
from urllib.parse import parse_qs

import numpy as np

from hri_physio_bridge.frames import Frame, default_channel_names


class StreamerError(RuntimeError):
    """A streamer could not do what was asked; the message says why."""


class StreamNotFoundError(StreamerError):
    """The input stream did not appear within the timeout."""


class OpenCancelled(StreamNotFoundError):
    """A stop was requested while waiting for the input to appear."""


class StreamLostError(StreamerError):
    """A connected input went away (it may come back: reopen to wait for it)."""


class StreamMismatchError(StreamerError):
    """The stream's shape or type does not match the configuration."""


# Channel formats the seed supports, by canonical name, with their aliases.
_DTYPES: dict[str, tuple[str, np.dtype | None]] = {
    "float64": ("float64", np.dtype(np.float64)),
    "float32": ("float32", np.dtype(np.float32)),
    "int64": ("int64", np.dtype(np.int64)),
    "int32": ("int32", np.dtype(np.int32)),
    "int16": ("int16", np.dtype(np.int16)),
    "int8": ("int8", np.dtype(np.int8)),
    "string": ("string", None),
}
_ALIASES = {
    "double": "float64", "double64": "float64", "float": "float32", "long": "int64",
    "longlong": "int64", "int": "int32", "short": "int16", "char": "int8", "str": "string",
}


def split_address(address: str, kind: str, what: str, known: set[str]) -> tuple[str, dict[str, str]]:
    """Split ``<target>?key=value&...`` and refuse options the transport does not know."""
    target, _, query = address.partition("?")
    if not target:
        raise ValueError(f"{kind} address {address!r} has no {what}")
    params = {k: v[-1] for k, v in parse_qs(query, keep_blank_values=True).items()}
    unknown = set(params) - known
    if unknown:
        raise ValueError(
            f"unknown {kind} option(s) {sorted(unknown)} in {address!r}; known: {sorted(known)}"
        )
    return target, params


def canonical_dtype(name: str) -> str:
    """Canonical channel-format name for ``name`` (e.g. 'double' -> 'float64')."""
    key = str(name).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in _DTYPES:
        known = ", ".join([*_DTYPES, *_ALIASES])
        raise ValueError(f"unknown dtype {name!r}; supported: {known}")
    return key


def numpy_dtype(name: str) -> np.dtype:
    """numpy dtype used to hold samples of this channel format."""
    key = canonical_dtype(name)
    dt = _DTYPES[key][1]
    return dt if dt is not None else np.dtype(object)


@dataclass
class StreamSpec:
    """What an output declares (and an input is checked against)."""

    name: str
    type: str = "Physio"
    channel_count: int = 1
    nominal_rate: float = 0.0
    dtype: str = "float64"
    source_id: str = ""
    channels: tuple[str, ...] = field(default=())
    #: Optional description an output carries where its transport can (LSL's stream description):
    #: each channel's unit (empty, or one per channel) and the acquisition device's (key, value) pairs.
    units: tuple[str, ...] = field(default=())
    device: tuple[tuple[str, str], ...] = field(default=())

    def __post_init__(self) -> None:
        self.dtype = canonical_dtype(self.dtype)
        if self.channel_count < 1:
            raise ValueError(f"channel_count must be >= 1, got {self.channel_count}")
        if self.nominal_rate < 0:
            raise ValueError(f"nominal_rate must be >= 0 (0 = irregular), got {self.nominal_rate}")
        if not self.channels:
            self.channels = default_channel_names(self.channel_count)
        self.channels = tuple(self.channels)
        if len(self.channels) != self.channel_count:
            raise ValueError(
                f"{len(self.channels)} channel names given for {self.channel_count} channels"
            )
        self.units = tuple(self.units)
        if self.units and len(self.units) != self.channel_count:
            raise ValueError(f"{len(self.units)} units given for {self.channel_count} channels")
        self.device = tuple((str(k), str(v)) for k, v in self.device)

    @property
    def is_string(self) -> bool:
        return self.dtype == "string"


class Streamer(abc.ABC):
    """One end of a data path. Open it as an input or an output, not both."""

    #: URI scheme this streamer serves, e.g. "lsl".
    scheme: str = ""

    def __init__(self, address: str) -> None:
        self.address = address
        self.spec: StreamSpec | None = None
        #: Input messages that arrived but could not be used (malformed, wrong shape); counted, not fatal.
        self.bad_messages = 0
        #: Input messages the transport says it lost before they reached us (e.g. a full DDS reader queue).
        self.lost_messages = 0

    @property
    def uri(self) -> str:
        return f"{self.scheme}:{self.address}"

    @abc.abstractmethod
    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        """Connect to the source; return what it is. Raise StreamNotFoundError/StreamMismatchError.

        A transport that waits for its source gives up promptly with OpenCancelled once ``stop``
        is set (Ctrl-C during a long ``timeout``).
        """

    @abc.abstractmethod
    def open_output(self, spec: StreamSpec) -> None:
        """Create the sink declaring ``spec``."""

    @abc.abstractmethod
    def receive(self, timeout: float = 0.1) -> Frame | None:
        """Next chunk of samples (any size), or None when nothing arrived in ``timeout``.

        Raises StreamLostError when the source has gone away.
        """

    def _check_publishable(self, frame: Frame, is_open: bool, carries: str) -> StreamSpec:
        """The output's spec, once ``frame`` fits it. Raises StreamerError when the output is not open,
        StreamMismatchError when the frame's channels differ (``carries``: how the message names the
        output, e.g. "/topic carries")."""
        if not is_open or self.spec is None:
            raise StreamerError(f"{self.uri} is not open as an output")
        if frame.num_channels != self.spec.channel_count:
            raise StreamMismatchError(
                f"frame has {frame.num_channels} channels, {carries} {self.spec.channel_count}")
        return self.spec

    @abc.abstractmethod
    def publish(self, frame: Frame) -> None:
        """Send a frame of samples."""

    def backlog(self) -> int:
        """Input chunks received by the transport but not yet taken with :meth:`receive`."""
        return 0

    #: Whether this input's timestamps are mapped onto the local clock (LSL time correction, ``sync=1``).
    corrects_clock = False

    def clock_offset(self) -> float | None:
        """This input's clock offset: what a timestamp taken on the source's clock needs added to be on
        ours, in s, as last measured (LSL's time correction); None where the transport measures none
        (yet)."""
        return None

    #: Whether :meth:`consumer_count` can count listeners (not just tell whether there is one).
    counts_consumers = False

    def has_consumers(self) -> bool:
        """Whether anything listens to this output (transports that cannot tell say True)."""
        return True

    def consumer_count(self) -> int:
        """How many listen to this output; only meaningful when ``counts_consumers``."""
        return int(self.has_consumers())

    def close(self) -> None:  # noqa: B027 - optional hook, most streamers need it
        """Release the transport (idempotent)."""

    def abandon(self) -> None:
        """Close an output that a failed start leaves before any data: as :meth:`close`, and what it
        created for nothing goes too (an empty CSV file would refuse the corrected rerun)."""
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.uri!r})"

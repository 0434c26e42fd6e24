"""Lab Streaming Layer streamer (pylsl).

Address: ``<stream name>[?type=<type>&source_id=<id>&sync=1&dejitter=1]``, e.g.
``lsl:PolarH10/1234/ECG`` or ``lsl:PolarH10/1234/ECG?type=ECG``. As an input the
stream is resolved by name (and type / source id when given); ``sync=1`` turns
on liblsl's clock synchronisation (``proc_clocksync``) for streams coming from
another machine: each timestamp gets the measured offset between the sender's
LSL clock and ours added, so it is on this host's clock. It is off by default
(on one machine the sender's timestamps are already on our clock, and we keep
them unchanged); a lab's station turns it on. Either way the measured offset is
reported (:meth:`LslStreamer.clock_offset`).

``dejitter=1`` turns on liblsl's dejitter (``proc_dejitter | proc_monotonize``) for
a source whose own stamps jitter: one that stamps each chunk on arrival (a BLE
strap's app pushing each notification with the time it came in) makes every chunk
boundary a step of a few milliseconds forward or back, which the processor takes
for lost samples or a clock jump, and its windows never fill. liblsl then replaces
the stamps by its running regression line of the stream's sampling. It is off by
default: on a stream stamped sample by sample (ours, ``polar_streamer``'s) that line
would hide the gaps and clock jumps the receiver reports.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pylsl

from hri_physio_bridge.frames import Frame
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
    split_address,
)
from hri_physio_bridge.waiting import wait_until

_TO_LSL = {
    "float64": pylsl.cf_double64,
    "float32": pylsl.cf_float32,
    "int64": pylsl.cf_int64,
    "int32": pylsl.cf_int32,
    "int16": pylsl.cf_int16,
    "int8": pylsl.cf_int8,
    "string": pylsl.cf_string,
}
_FROM_LSL = {v: k for k, v in _TO_LSL.items()}
_QUERY_KEYS = {"type", "source_id", "sync", "dejitter"}
#: Seconds between two looks at the resolver's results while waiting for an input stream.
RESOLVE_POLL = 0.05
#: Seconds a status waits for liblsl's first time-correction estimate (later ones are instantaneous).
OFFSET_TIMEOUT = 0.05
#: Seconds a closing outlet with consumers waits for them to take its last chunk (liblsl has no flush).
LINGER = 0.2


def parse_lsl_address(address: str) -> tuple[str, dict[str, str]]:
    return split_address(address, "LSL", "stream name", _QUERY_KEYS)


def describe_stream(info: pylsl.StreamInfo) -> str:
    return (
        f"{info.name()} (type={info.type()}, channels={info.channel_count()}, "
        f"rate={info.nominal_srate():g}, format={_FROM_LSL.get(info.channel_format(), '?')}, "
        f"source_id={info.source_id() or '-'})"
    )


def _spec_from_info(info: pylsl.StreamInfo) -> StreamSpec:
    labels: list[str] = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty() and len(labels) < info.channel_count():
        labels.append(ch.child_value("label"))
        ch = ch.next_sibling()
    if len(labels) != info.channel_count() or not all(labels):
        labels = []
    return StreamSpec(
        name=info.name(),
        type=info.type(),
        channel_count=info.channel_count(),
        nominal_rate=info.nominal_srate(),
        dtype=_FROM_LSL.get(info.channel_format(), "float64"),
        source_id=info.source_id(),
        channels=tuple(labels),
    )


class LslStreamer(Streamer):
    scheme = "lsl"

    def __init__(self, address: str, max_chunk: int = 1024, max_buflen: int = 360) -> None:
        super().__init__(address)
        self.name, self.params = parse_lsl_address(address)
        if max_chunk < 1:
            raise ValueError(f"max_chunk must be >= 1, got {max_chunk}")
        self.max_chunk = int(max_chunk)
        self.max_buflen = int(max_buflen)
        self._inlet: pylsl.StreamInlet | None = None
        self._outlet: pylsl.StreamOutlet | None = None
        self._dtype: np.dtype | None = None
        self.corrects_clock = self._switch("sync")
        self.dejitters = self._switch("dejitter")

    def _switch(self, key: str) -> bool:
        """An on/off address option (``?sync=1``): 1, true or yes turn it on."""
        return self.params.get(key, "0").lower() in ("1", "true", "yes")

    # -- input ---------------------------------------------------------------
    def _predicate(self) -> str:
        def quote(v: str) -> str:
            return "'" + v.replace("'", "") + "'"

        parts = [f"name={quote(self.name)}"]
        if self.params.get("type"):
            parts.append(f"type={quote(self.params['type'])}")
        if self.params.get("source_id"):
            parts.append(f"source_id={quote(self.params['source_id'])}")
        return " and ".join(parts)

    def _resolve(self, timeout: float, stop: threading.Event | None) -> pylsl.StreamInfo:
        """Wait up to ``timeout`` for the stream; give up promptly once ``stop`` is set.

        A continuous resolver is polled rather than one blocking resolve: the main thread
        stays in Python, so a signal handler (Ctrl-C) runs at once. (Short blocking resolves
        are no substitute: with liblsl 1.18 a 0.5 s resolve_bypred sometimes takes 5.5 s.)
        """
        held = [pylsl.ContinuousResolver(pred=self._predicate())]
        found: list[pylsl.StreamInfo] = []

        def stopped_or_appeared() -> bool:
            if stop is not None and stop.is_set():
                return True
            found[:] = held[0].results()
            return bool(found)

        wait_until(stopped_or_appeared, timeout, stop=stop, poll=RESOLVE_POLL)
        # liblsl may block for seconds destroying a resolver in the middle of a query wave: let a
        # daemon thread drop it, so a stop (or the error below) is never held up by that.
        threading.Thread(target=held.clear, name="lsl-resolver-release", daemon=True).start()
        if stop is not None and stop.is_set():
            raise OpenCancelled(f"stopped while waiting for LSL stream {self._predicate()}")
        if found:
            return found[0]
        seen = pylsl.resolve_streams(wait_time=min(1.0, max(timeout, 0.2)))
        listing = "; ".join(describe_stream(i) for i in seen) or "none"
        raise StreamNotFoundError(
            f"LSL stream {self._predicate()} did not appear within {timeout:g} s. Streams seen: {listing}"
        )

    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        self.close()
        info = self._resolve(timeout, stop)
        spec = _spec_from_info(info)
        if expected is not None:
            check_matches(spec, expected, self.uri)
        flags = pylsl.proc_clocksync if self.corrects_clock else 0
        if self.dejitters:
            flags |= pylsl.proc_dejitter | pylsl.proc_monotonize
        self._inlet = pylsl.StreamInlet(
            info, max_buflen=self.max_buflen, recover=False, processing_flags=flags
        )
        try:
            self._inlet.open_stream(timeout=max(timeout, 1.0))
        except Exception as exc:  # pylsl raises TimeoutError / LostError
            self.close()
            raise StreamLostError(f"could not open LSL stream {spec.name}: {exc}") from exc
        self.spec = spec
        self._dtype = numpy_dtype(spec.dtype)
        return spec

    def backlog(self) -> int:
        """Chunks the inlet already holds (samples waiting, in chunks of ``max_chunk``)."""
        if self._inlet is None:
            return 0
        try:
            waiting = int(self._inlet.samples_available())
        except pylsl.util.LostError:
            return 0
        return -(-waiting // self.max_chunk)

    def clock_offset(self) -> float | None:
        """liblsl's current time correction of this inlet (s): applied to every timestamp with
        ``sync=1``, measured only otherwise. None before its first estimate or without an inlet."""
        if self._inlet is None:
            return None
        try:
            return float(self._inlet.time_correction(timeout=OFFSET_TIMEOUT))
        except (pylsl.util.TimeoutError, pylsl.util.LostError):
            return None

    def receive(self, timeout: float = 0.1) -> Frame | None:
        if self._inlet is None or self.spec is None:
            raise StreamerError(f"{self.uri} is not open as an input")
        try:
            samples, stamps = self._inlet.pull_chunk(
                timeout=timeout, max_samples=self.max_chunk, min_samples=1, as_numpy=True
            )
        except pylsl.util.LostError as exc:
            raise StreamLostError(f"LSL stream {self.name} was lost") from exc
        if stamps is None or len(stamps) == 0:
            return None
        if self.spec.is_string:
            values = np.array(
                [[v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v) for v in row]
                 for row in samples],
                dtype=object,
            )
        else:
            values = np.asarray(samples, dtype=self._dtype)
        return Frame(np.asarray(stamps, dtype=np.float64), values, self.spec.channels)

    # -- output --------------------------------------------------------------
    def open_output(self, spec: StreamSpec) -> None:
        """An outlet declaring ``spec``: channel labels (and units, type) and the acquisition device."""
        self.close()
        stream_type = self.params.get("type") or spec.type
        info = pylsl.StreamInfo(
            name=self.name,
            type=stream_type,
            channel_count=spec.channel_count,
            nominal_srate=spec.nominal_rate,
            channel_format=_TO_LSL[spec.dtype],
            source_id=self.params.get("source_id") or spec.source_id,
        )
        desc = info.desc()
        chans = desc.append_child("channels")
        for i, label in enumerate(spec.channels):
            channel = chans.append_child("channel")
            channel.append_child_value("label", label)
            if spec.units:
                channel.append_child_value("unit", spec.units[i])
                channel.append_child_value("type", stream_type)
        if spec.device:
            acquisition = desc.append_child("acquisition")
            for key, value in spec.device:
                acquisition.append_child_value(key, value)
        self._outlet = pylsl.StreamOutlet(info, chunk_size=0, max_buffered=self.max_buflen)
        self.spec = spec
        self._dtype = numpy_dtype(spec.dtype)

    def publish(self, frame: Frame) -> None:
        spec = self._check_publishable(frame, self._outlet is not None, f"LSL output {self.name} declares")
        if frame.num_samples == 0:
            return
        if spec.is_string:
            data = [[str(v) for v in row] for row in frame.values]
        else:
            data = np.ascontiguousarray(cast_for_output(frame.values, self._dtype, self.uri))
        self._outlet.push_chunk(data, timestamp=frame.timestamps.tolist())

    def has_consumers(self) -> bool:
        return bool(self._outlet is not None and self._outlet.have_consumers())

    def close(self, linger: float = LINGER) -> None:
        """Close the inlet or outlet; an outlet with consumers first waits ``linger`` s for them."""
        if self._inlet is not None:
            try:
                self._inlet.close_stream()
            finally:
                self._inlet = None
        if self._outlet is not None and linger > 0 and self._outlet.have_consumers():
            # liblsl has no flush: give connected inlets a moment to take the last chunk.
            time.sleep(linger)
        self._outlet = None  # liblsl destroys the outlet with the object


def check_matches(actual: StreamSpec, expected: StreamSpec, where: str) -> None:
    """Raise StreamMismatchError when a stream differs from the configuration."""
    problems = []
    if actual.channel_count != expected.channel_count:
        problems.append(
            f"it has {actual.channel_count} channel(s) but num_channels is {expected.channel_count}"
        )
    if canonical_dtype(actual.dtype) != canonical_dtype(expected.dtype):
        problems.append(f"its format is {actual.dtype} but dtype is {expected.dtype}")
    if problems:
        raise StreamMismatchError(f"{where}: " + "; ".join(problems))


def cast_for_output(values: np.ndarray, dtype: np.dtype, where: str) -> np.ndarray:
    """Cast to an integer/float output format, refusing values it cannot hold."""
    if dtype.kind != "i":
        return values.astype(dtype, copy=False)
    info = np.iinfo(dtype)

    def out_of_range() -> StreamMismatchError:
        return StreamMismatchError(
            f"{where}: values outside [{info.min}, {info.max}] cannot be sent as {dtype}"
        )

    if values.dtype.kind in "iu":
        # Integers cast exactly: no detour through float64, which rounds int64 beyond 2**53.
        if values.size and (values.min() < info.min or values.max() > info.max):
            raise out_of_range()
        return values.astype(dtype, copy=False)
    if not np.all(np.isfinite(values)):
        raise StreamMismatchError(f"{where}: NaN/inf cannot be sent on an integer ({dtype}) stream")
    rounded = np.rint(values)
    limit = 2.0 ** (info.bits - 1)  # [-limit, limit) holds the type, compared exactly as floats
    if rounded.size and (rounded.min() < -limit or rounded.max() >= limit):
        raise out_of_range()
    return rounded.astype(dtype)

"""The physio receiver pipeline: input streamer -> CSV log -> ring buffer -> output streamer.

Plain Python on two threads, as the seed's producer/consumer: the producer
pulls chunks from the input, logs every chunk (timestamps + values) before
buffering it, checks it and enqueues it; the consumer dequeues frames of
``output_frame`` samples with ``sample_overlap`` samples of overlap and
publishes them. Nothing here imports rclpy; the node wires the streamers.

When the input is lost the producer keeps trying to reopen it; the samples
that went missing are reported as a gap (first and last missing timestamp,
estimated from the nominal rate) and everything received before stays.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import field_validator, model_validator

from hri_physio_bridge.config import ConfigError, NodeConfig, option
from hri_physio_bridge.frames import Frame
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.ring_buffer import BufferClosed, Gap, OverflowPolicy, RingBuffer
from hri_physio_bridge.streamers.base import (
    OpenCancelled,
    Streamer,
    StreamerError,
    StreamLostError,
    StreamMismatchError,
    StreamSpec,
    canonical_dtype,
    numpy_dtype,
)
from hri_physio_bridge.streamers.csv_stream import CsvWriter
from hri_physio_bridge.streamers.factory import split_uri
from hri_physio_bridge.streamers.opener import StreamOpener
from hri_physio_bridge.timeline import ClockJump, ClockOffsetTrack, RateMeter, TimelineCheck
from hri_physio_bridge.waiting import Backoff, wait_for_consumers

#: The measured rate may differ from sampling_rate by this share before it is warned about.
RATE_TOLERANCE = 0.05
#: Seconds between two warnings about the measured rate (each says how often it was off since).
RATE_WARNING_PERIOD = 60.0


class ReceiverConfig(NodeConfig):
    """The seed's receiver options (conf.yaml keys) plus a few of our own."""

    SEED_KEYS: ClassVar[tuple[str, ...]] = (
        "input", "output", "dtype", "sampling_rate", "input_frame", "output_frame", "num_channels",
        "sample_overlap", "buffer_length", "log_data", "log_name",
    )

    input: str = option("lsl:PolarH10/SIM0001/ECG", "source stream address: lsl:<name>[?type=&source_id="
                        "&sync=1] (sync=1: LSL's time correction added to each stamp), ros:/<topic>, "
                        "csv:<file>[?rate=]", min_length=1)
    output: str = option("ros:/physio/polar_h10/ecg", "destination stream address (same schemes)",
                         min_length=1)
    dtype: str = option("float64", "channel format: float64|float32|int64|int32|int16|int8|string "
                        "(aliases: double, float, char...)")
    sampling_rate: float = option(130.0, "nominal rate (0 = irregular); checked against the input's "
                                  "declared and measured rate, used for gap detection and LSL outputs",
                                  unit="Hz", ge=0)
    input_frame: int = option(32, "largest chunk pulled from the input at once", unit="samples", ge=1)
    output_frame: int = option(1, "samples per published frame", unit="samples", ge=1)
    num_channels: int = option(1, "channels per sample (the input must match)", ge=1)
    sample_overlap: int = option(0, "samples each frame shares with the previous one (sliding window)",
                                 unit="samples", ge=0)
    buffer_length: int = option(5000, "ring buffer capacity", unit="samples", ge=1)
    log_data: bool = option(False, "write every received sample to a CSV log before buffering it")
    log_name: str = option("", "CSV log path (default logs/<stream>_<time>.csv); never overwritten")
    overflow_policy: str = option("block", "full buffer: block (wait, lose nothing) or drop_oldest "
                                  "(drop, report a gap)")
    resolve_timeout: float = option(10.0, "how long to wait for the input stream to appear", unit="s", ge=0)
    reconnect: bool = option(True, "when the input is lost, wait for it to come back (false: flush and exit)")
    stream_type: str = option("", "stream type declared on LSL outputs (default: the input's)")
    channel_names: list[str] = option([], "comma-separated channel labels (default: the input's)")
    wait_for_consumers: float = option(0.0, "how long to wait for a listener on the output before reading "
                                       "the input (0 = no wait)", unit="s", ge=0)
    min_consumers: int = option(1, "with wait_for_consumers: how many listeners to wait for, e.g. 2 for a "
                                "processor and a recorder (ros: outputs only)", ge=1)
    interactive: bool = option(False, "text console on stdin: status, pause, resume, quit", switch=True)
    drain_timeout: float = option(5.0, "at a stop, the most time spent taking what the input already "
                                  "holds, plus drain_per_chunk for each chunk it holds (an input still "
                                  "delivering after that is cut, with an error line)", unit="s", ge=0)
    drain_per_chunk: float = option(0.01, "the time a stop allows per chunk the input already holds",
                                    unit="s", ge=0)
    status_period: float = option(5.0, "time between progress reports", unit="s", gt=0)

    @field_validator("dtype")
    @classmethod
    def _dtype(cls, value: str) -> str:
        return canonical_dtype(value)

    @field_validator("input", "output")
    @classmethod
    def _address(cls, value: str) -> str:
        split_uri(value)  # a known scheme and an address: checked before anything starts
        return value

    @field_validator("overflow_policy")
    @classmethod
    def _policy(cls, value: str) -> str:
        return OverflowPolicy.parse(value).value

    @model_validator(mode="after")
    def _consistent(self) -> ReceiverConfig:
        if self.sample_overlap >= self.output_frame:
            raise ValueError(f"sample_overlap must be < output_frame ({self.output_frame}), "
                             f"got {self.sample_overlap}")
        if self.buffer_length < self.output_frame:
            raise ValueError(f"buffer_length must hold at least one output frame ({self.output_frame} "
                             f"samples), got {self.buffer_length}")
        if self.min_consumers > 1 and self.wait_for_consumers <= 0:
            raise ValueError("min_consumers only counts while waiting: set wait_for_consumers > 0 too")
        if self.channel_names and len(self.channel_names) != self.num_channels:
            raise ValueError(f"channel_names must list num_channels ({self.num_channels}) names, "
                             f"got {len(self.channel_names)}")
        return self

    def expected_spec(self) -> StreamSpec:
        return StreamSpec(
            name=self.input,
            type=self.stream_type or "Physio",
            channel_count=self.num_channels,
            nominal_rate=self.sampling_rate,
            dtype=self.dtype,
            channels=tuple(self.channel_names),
        )


@dataclass
class ReceiverStats:
    received_samples: int = 0
    received_chunks: int = 0
    published_samples: int = 0
    published_frames: int = 0
    logged_samples: int = 0
    nonfinite_samples: int = 0
    bad_timestamp_samples: int = 0  # samples dropped because their timestamp was NaN or infinite
    rejected_chunks: int = 0
    publish_errors: int = 0
    gaps: list[Gap] = field(default_factory=list)
    clock_jumps: list[ClockJump] = field(default_factory=list)
    reconnects: int = 0
    connected: bool = False
    paused: bool = False
    last_timestamp: float = math.nan
    measured_rate: float | None = None  # from the timestamps (None until a few seconds are in)
    unread_at_stop: int = 0  # input chunks (LSL: estimated) a stop left unread when its drain ran out
    unpublished_at_stop: int = 0  # buffered samples a stop left unpublished when its drain ran out

    def as_dict(self) -> dict[str, Any]:
        return {
            "connected": self.connected,
            "paused": self.paused,
            "received_samples": self.received_samples,
            "received_chunks": self.received_chunks,
            "published_samples": self.published_samples,
            "published_frames": self.published_frames,
            "logged_samples": self.logged_samples,
            "nonfinite_samples": self.nonfinite_samples,
            "bad_timestamp_samples": self.bad_timestamp_samples,
            "rejected_chunks": self.rejected_chunks,
            "publish_errors": self.publish_errors,
            "gaps": len(self.gaps),
            "missing_samples": sum(g.count for g in self.gaps),
            "unread_at_stop": self.unread_at_stop,
            "unpublished_at_stop": self.unpublished_at_stop,
            "clock_jumps": len(self.clock_jumps),
            "reconnects": self.reconnects,
            "last_timestamp": self.last_timestamp,
            "measured_rate": self.measured_rate,
        }


class PhysioReceiver:
    """Moves samples from ``source`` to ``sink`` through a ring buffer; loses nothing silently."""

    def __init__(
        self,
        config: ReceiverConfig,
        source: Streamer,
        sink: Streamer,
        log: logging.Logger | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        log_writer_factory: Callable[[StreamSpec], CsvWriter] | None = None,
    ) -> None:
        if config.min_consumers > 1 and not sink.counts_consumers:
            raise ConfigError(
                f"min_consumers {config.min_consumers}: output {sink.uri} cannot count its listeners "
                "(LSL only tells whether one listens); use 1, or a ros: output"
            )
        self.config = config
        self.source = source
        self.sink = sink
        self.log = log or logging.getLogger("physio_receiver")
        self._monotonic = monotonic
        self._log_writer_factory = log_writer_factory
        self.stats = ReceiverStats()
        self.buffer: RingBuffer | None = None
        self.input_spec: StreamSpec | None = None
        self._writer: CsvWriter | None = None
        self._stop = threading.Event()
        self._resume = threading.Event()
        self._resume.set()
        self._threads: list[threading.Thread] = []
        self._fatal: BaseException | None = None
        self._finished = threading.Event()
        #: Called (from the thread that ended it) once the receiver has finished by itself: a finite
        #: input forwarded, or a fatal error. Lets its owner wait for that rather than poll.
        self.on_finished: Callable[[], None] | None = None
        self._abandon = threading.Event()  # a stop whose drain ran out: the consumer leaves at once
        self._lock = threading.Lock()
        # Rejected chunks, overflows and NaN/inf can repeat many times a second: one line per kind
        # every 5 s, each counted.
        self._rejections = RateLimitedLog(lambda text: self.log.error(text), monotonic=monotonic)
        self._warnings = RateLimitedLog(lambda text: self.log.warning(text), monotonic=monotonic)
        self._rate_warnings = RateLimitedLog(lambda text: self.log.warning(text), period=RATE_WARNING_PERIOD,
                                             monotonic=monotonic)
        self._timeline = TimelineCheck(config.sampling_rate)
        self._rate_meter = RateMeter()
        self._next_rate_check = -math.inf
        self._source_spec: StreamSpec | None = None  # what the input declared when it first opened
        #: The input's clock offsets (LSL time correction) as each status measured them.
        self._offsets = ClockOffsetTrack(applied=source.corrects_clock)

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> StreamSpec:
        """Connect input and output. Raises StreamNotFoundError / StreamMismatchError.

        Raises OpenCancelled when :meth:`request_stop` comes while waiting for the input.
        """
        cfg = self.config
        # A file is there or not (never waited for); a stream may still appear.
        waits = "" if self.source.scheme == "csv" else f" (waiting up to {cfg.resolve_timeout:g} s for it)"
        self.log.info(f"opening {self.source.uri}{waits}")
        spec = self.source.open_input(cfg.expected_spec(), timeout=cfg.resolve_timeout, stop=self._stop)
        try:
            self._check_declared(spec)
        except StreamerError:
            self.source.close()
            raise
        # The configuration is the contract; the stream's own labels win when it has them.
        channels = spec.channels if len(spec.channels) == cfg.num_channels else cfg.expected_spec().channels
        out_spec = StreamSpec(
            name=spec.name,
            type=cfg.stream_type or spec.type,
            channel_count=cfg.num_channels,
            nominal_rate=cfg.sampling_rate,
            dtype=cfg.dtype,
            source_id=spec.source_id or "hri_physio_receiver",
            channels=tuple(cfg.channel_names) or channels,
        )
        self.input_spec = out_spec
        try:
            self.sink.open_output(out_spec)
            if cfg.log_data:
                self._writer = (
                    self._log_writer_factory(out_spec)
                    if self._log_writer_factory
                    else CsvWriter(cfg.log_name or default_log_name(out_spec), out_spec.channels, cfg.dtype)
                )
                self.log.info(f"logging every received sample to {self._writer.path}")
        except BaseException:
            # Nothing was received yet: leave nothing behind (an empty output file would make the
            # corrected rerun refuse to overwrite it).
            self.source.close()
            self.sink.abandon()
            raise
        self.buffer = RingBuffer(
            cfg.buffer_length,
            cfg.num_channels,
            dtype=numpy_dtype(cfg.dtype),
            overflow=cfg.overflow_policy,
            channels=out_spec.channels,
            on_overflow=self._on_overflow,
        )
        self.stats.connected = True
        self.log.info(
            f"connected {self.source.uri} -> {self.sink.uri}: {cfg.num_channels} ch {cfg.dtype} "
            f"@ {cfg.sampling_rate:g} Hz, frames of {cfg.output_frame} (overlap {cfg.sample_overlap})"
        )
        return out_spec

    def _check_declared(self, spec: StreamSpec) -> None:
        """The input's declared rate must be sampling_rate (a stream that declares none is taken
        with a warning); after a reconnect, the stream must be the one it was."""
        cfg, uri = self.config, self.source.uri
        first = self._source_spec
        if first is not None:
            changed = [f"{what} {new} (was {old})" for what, old, new in (
                ("nominal rate", f"{first.nominal_rate:g} Hz", f"{spec.nominal_rate:g} Hz"),
                ("channel count", first.channel_count, spec.channel_count),
                ("format", first.dtype, spec.dtype),
            ) if old != new]
            if changed:
                raise StreamMismatchError(f"{uri} came back as another stream: {', '.join(changed)}; "
                                          "not mixing two streams in one output")
            return
        declared = spec.nominal_rate
        if declared > 0 and not math.isclose(declared, cfg.sampling_rate, rel_tol=1e-9, abs_tol=1e-9):
            raise StreamMismatchError(
                f"{uri} declares a nominal rate of {declared:g} Hz but sampling_rate is "
                f"{cfg.sampling_rate:g} Hz; set sampling_rate to {declared:g}"
            )
        if declared == 0 and cfg.sampling_rate > 0:
            self.log.warning(
                f"{uri} declares no nominal rate (irregular); gaps are judged by sampling_rate "
                f"{cfg.sampling_rate:g} Hz and the rate measured from its timestamps is checked against it"
            )
        self._source_spec = spec

    def start(self) -> None:
        if self.buffer is None:
            self.open()
        self._wait_for_consumers()
        if self._stop.is_set():
            return  # stopped while waiting: stop() closes both ends
        self._threads = [
            threading.Thread(target=self._guard(self._produce), name="receiver-producer", daemon=True),
            threading.Thread(target=self._guard(self._consume), name="receiver-consumer", daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _wait_for_consumers(self) -> None:
        """Optionally hold the input until the output has ``min_consumers`` listeners (log
        replays; a processor and a recorder that must both see the first sample). The input is
        open meanwhile, so a live source's samples wait in its queue."""
        cfg = self.config
        wait_for_consumers(self.sink.consumer_count, cfg.min_consumers, cfg.wait_for_consumers,
                           what=self.sink.uri, log=self.log, clock=self._monotonic, stop=self._stop)

    def _guard(self, fn: Callable[[], None]) -> Callable[[], None]:
        def run() -> None:
            try:
                fn()
            except BaseException as exc:  # surfaced to the caller through wait()/fatal
                self._fatal = exc
                self.log.error(f"{threading.current_thread().name} stopped: {exc}")
                self._stop.set()
                if self.buffer is not None:
                    self.buffer.close()
                self._finish()

        return run

    def _finish(self) -> None:
        if self.on_finished is not None:
            self.on_finished()  # first: whoever sees it finished has been told too
        self._finished.set()

    @property
    def fatal(self) -> BaseException | None:
        return self._fatal

    @property
    def finished(self) -> bool:
        """True once a finite input (a CSV log) has been fully forwarded, or on a fatal error."""
        return self._finished.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._finished.wait(timeout)

    def request_stop(self) -> None:
        """Ask every wait (input, consumers, threads) to end soon; safe from a signal handler.

        :meth:`stop` still does the flushing and closing.
        """
        self._stop.set()

    def status(self) -> dict[str, Any]:
        """The counters, plus the input messages the transport rejected (malformed, wrong shape) and,
        for an input that measures one (LSL), its clock offset (``clock_correction``, None otherwise)."""
        with self._lock:
            status = self.stats.as_dict()
        status["rejected_messages"] = self.source.bad_messages
        self._offsets.add(self.source.clock_offset())
        measured = self._offsets.count > 0 or self._offsets.applied
        status["clock_correction"] = self._offsets.as_dict() if measured else None
        return status

    def pause(self) -> None:
        """Hold publishing; input is still logged and buffered."""
        self._resume.clear()
        self.stats.paused = True
        self.log.info("paused: input is still logged and buffered")

    def resume(self) -> None:
        self._resume.set()
        self.stats.paused = False
        self.log.info("resumed")

    def stop(self, timeout: float = 5.0) -> None:
        """Stop both threads, publish what is buffered, flush the log, close both ends."""
        self._stop.set()
        self._resume.set()
        for t in self._threads:
            if t.name == "receiver-producer":
                t.join(timeout + self._drain_budget())
        if self.buffer is not None:
            self.buffer.close()
        self._join_consumer(timeout)
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self.source.close()
        self.sink.close()
        self.stats.connected = False
        self.log.info(f"stopped: {self.status()}")

    def _join_consumer(self, timeout: float) -> None:
        """Let the consumer publish what the buffer holds, then publish its rest, from one thread only
        (publishing the rest beside a consumer still at work would reorder samples).

        The wait scales with the frames buffered (``drain_timeout`` + ``drain_per_chunk`` each). A
        consumer still at work after that (a big backlog on a busy machine) is told to leave after its
        current frame, and the rest goes out as one frame. Only a consumer stuck in the output leaves
        samples unpublished: counted (``unpublished_at_stop``) and said as an error."""
        consumer = next((t for t in self._threads if t.name == "receiver-consumer"), None)
        if consumer is not None and consumer.is_alive():
            frames = self.buffer.unread // max(1, self.config.output_frame) if self.buffer is not None else 0
            consumer.join(timeout + self.config.drain_timeout + self.config.drain_per_chunk * frames)
            if consumer.is_alive():
                self._abandon.set()
                consumer.join(timeout)
        if consumer is not None and consumer.is_alive():
            self.stats.unpublished_at_stop = self.buffer.unread if self.buffer is not None else 0
            self.log.error(f"stopping: the output is stuck: {self.stats.unpublished_at_stop} buffered "
                           f"sample(s) not published")
            return
        self._publish_rest()

    # -- producer ------------------------------------------------------------
    def _produce(self) -> None:
        while not self._stop.is_set():
            try:
                chunk = self.source.receive(timeout=0.1)
            except StreamLostError as exc:
                self._handle_lost(exc)
                continue
            if chunk is None:
                if getattr(self.source, "exhausted", False):
                    self.log.info(f"{self.source.uri}: end of input")
                    self.buffer.close()
                    return
                continue
            self._accept(chunk)
        self._take_what_arrived()

    def _drain_budget(self) -> float:
        """The time a stop allows for taking what the input holds: it scales with what is queued."""
        return self.config.drain_timeout + self.config.drain_per_chunk * self.source.backlog()

    def _take_what_arrived(self) -> None:
        """On a stop: what the input already holds is forwarded too, until it is empty (within
        :meth:`_drain_budget`; what an input still delivering after that is left unread, said as an
        error)."""
        budget = self._drain_budget()
        deadline = self._monotonic() + budget
        taken = 0
        while True:
            try:
                chunk = self.source.receive(timeout=0.0)
            except StreamerError:
                break  # lost or broken at the very end: what was taken stays
            if chunk is None:
                break
            self._accept(chunk)
            taken += chunk.num_samples
            if self._monotonic() >= deadline:
                left = self.source.backlog()
                self.log.error(f"stopping: {self.source.uri} still delivered after {budget:g} s of "
                               f"taking what had arrived ({taken} sample(s) taken, about {left} chunk(s) "
                               f"left unread; drain_timeout {self.config.drain_timeout:g} s)")
                self.stats.unread_at_stop = left
                break
        if taken:
            self.log.info(f"stopping: took the {taken} sample(s) that had already arrived")

    def _accept(self, chunk: Frame) -> None:
        cfg = self.config
        if chunk.num_channels != cfg.num_channels:
            self.stats.rejected_chunks += 1
            self._rejections.report(
                "channels",
                f"{self.source.uri}: chunk with {chunk.num_channels} channel(s) rejected, "
                f"num_channels is {cfg.num_channels}",
                "chunk(s) rejected",
            )
            return
        # Log first: the CSV is the record of what arrived, whatever happens next.
        if self._writer is not None:
            self._writer.write(chunk)
            self.stats.logged_samples += chunk.num_samples
        finite = np.isfinite(chunk.timestamps)
        if not finite.all():
            chunk = self._drop_bad_timestamps(chunk, finite)
            if chunk.num_samples == 0:
                return
        self._check_values(chunk)
        self._check_continuity(chunk)
        self._check_rate()
        with self._lock:
            self.stats.received_samples += chunk.num_samples
            self.stats.received_chunks += 1
            self.stats.last_timestamp = float(chunk.timestamps[-1])
        try:
            self.buffer.enqueue(chunk.timestamps, chunk.values)
        except BufferClosed:
            if not self._stop.is_set():
                raise

    def _drop_bad_timestamps(self, chunk: Frame, finite: np.ndarray) -> Frame:
        """A sample whose timestamp is NaN or infinite has no place in time: it is dropped, counted
        and said (rate-limited), and the chunk's other samples go on."""
        bad = int((~finite).sum())
        self.stats.bad_timestamp_samples += bad
        good = chunk.timestamps[finite]
        near = f" (in a chunk from t={good[0]:.4f})" if good.size else ""
        self._rejections.report(
            "timestamps",
            f"{self.source.uri}: {bad} sample(s) with a NaN or infinite timestamp dropped{near}",
            "sample(s) dropped for a NaN or infinite timestamp",
            count=bad,
        )
        return Frame(good, chunk.values[finite], chunk.channels)

    def _check_values(self, chunk: Frame) -> None:
        if chunk.is_string or chunk.values.dtype.kind != "f":
            return
        bad = ~np.isfinite(chunk.values)
        if bad.any():
            count = int(bad.any(axis=1).sum())
            self.stats.nonfinite_samples += count
            self._warnings.report(
                "nonfinite",
                f"{self.source.uri}: {count} sample(s) with NaN/inf near t={chunk.timestamps[0]:.3f} "
                "(forwarded unchanged)",
                "sample(s) with NaN/inf",
                count=count,
            )

    def _check_continuity(self, chunk: Frame) -> None:
        """Gaps (missing samples) and clock jumps (the sender's clock moved): counted apart,
        each logged at most every 5 s with how many there were since."""
        gaps, jumps = self._timeline.check(chunk.timestamps)
        uri = self.source.uri
        for gap in gaps:
            self.stats.gaps.append(gap)
            self._warnings.report(
                "gap",
                f"{uri}: gap of {gap.count} sample(s) from t={gap.first_t:.4f} to t={gap.last_t:.4f} "
                f"({gap.t_after - gap.t_before:.3f} s without data)",
                "gap(s)",
            )
        for jump in jumps:
            self.stats.clock_jumps.append(jump)
            self._warnings.report("clock_jump", f"{uri}: clock jump: {jump.describe()} (not counted as "
                                  "missing samples)", "clock jump(s)")
        if jumps:
            self._rate_meter.reset()  # intervals across a jump say nothing about the rate
            self._rate_meter.add(chunk.timestamps[-1:])
        else:
            self._rate_meter.add(chunk.timestamps)

    def _check_rate(self) -> None:
        """Once a second: the rate measured from the timestamps, warned about when it is more than
        5 % off sampling_rate."""
        now = self._monotonic()
        if now < self._next_rate_check:
            return
        self._next_rate_check = now + 1.0
        measured = self._rate_meter.rate
        with self._lock:
            self.stats.measured_rate = measured
        expected = self.config.sampling_rate
        if measured is None or expected <= 0:
            return
        off = measured / expected - 1.0
        if abs(off) > RATE_TOLERANCE:
            self._rate_warnings.report(
                "measured_rate",
                f"{self.source.uri}: measured rate {measured:.4g} Hz is {off:+.0%} off sampling_rate "
                f"{expected:g} Hz (median interval over the last {self._rate_meter.span:.0f} s of "
                "timestamps); check the device and its declared rate",
                "check(s) off",
            )

    def _handle_lost(self, exc: StreamerError) -> None:
        self.stats.connected = False
        if not self.config.reconnect:
            self.log.warning(f"{exc}: input lost; reconnect is off: publishing what is buffered and exiting")
            raise exc
        self.log.warning(f"{exc}; waiting for it to come back (data received so far is kept)")
        opener = StreamOpener(self.source, self.config.expected_spec(), timeout=1.0, retry=True,
                              log=self.log, stop=self._stop, clock=self._monotonic,
                              backoff=Backoff(initial=0.2, maximum=2.0))
        try:
            spec = opener.open()
        except OpenCancelled:
            return
        self._check_declared(spec)  # another rate or shape after the reconnect: fatal
        self._rate_meter.reset()
        self.stats.connected = True
        self.stats.reconnects += 1
        self.log.info(f"{self.source.uri}: reconnected")

    def _on_overflow(self, gap: Gap) -> None:
        """Log overflows, at most one line per policy every 5 s (every gap is kept in the stats)."""
        if gap.count:
            self._warnings.report(
                "dropped",
                f"buffer overflow: dropped {gap.count} oldest sample(s) "
                f"t={gap.first_t:.4f}..{gap.last_t:.4f}",
                "sample(s) dropped",
                count=gap.count,
            )
        else:
            self._warnings.report(
                "blocked", "buffer full: producer waits for the consumer (raise buffer_length?)", "wait(s)"
            )

    # -- consumer ------------------------------------------------------------
    def _consume(self) -> None:
        cfg = self.config
        while True:
            self._resume.wait()
            if self._abandon.is_set():
                return  # a stop ran out of time for frame after frame: it publishes the rest at once
            # No timeout: a frame, or the buffer's close (a stop, the input's end, a fatal error), wakes it.
            frame = self.buffer.dequeue_frame(cfg.output_frame, cfg.sample_overlap)
            if frame is None:
                if self.buffer.closed:
                    if not self._stop.is_set():
                        # Finite input done: forward the tail, then report completion.
                        self._publish_rest()
                        self._finish()
                    return
                continue
            self._resume.wait()  # a pause that came while waiting for this frame holds it
            self._publish(frame)

    def _publish(self, frame: Frame) -> None:
        for gap in getattr(frame, "gaps", ()):
            self.stats.gaps.append(gap)
        try:
            self.sink.publish(frame)
        except StreamerError as exc:
            self.stats.publish_errors += 1
            self.log.error(f"{self.sink.uri}: could not publish frame at t={frame.timestamps[0]:.4f}: {exc}")
            return
        with self._lock:
            self.stats.published_samples += getattr(frame, "fresh", frame.num_samples)
            self.stats.published_frames += 1

    def _publish_rest(self) -> None:
        if self.buffer is None:
            return
        rest = self.buffer.drain()
        if rest is not None and rest.num_samples:
            self.log.info(f"publishing the last {rest.num_samples} buffered sample(s) as a short frame")
            self._publish(rest)


def default_log_name(spec: StreamSpec) -> str:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in spec.name).strip("_") or "stream"
    return f"logs/{safe}_{time.strftime('%Y%m%d-%H%M%S')}.csv"

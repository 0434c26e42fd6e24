"""From notifications to timed samples: decode, check the rate, place on the device clock, map, push.

:class:`DataPath` is the session's receiving half. For each PMD data notification it decodes the
frame with the stream's settings, holds the first frames of a connection until the stream's
effective rate is known (:mod:`~hri_physio_bridge.polar.rate_check`; a rate the device announced
wrongly is corrected, with a ``rate_corrected`` marker), times every sample on the device clock
(:class:`~hri_physio_bridge.polar.timing.FrameTimer`), maps it onto the host clock
(:class:`~hri_physio_bridge.polar.clock_sync.DeviceClockMapper`) and pushes it in order. Heart
Rate Measurement notifications give the HR and RR streams (RR chained by
:class:`~hri_physio_bridge.polar.timing.BeatTimer`). Gaps, dropped frames, clock jumps and the
first drift estimate become markers. Nothing received is dropped without being counted, and
frames held for a rate check are pushed when the connection ends (:meth:`DataPath.flush`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.clock_sync import DeviceClockMapper
from hri_physio_bridge.polar.devices import KNOWN_RATES, StreamKind
from hri_physio_bridge.polar.output import OutputStream, Sink
from hri_physio_bridge.polar.protocol import (
    Measurement,
    PmdFrame,
    PolarProtocolError,
    decode_heart_rate,
    decode_pmd_frame,
)
from hri_physio_bridge.polar.rate_check import RateCheck, RateVerdict
from hri_physio_bridge.polar.timing import NS, BeatTimer, FrameTimer, TimingCounts
from hri_physio_bridge.rate_limit import RateLimitedLog

#: After a stream's LSL outlet was declared anew (a corrected rate), how long (host s) its samples
#: wait for the consumers of the old outlet to find the new one.
REOPEN_WAIT_S = 10.0

Emit = Callable[..., None]


@dataclass
class StreamStats:
    """One stream's counts for the whole session (every connection), as in ``status()["streams"]``."""

    rate_hz: float = 0.0  # the rate the stream is timed at (and declared on LSL)
    announced_rate_hz: float = 0.0  # what the device said (after known quirks)
    samples: int = 0  # pushed to the sink
    frames: int = 0  # notifications decoded (HR: with a value for this stream)
    decode_errors: int = 0
    out_of_order_samples: int = 0  # not after the previous sample: dropped
    stalls: int = 0  # watchdog alarms: no data since a start, or a silence while streaming
    rate_corrections: int = 0  # connections on which the announced rate was wrong
    timing: TimingCounts = field(default_factory=TimingCounts)  # written by the stream's timer

    def as_dict(self) -> dict[str, Any]:
        counts = {k: v for k, v in asdict(self).items() if k != "timing"}
        return {**counts, **asdict(self.timing), "dropped_frames": self.timing.dropped_frames}


@dataclass
class ActiveStream:
    """A started output stream of the current connection."""

    kind: StreamKind
    rate: float = 0.0
    selected: dict[cp.SettingType, int] = field(default_factory=dict)
    factor: float = 1.0
    timer: FrameTimer | None = None
    beats: BeatTimer | None = None
    #: Checking the effective rate: frames wait in ``held`` until the verdict.
    check: RateCheck | None = None
    #: Frames (and their arrival, host ns) not yet timed: during a rate check, or while the
    #: consumers of a re-declared outlet reconnect (until ``hold_until``, host s).
    held: list[tuple[PmdFrame, int]] = field(default_factory=list)
    hold_until: float | None = None

    @property
    def channels(self) -> int | None:
        return self.selected.get(cp.SettingType.CHANNELS)

    @property
    def resolution(self) -> int | None:
        return self.selected.get(cp.SettingType.RESOLUTION)


class DataPath:
    """Notifications in, samples and markers out (see the module docstring)."""

    def __init__(
        self,
        sink: Sink,
        *,
        clock: Callable[[], float],
        emit: Emit,
        log: logging.Logger,
        warnings: RateLimitedLog,
        latency_ns: int = 0,
        on_data: Callable[[str], None] = lambda _source: None,
    ) -> None:
        self.sink, self.clock, self.log, self.latency_ns = sink, clock, log, latency_ns
        # The session's ears: markers and status, rate-limited warnings, "data seen" for the watchdog.
        self._emit, self._warnings, self._on_data_seen = emit, warnings, on_data
        self.stats: dict[str, StreamStats] = {}
        self.active: dict[int, ActiveStream] = {}  # PMD streams by measurement
        self.hr_streams: dict[str, ActiveStream] = {}  # hr / rr
        self.opened: dict[str, OutputStream] = {}
        self.unexpected = 0  # data of a measurement that was not started
        #: Rates found wrong on an earlier connection: stream key -> (announced, effective).
        self.corrected_rates: dict[str, tuple[float, float]] = {}
        self._last_stamp: dict[str, int] = {}
        self.mapper = DeviceClockMapper(latency_ns=latency_ns)
        self._drift_reported = False
        self.reopen_wait_s = REOPEN_WAIT_S

    # ------------------------------------------------------------------------------------------
    def stream_stats(self, kind: StreamKind, rate: float) -> StreamStats:
        """The session's counts for ``kind`` (created at its first connection, kept across reconnects)."""
        return self.stats.setdefault(kind.key, StreamStats(rate_hz=rate, announced_rate_hz=rate))

    def reset_timing(self) -> None:
        """A new connection or a clock jump: a new device clock estimate."""
        self.mapper = DeviceClockMapper(latency_ns=self.latency_ns)
        self._drift_reported = False

    def end_connection(self) -> None:
        """The connection ended: push what is held, forget the started streams."""
        self.flush()
        self.active.clear()
        self.hr_streams.clear()

    def begin_timing(self, stream: ActiveStream, announced: float) -> None:
        """Time a PMD stream from its announced rate, checked on its first frames."""
        kind = stream.kind
        earlier = self.corrected_rates.get(kind.key)
        stream.rate = earlier[1] if earlier is not None and earlier[0] == announced else announced
        stats = self.stream_stats(kind, stream.rate)
        stats.announced_rate_hz = announced
        stream.timer = FrameTimer(stream.rate, counts=stats.timing)
        stream.check = RateCheck(stream.rate, known_rates=KNOWN_RATES.get(kind.key, ()))

    # ------------------------------------------------------------------------------------------
    # PMD data
    def on_pmd(self, raw: bytes, arrival: int) -> None:
        stream = self.active.get(raw[0] & cp.MEASUREMENT_MASK) if raw else None
        if stream is None:
            self.unexpected += 1
            return
        stats = self.stats[stream.kind.key]
        try:
            frame = decode_pmd_frame(raw, stream.channels, stream.resolution)
        except PolarProtocolError as exc:
            stats.decode_errors += 1
            self._warnings.report(
                f"decode-{stream.kind.key}",
                f"{stream.kind.label}: undecodable frame ({exc})",
                "frame(s) dropped",
            )
            return
        stats.frames += 1
        self._on_data_seen(stream.kind.key)
        if stream.beats is not None:
            self._push_ppi(stream, frame, arrival)
            return
        if stream.check is not None or stream.held:
            stream.held.append((frame, arrival))
            if stream.check is not None:
                verdict = stream.check.add(frame.timestamp_ns, frame.sample_count)
                if verdict is not None:
                    self._conclude(stream, verdict)
            self._release_held(stream)
            return
        self._place(stream, frame, arrival)

    def flush(self) -> None:
        """Time and push every held frame (the connection ends: nothing received is lost)."""
        for stream in self.active.values():
            if stream.check is not None:
                self._conclude(stream, stream.check.verdict())
            stream.hold_until = None
            self._release_held(stream)

    def _conclude(self, stream: ActiveStream, verdict: RateVerdict) -> None:
        stream.check = None
        if not verdict.corrected:
            return
        kind = stream.kind
        stats = self.stats[kind.key]
        stats.rate_corrections += 1
        stats.rate_hz = verdict.rate
        announced = stats.announced_rate_hz
        self.corrected_rates[kind.key] = (announced, verdict.rate)
        stream.rate = verdict.rate
        stream.timer = FrameTimer(verdict.rate, counts=stats.timing)
        self._emit(
            "rate_corrected",
            marker=True,
            stream=kind.label,
            announced=announced,
            measured=round(verdict.measured, 3),
            rate=verdict.rate,
        )
        self.log.warning(
            f"{kind.label}: the device announced {announced:g} Hz but sends {verdict.measured:.2f} Hz "
            f"(measured on its clock over {verdict.pairs} frames): timed and declared at {verdict.rate:g} Hz "
            "(a firmware issue; updating the sensor's firmware may fix it)"
        )
        existing = self.opened.get(kind.key)
        if existing is not None and existing.nominal_rate != verdict.rate:
            had_consumers = self.sink.consumers(kind.key)
            self.declare(kind, verdict.rate, anew=True)
            if had_consumers:
                stream.hold_until = self.clock() + self.reopen_wait_s

    def _release_held(self, stream: ActiveStream) -> None:
        if stream.check is not None or not stream.held:
            return
        if stream.hold_until is not None:
            if not self.sink.consumers(stream.kind.key) and self.clock() < stream.hold_until:
                return
            stream.hold_until = None
        held, stream.held = stream.held, []
        for frame, arrival in held:
            self._place(stream, frame, arrival)

    def _place(self, stream: ActiveStream, frame: PmdFrame, arrival: int) -> None:
        assert stream.timer is not None
        placement = stream.timer.place(frame.timestamp_ns, frame.sample_count, arrival)
        if placement.dropped:
            self._emit(
                "frame_dropped",
                marker=True,
                stream=stream.kind.label,
                reason=placement.kind,
                device_ns=frame.timestamp_ns,
            )
            return
        if placement.kind == "clock_jump":
            self.reset_timing()
            for other in self.active.values():
                if other is not stream and other.timer is not None:
                    other.timer.reset()
            self._emit("clock_jump", marker=True, stream=stream.kind.label, device_ns=frame.timestamp_ns)
        self.mapper.observe(frame.timestamp_ns, arrival)
        if not self._drift_reported and self.mapper.drift_estimated:
            self._drift_reported = True
            estimate = self.mapper.estimate()
            self._emit(
                "clock_drift",
                marker=True,
                drift_ppm=round(self.mapper.drift_ppm, 3),
                offset_s=None if estimate is None else estimate.offset_ns / NS,
            )
        host = self.mapper.to_host_many(placement.device_ns)
        if placement.kind == "gap":
            start, end = (
                self.mapper.to_host(placement.gap_from_ns),
                self.mapper.to_host(placement.gap_to_ns),
            )
            self._emit(
                "gap",
                marker=True,
                at=start / NS,
                stream=stream.kind.label,
                missing=placement.missing,
                start=start / NS,
                end=end / NS,
            )
            self._warnings.report(
                f"gap-{stream.kind.key}",
                f"{stream.kind.label}: {placement.missing} sample(s) lost in transmission (gap marker sent)",
                "gap(s)",
            )
        self._push(stream.kind.key, host, self._scaled(frame, stream))

    @staticmethod
    def _scaled(frame: PmdFrame, stream: ActiveStream) -> list[list[float]]:
        """Sample values in the stream's unit: compressed frames times the device's conversion factor."""
        factor = stream.factor if frame.compressed else 1.0
        if frame.compressed and frame.measurement == Measurement.ACC and frame.frame_type == 0:
            factor *= 1000.0  # compressed ACC type 0 comes in G
        if factor == 1.0:
            return [[float(v) for v in row] for row in frame.samples]
        return [[v * factor for v in row] for row in frame.samples]

    def _push_ppi(self, stream: ActiveStream, frame: PmdFrame, arrival: int) -> None:
        assert stream.beats is not None
        # Every interval goes to the timer, which skips and counts those <= 0.
        stamps = stream.beats.place([row[1] * 1_000_000 for row in frame.samples], arrival - self.latency_ns)
        rows = [row for row in frame.samples if row[1] > 0]
        self._push(
            stream.kind.key, stamps, [[float(r[1]), float(r[2]), float(r[0]), float(r[3])] for r in rows]
        )

    # ------------------------------------------------------------------------------------------
    # Heart Rate Measurement
    def on_heart_rate(self, raw: bytes, arrival: int) -> None:
        try:
            hr = decode_heart_rate(raw)
        except PolarProtocolError as exc:
            for key in self.hr_streams:
                self.stats[key].decode_errors += 1
            self._warnings.report(
                "decode-hr", f"HR: undecodable notification ({exc})", "notification(s) dropped"
            )
            return
        self._on_data_seen("hr")
        at = arrival - self.latency_ns
        if "hr" in self.hr_streams:
            self.stats["hr"].frames += 1
            self._push("hr", [at], [[float(hr.bpm)]])
        rr_stream = self.hr_streams.get("rr")
        if rr_stream is not None and rr_stream.beats is not None and hr.rr_1024:
            self.stats["rr"].frames += 1
            stamps = rr_stream.beats.place([(rr * NS * 2 + 1024) // 2048 for rr in hr.rr_1024], at)
            valid = [rr for rr in hr.rr_1024 if rr > 0]  # the intervals the timer placed
            self._push("rr", stamps, [[rr * 1000.0 / 1024.0] for rr in valid])

    # ------------------------------------------------------------------------------------------
    # Output
    def declare(self, kind: StreamKind, rate: float, *, name: str = "", source_id: str = "",
                device: dict[str, str] | None = None, anew: bool = False) -> bool:
        """Declare ``kind``'s outlet (once; again with ``anew`` for a corrected rate); False when it
        exists already at another rate."""
        existing = self.opened.get(kind.key)
        if existing is not None and not anew:
            return existing.nominal_rate == rate
        if existing is not None:
            stream = OutputStream(**{**asdict(existing), "nominal_rate": rate})
            self.sink.reopen(stream)
        else:
            stream = OutputStream(
                key=kind.key,
                name=name,
                type=kind.label,
                channels=kind.channels,
                units=kind.units,
                nominal_rate=rate,
                source_id=source_id,
                device=dict(device or {}),
            )
            self.sink.open(stream)
        self.opened[kind.key] = stream
        self.stream_stats(kind, rate)
        self._emit("stream_opened", name=stream.name, rate=rate, channels=len(kind.channels))
        return True

    def _push(self, key: str, host_ns: list[int], rows: list[list[float]]) -> None:
        """Push samples in time order; a sample not after the previous one is dropped and counted."""
        last = self._last_stamp.get(key)
        stats = self.stats[key]
        keep_t, keep_rows = [], []
        for t, row in zip(host_ns, rows, strict=True):
            if last is not None and t <= last:
                stats.out_of_order_samples += 1
                continue
            keep_t.append(t)
            keep_rows.append(row)
            last = t
        if not keep_t:
            return
        self._last_stamp[key] = keep_t[-1]
        stats.samples += len(keep_t)
        self.sink.push(key, [t / NS for t in keep_t], keep_rows)

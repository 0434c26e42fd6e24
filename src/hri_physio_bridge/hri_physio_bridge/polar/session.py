"""One Polar sensor's life cycle: find, connect, start its streams, time every sample, reconnect.

:class:`PolarSession` runs on an asyncio loop and knows nothing of bleak, rclpy or pylsl: the
BLE stack comes in as a :class:`~hri_physio_bridge.polar.ble.Scanner` and a client factory, the
outputs as a :class:`~hri_physio_bridge.polar.output.Sink`, time as an injected clock (seconds on
the LSL clock) and sleep.

Life cycle, until stopped: scan for the device (id, address or name prefix), connect, read its
features, subscribe to the control point and the data (and the Heart Rate Measurement), ask each
requested measurement's settings, start it at the requested rate/range, then stream. When the
link drops, the outputs stay open (consumers keep their inlets), the session backs off with
jitter (1 -> 30 s), scans, reconnects, re-subscribes, restarts the streams and restarts all
timing. Before any deliberate disconnect every started measurement is stopped (an H10 left
streaming drains its battery). Problems a retry cannot fix end the run with a one-line message:
no Bluetooth, pairing required, a stream or setting the device does not offer.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import random
import time
from collections.abc import Awaitable, Callable
from dataclasses import asdict, dataclass, field
from typing import Any, TypeVar

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.ble import (
    Advertisement,
    BleClient,
    BleError,
    BleUnavailableError,
    ClientFactory,
    ConnectionLostError,
    DeviceNotFoundError,
    PairingRequiredError,
    Scanner,
    Sleep,
)
from hri_physio_bridge.polar.capture import CaptureWriter
from hri_physio_bridge.polar.clock_sync import DeviceClockMapper
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.devices import (
    FAMILIES,
    STREAM_KINDS,
    Family,
    StreamKind,
    actual_rate,
    device_id_of,
    family_of,
    matches,
    stream_name,
)
from hri_physio_bridge.polar.gatt import BATTERY_LEVEL, HEART_RATE_MEASUREMENT, PMD_CONTROL_POINT, PMD_DATA
from hri_physio_bridge.polar.gatt import decode_battery as _decode_battery
from hri_physio_bridge.polar.output import OutputStream, Sink
from hri_physio_bridge.polar.protocol import (
    Measurement,
    PmdFrame,
    PolarProtocolError,
    decode_heart_rate,
    decode_pmd_frame,
)
from hri_physio_bridge.polar.timing import NS, BeatTimer, FrameTimer, TimingCounts
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.waiting import Backoff

T = TypeVar("T")

#: Control point statuses that a retry will not fix (the request itself is wrong for this device).
_UNSUPPORTED_STATUSES = {
    cp.Status.INVALID_OP_CODE,
    cp.Status.INVALID_MEASUREMENT_TYPE,
    cp.Status.NOT_SUPPORTED,
    cp.Status.INVALID_LENGTH,
    cp.Status.INVALID_PARAMETER,
    cp.Status.INVALID_RESOLUTION,
    cp.Status.INVALID_SAMPLE_RATE,
    cp.Status.INVALID_RANGE,
    cp.Status.INVALID_MTU,
    cp.Status.INVALID_NUMBER_OF_CHANNELS,
}
#: PPI arrives in batches (the first after ~25 s): its chain may lag the arrival this much.
PPI_MAX_LAG_NS = 30 * NS


class UnsupportedError(RuntimeError):
    """The device does not offer a requested stream or setting (not retried)."""


class Stopped(Exception):
    """A stop was requested while waiting."""


#: Errors that end the run at once (exit status 2): retrying cannot fix them.
FATAL_ERRORS = (BleUnavailableError, PairingRequiredError, UnsupportedError)


@dataclass
class ActiveStream:
    """A started output stream of the current connection."""

    kind: StreamKind
    rate: float = 0.0
    selected: dict[cp.SettingType, int] = field(default_factory=dict)
    factor: float = 1.0
    timer: FrameTimer | None = None
    beats: BeatTimer | None = None

    @property
    def channels(self) -> int | None:
        return self.selected.get(cp.SettingType.CHANNELS)

    @property
    def resolution(self) -> int | None:
        return self.selected.get(cp.SettingType.RESOLUTION)


@dataclass
class StreamStats:
    """One stream's counts for the whole session (every connection), as in ``status()["streams"]``."""

    rate_hz: float = 0.0
    samples: int = 0  # pushed to the sink
    frames: int = 0  # notifications decoded (HR: with a value for this stream)
    decode_errors: int = 0
    out_of_order_samples: int = 0  # not after the previous sample: dropped
    timing: TimingCounts = field(default_factory=TimingCounts)  # written by the stream's timer

    def as_dict(self) -> dict[str, Any]:
        counts = {k: v for k, v in asdict(self).items() if k != "timing"}
        return {**counts, **asdict(self.timing), "dropped_frames": self.timing.dropped_frames}


class PolarSession:
    """Streams one Polar sensor into a :class:`Sink` until stopped (see the module docstring)."""

    def __init__(
        self,
        config: PolarConfig,
        scanner: Scanner,
        connect: ClientFactory,
        sink: Sink,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Sleep | None = None,
        log: logging.Logger | None = None,
        capture: CaptureWriter | None = None,
        rng: random.Random | None = None,
    ) -> None:
        self.config = config
        self.scanner = scanner
        self.connect = connect
        self.sink = sink
        self.clock = clock
        self._sleep: Sleep = sleep or asyncio.sleep
        self.log = log or logging.getLogger("polar_streamer")
        self.capture = capture
        self.backoff = Backoff(config.backoff_initial, config.backoff_max, jitter=0.3, rng=rng)
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self._warnings = RateLimitedLog(self.log.warning, period=10.0, monotonic=clock)
        self._latency_ns = round(config.ble_latency * NS)
        # device
        self.family: Family | None = None
        self.device_id: str | None = None
        self.advert: Advertisement | None = None
        self.battery: int | None = None
        # state
        self.state = "idle"
        self.error: str | None = None
        self.connections = 0
        self.reconnects = 0
        self.device_stops = 0
        self.unexpected_notifications = 0
        self.stats: dict[str, StreamStats] = {}
        self._active: dict[int, ActiveStream] = {}  # by PMD measurement
        self._hr_streams: dict[str, ActiveStream] = {}  # hr / rr
        self._opened: dict[str, OutputStream] = {}
        self._last_stamp: dict[str, int] = {}
        self._mapper = DeviceClockMapper(latency_ns=self._latency_ns)
        self._drift_reported = False
        self._pending: tuple[int, int, asyncio.Future[cp.ControlPointResponse], bytearray] | None = None
        self._client: BleClient | None = None
        self._disconnected: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: set[asyncio.Task[Any]] = set()

    # ------------------------------------------------------------------------------------------
    # Events and status
    def _emit(self, event: str, marker: bool = False, **fields: Any) -> None:
        item = {"event": event, "t": self.clock(), **fields}
        if marker and "markers" in self._opened:
            self.sink.marker("markers", float(fields.get("at", item["t"])), json.dumps(item, sort_keys=True))
        for listener in list(self.listeners):
            listener(item)

    def _set_state(self, state: str, **fields: Any) -> None:
        self.state = state
        self._emit("state", state=state, **fields)

    def status(self) -> dict[str, Any]:
        estimate = self._mapper.estimate()
        return {
            "state": self.state,
            "error": self.error,
            "device": {
                "query": self.config.device,
                "name": self.advert.name if self.advert else None,
                "address": self.advert.address if self.advert else None,
                "id": self.device_id,
                "family": self.family.name if self.family else None,
            },
            "battery": self.battery,
            "connections": self.connections,
            "reconnects": self.reconnects,
            "device_stops": self.device_stops,
            "unexpected_notifications": self.unexpected_notifications,
            "drift_ppm": round(self._mapper.drift_ppm, 3),
            "clock_offset_s": None if estimate is None else estimate.offset_ns / NS,
            "streams": {key: s.as_dict() for key, s in self.stats.items()},
        }

    # ------------------------------------------------------------------------------------------
    # Helpers
    def _now_ns(self) -> int:
        return round(self.clock() * NS)

    def _record(self, op: str, char: str, data: bytes, t: float | None = None) -> None:
        if self.capture is not None:
            self.capture.record(self.clock() if t is None else t, op, char, data)

    async def _race(self, awaitable: Awaitable[T], stop: asyncio.Event, timeout: float | None = None) -> T:
        """Await ``awaitable``; raise :class:`Stopped` (after cancelling it) as soon as ``stop`` is set."""
        task = asyncio.ensure_future(awaitable)
        stopper = asyncio.ensure_future(stop.wait())
        try:
            done, _ = await asyncio.wait(
                {task, stopper}, timeout=timeout, return_when=asyncio.FIRST_COMPLETED
            )
        finally:
            stopper.cancel()
        if task in done:
            return task.result()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
        if stop.is_set():
            raise Stopped()
        raise TimeoutError()

    # ------------------------------------------------------------------------------------------
    # Life cycle
    async def run(self, stop: asyncio.Event) -> int:
        """Stream until ``stop``; the exit status: 0 stopped, 1 gave up, 2 a problem retrying cannot fix."""
        self._loop = asyncio.get_running_loop()
        self.backoff.reset()
        waiting_since = self.clock()
        try:
            while not stop.is_set():
                try:
                    advert = await self._find(stop)
                    streamed = await self._connect_and_stream(advert, stop)
                    if streamed:
                        self.backoff.reset()
                        waiting_since = self.clock()
                except Stopped:
                    break
                except FATAL_ERRORS as exc:
                    return self._fail(str(exc), 2)
                except (BleError, PolarProtocolError, cp.ControlPointRefused, TimeoutError) as exc:
                    self.error = str(exc)
                    self._warnings.report("retry", str(exc), "failed attempt(s)")
                if stop.is_set():
                    break
                give_up = self.config.give_up_after
                if give_up and self.clock() - waiting_since >= give_up:
                    return self._fail(
                        f"no connection to {self.config.device or 'a Polar device'} for "
                        f"{give_up:g} s; last problem: {self.error}",
                        1,
                    )
                delay = self.backoff.next_delay()
                self._set_state("waiting", retry_in=round(delay, 3))
                self.log.info(f"reconnecting in {delay:.1f} s")
                try:
                    await self._race(self._sleep(delay), stop)
                except Stopped:
                    break
        finally:
            for task in list(self._tasks):
                task.cancel()
        self._set_state("stopped")
        return 0

    def _fail(self, message: str, status: int) -> int:
        """End the run; status 2 problems are printed by the caller as its one error line."""
        self.error = message
        if status != 2:
            self.log.error(message)
        self._set_state("failed", error=message, exit_status=status)
        return status

    async def _find(self, stop: asyncio.Event) -> Advertisement:
        """The device asked for; after a first connection, that same device (by address)."""
        query = self.config.device
        known = self.advert.address if self.advert is not None else None
        self._set_state("searching", query=known or query)

        def wanted(a: Advertisement) -> bool:
            return a.address == known if known else matches(query, a.name, a.address)

        advert = await self._race(self.scanner.find(wanted, self.config.scan_timeout), stop)
        if advert is None:
            raise DeviceNotFoundError(
                f"Polar device {query!r} not found in a {self.config.scan_timeout:g} s scan: is it worn "
                "(an H10 wakes up on a moist strap), charged, near, and not connected to another app "
                "or phone?"
            )
        return advert

    def _identify(self, advert: Advertisement) -> tuple[Family, str, list[str]]:
        family = family_of(advert.name)
        if family is None:
            known = ", ".join(p for f in FAMILIES for p in f.name_prefixes)
            raise UnsupportedError(
                f"{advert.name or advert.address} is not a supported Polar sensor ({known})"
            )
        device_id = device_id_of(advert.name) or advert.address.replace(":", "").replace("-", "")[-8:].upper()
        streams = self.config.streams or list(family.default_streams)
        missing = [s for s in streams if s not in family.streams]
        if missing:
            raise UnsupportedError(
                f"a Polar {family.name} has no {', '.join(missing)} stream; it offers "
                f"{', '.join(family.streams)}"
            )
        return family, device_id, streams

    async def _connect_and_stream(self, advert: Advertisement, stop: asyncio.Event) -> bool:
        family, device_id, streams = self._identify(advert)
        self.family, self.device_id, self.advert = family, device_id, advert
        loop = self._loop or asyncio.get_running_loop()
        disconnected = asyncio.Event()
        self._disconnected = disconnected

        def on_disconnect() -> None:
            loop.call_soon_threadsafe(disconnected.set)

        self._set_state("connecting", name=advert.name, address=advert.address)
        client = self.connect(advert, on_disconnect)
        self._client = client
        try:
            await self._race(client.connect(), stop, timeout=self.config.connect_timeout)
        except TimeoutError:
            raise ConnectionLostError(
                f"connecting to {advert.name} took longer than {self.config.connect_timeout:g} s"
            ) from None
        self._reset_timing()
        if self.capture is not None:
            self.capture.note(
                device={
                    "name": advert.name,
                    "address": advert.address,
                    "id": device_id,
                    "family": family.name,
                },
                t=self.clock(),
            )
        started: list[ActiveStream] = []
        try:
            self._set_state("starting")
            await self._start(client, streams, started, stop)
            self.connections += 1
            if self.connections > 1:
                self.reconnects += 1
            self.error = None
            self._set_state("streaming", streams=streams, connection=self.connections)
            self._emit("connected", marker=True, device=device_id, connection=self.connections)
            self.log.info(f"streaming {', '.join(streams)} from {advert.name} ({advert.address})")
            await self._race(disconnected.wait(), stop)
            self.error = f"lost the connection to {advert.name}"
            self._emit("disconnected", marker=True, device=device_id)
            self.log.warning(f"{self.error}; the LSL streams stay open while reconnecting")
            return True
        except Stopped:
            raise
        finally:
            await self._shutdown(client, started)
            self._active.clear()
            self._hr_streams.clear()
            self._pending = None
            self._client = None

    async def _shutdown(self, client: BleClient, started: list[ActiveStream]) -> None:
        """Stop every started measurement, then disconnect (never the other way round)."""
        if not client.is_connected:
            return
        for stream in reversed(started):
            if stream.kind.measurement is None:
                continue
            try:
                await self._request(client, cp.stop_request(stream.kind.measurement), allow_refusal=True)
            except (BleError, TimeoutError, PolarProtocolError) as exc:
                self.log.warning(f"could not stop {stream.kind.label} before disconnecting: {exc}")
        with contextlib.suppress(BleError, TimeoutError):
            await asyncio.wait_for(client.disconnect(), self.config.response_timeout)

    def _reset_timing(self) -> None:
        self._mapper = DeviceClockMapper(latency_ns=self._latency_ns)
        self._drift_reported = False

    # ------------------------------------------------------------------------------------------
    # Starting streams
    async def _start(
        self, client: BleClient, streams: list[str], started: list[ActiveStream], stop: asyncio.Event
    ) -> None:
        assert self.family is not None and self.device_id is not None
        pmd = [STREAM_KINDS[s] for s in streams if STREAM_KINDS[s].measurement is not None]
        heart = [STREAM_KINDS[s] for s in streams if STREAM_KINDS[s].measurement is None]
        with contextlib.suppress(BleError, PolarProtocolError):
            data = await self._race(client.read_gatt_char(BATTERY_LEVEL), stop)
            self._record("read", BATTERY_LEVEL, data)
            self.battery = _decode_battery(data)
            if self.battery < 15:
                self.log.warning(f"battery at {self.battery} %: replace or charge it before a session")
        if pmd:
            features_data = await self._race(client.read_gatt_char(PMD_CONTROL_POINT), stop)
            self._record("read", PMD_CONTROL_POINT, features_data)
            features = cp.decode_features(features_data)
            missing = [k.key for k in pmd if k.measurement not in features]
            if missing:
                offered = ", ".join(sorted(m.name.lower() for m in features)) or "nothing"
                raise UnsupportedError(
                    f"{self.advert.name if self.advert else 'the device'} does not offer "
                    f"{', '.join(missing)} (its PMD features: {offered})"
                )
            # Subscribe to the control point and the data before sending any start.
            await self._race(client.start_notify(PMD_CONTROL_POINT, self._on_control_point), stop)
            await self._race(client.start_notify(PMD_DATA, self._on_data), stop)
        if heart:
            await self._race(client.start_notify(HEART_RATE_MEASUREMENT, self._on_heart_rate), stop)
            for kind in heart:
                stream = ActiveStream(kind, rate=kind.nominal_rate or 0.0)
                if kind.key == "rr":
                    stream.beats = BeatTimer(counts=self._stream_stats(kind, stream.rate).timing)
                self._hr_streams[kind.key] = stream
                self._open_output(kind, stream.rate)
        for kind in pmd:
            stream = await self._start_measurement(client, kind, stop)
            started.append(stream)
        self._open_markers()

    async def _start_measurement(
        self, client: BleClient, kind: StreamKind, stop: asyncio.Event
    ) -> ActiveStream:
        assert kind.measurement is not None and self.family is not None
        m = int(kind.measurement)
        stream = ActiveStream(kind)
        if kind.measurement != Measurement.PPI:
            response = await self._race(self._request(client, cp.get_settings_request(m)), stop)
            stream.selected = self._choose_settings(kind, cp.decode_settings(response.params))
        response = await self._race(self._request(client, cp.start_request(m, stream.selected)), stop)
        try:
            factors = cp.decode_settings(response.params).get(cp.SettingType.FACTOR)
        except PolarProtocolError as exc:
            self.log.warning(f"{kind.label}: unreadable start response parameters ({exc}); factor 1")
            factors = None
        stream.factor = float(factors[0]) if factors else 1.0
        if kind.measurement == Measurement.PPI:
            stream.rate = 0.0
            counts = self._stream_stats(kind, stream.rate).timing
            stream.beats = BeatTimer(max_lag_ns=PPI_MAX_LAG_NS, counts=counts)
        else:
            reported = stream.selected.get(cp.SettingType.SAMPLE_RATE, 0)
            stream.rate = float(actual_rate(self.family, kind.key, reported))
            if stream.rate <= 0:
                raise UnsupportedError(f"{kind.label}: the device gave no sample rate")
            stream.timer = FrameTimer(stream.rate, counts=self._stream_stats(kind, stream.rate).timing)
        self._active[m] = stream
        self._open_output(kind, stream.rate)
        self.log.info(
            f"{kind.label} started: "
            + ", ".join(f"{k.name.lower()} {v}" for k, v in stream.selected.items())
            + f", factor {stream.factor:g}"
        )
        return stream

    def _choose_settings(
        self, kind: StreamKind, offered: dict[cp.SettingType, list[int | float]]
    ) -> dict[cp.SettingType, int]:
        """One value per offered setting: the requested rate/range (refused if not offered), else the
        highest."""
        cfg = self.config
        wanted: dict[cp.SettingType, tuple[str, int]] = {}
        if kind.key == "ecg":
            wanted[cp.SettingType.SAMPLE_RATE] = ("ecg_rate", cfg.ecg_rate)
        elif kind.key == "acc":
            wanted[cp.SettingType.SAMPLE_RATE] = ("acc_rate", cfg.acc_rate)
            wanted[cp.SettingType.RANGE] = ("acc_range", cfg.acc_range)
        elif kind.key == "ppg":
            wanted[cp.SettingType.SAMPLE_RATE] = ("ppg_rate", cfg.ppg_rate)
        selected: dict[cp.SettingType, int] = {}
        for setting, values in offered.items():
            if setting in (cp.SettingType.FACTOR, cp.SettingType.SECURITY) or not values:
                continue
            ints = sorted({int(v) for v in values})
            name, want = wanted.get(setting, ("", 0))
            if want and want not in ints:
                raise UnsupportedError(
                    f"{name} {want}: {self.advert.name if self.advert else 'the device'} offers "
                    f"{', '.join(str(v) for v in ints)} for {kind.label}"
                )
            selected[setting] = want or ints[-1]
        return selected

    def _open_output(self, kind: StreamKind, rate: float) -> None:
        assert self.family is not None and self.device_id is not None
        existing = self._opened.get(kind.key)
        if existing is not None:
            if existing.nominal_rate != rate:
                raise UnsupportedError(
                    f"{kind.label} restarted at {rate:g} Hz but its LSL stream declares "
                    f"{existing.nominal_rate:g} Hz"
                )
            return
        name = stream_name(self.family, self.device_id, kind.key, self.config.name_prefix)
        stream = OutputStream(
            key=kind.key,
            name=name,
            type=kind.label,
            channels=kind.channels,
            units=kind.units,
            nominal_rate=rate,
            source_id=f"{self.device_id}-{kind.label}",
            device=self._device_description(),
        )
        self.sink.open(stream)
        self._opened[kind.key] = stream
        self._stream_stats(kind, rate)
        self._emit("stream_opened", name=name, rate=rate, channels=len(kind.channels))

    def _stream_stats(self, kind: StreamKind, rate: float) -> StreamStats:
        """The session's counts for ``kind`` (created at its first connection, kept across reconnects)."""
        return self.stats.setdefault(kind.key, StreamStats(rate_hz=rate))

    def _open_markers(self) -> None:
        if "markers" in self._opened or self.family is None or self.device_id is None:
            return
        name = stream_name(self.family, self.device_id, "Markers", self.config.name_prefix)
        stream = OutputStream(
            key="markers",
            name=name,
            type="Markers",
            channels=("event",),
            units=("json",),
            nominal_rate=0.0,
            source_id=f"{self.device_id}-Markers",
            text=True,
            device=self._device_description(),
        )
        self.sink.open(stream)
        self._opened["markers"] = stream

    def _device_description(self) -> dict[str, str]:
        return {
            "manufacturer": "Polar",
            "model": self.family.name if self.family else "",
            "id": self.device_id or "",
            "name": (self.advert.name or "") if self.advert else "",
        }

    # ------------------------------------------------------------------------------------------
    # Control point
    async def _request(
        self, client: BleClient, payload: bytes, allow_refusal: bool = False
    ) -> cp.ControlPointResponse:
        op, m = payload[0], payload[1]
        loop = asyncio.get_running_loop()
        future: asyncio.Future[cp.ControlPointResponse] = loop.create_future()
        self._pending = (op, m, future, bytearray())
        try:
            self._record("write", PMD_CONTROL_POINT, payload)
            await client.write_gatt_char(PMD_CONTROL_POINT, payload, response=True)
            try:
                response = await asyncio.wait_for(future, self.config.response_timeout)
            except TimeoutError:
                raise ConnectionLostError(
                    f"the device did not answer '{payload.hex(' ')}' within "
                    f"{self.config.response_timeout:g} s"
                ) from None
        finally:
            self._pending = None
        accepted = response.ok or (
            op in (cp.OpCode.START, cp.OpCode.STOP) and response.status == cp.Status.ALREADY_IN_STATE
        )
        if not accepted:
            refused = cp.ControlPointRefused(op, m, response.status)
            if allow_refusal:
                self.log.warning(str(refused))
            elif response.status in _UNSUPPORTED_STATUSES:
                raise UnsupportedError(str(refused))
            else:
                raise refused
        return response

    def _on_control_point(self, _char: Any, data: bytearray) -> None:
        self._record("notify", PMD_CONTROL_POINT, bytes(data))
        try:
            message = cp.decode_control_point(bytes(data))
        except PolarProtocolError as exc:
            self._warnings.report("cp", f"unreadable control point indication: {exc}", "indication(s)")
            return
        if isinstance(message, cp.StopIndication):
            self._on_device_stop(message)
            return
        pending = self._pending
        if pending is None or pending[0] != message.op or pending[1] != message.measurement:
            self.unexpected_notifications += 1
            return
        op, m, future, params = pending
        params += message.params
        if message.more:
            return
        if not future.done():
            future.set_result(cp.ControlPointResponse(op, m, message.status, False, bytes(params)))

    def _on_device_stop(self, message: cp.StopIndication) -> None:
        client = self._client
        for m in message.measurements:
            stream = self._active.get(m)
            if stream is None:
                continue
            self.device_stops += 1
            self._emit("device_stopped", marker=True, stream=stream.kind.label)
            self.log.warning(f"the device stopped {stream.kind.label} by itself; restarting it")
            if client is not None:
                task = asyncio.ensure_future(self._restart(client, stream))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)

    async def _restart(self, client: BleClient, stream: ActiveStream) -> None:
        assert stream.kind.measurement is not None
        try:
            await self._request(client, cp.start_request(int(stream.kind.measurement), stream.selected))
        except (BleError, cp.ControlPointRefused, UnsupportedError, PolarProtocolError) as exc:
            self.log.error(f"could not restart {stream.kind.label}: {exc}")
            return
        if stream.timer is not None:
            stream.timer.reset()
        self._emit("stream_restarted", stream=stream.kind.label)

    # ------------------------------------------------------------------------------------------
    # Data
    def _on_data(self, _char: Any, data: bytearray) -> None:
        arrival = self._now_ns()
        raw = bytes(data)
        self._record("notify", PMD_DATA, raw, arrival / NS)
        stream = self._active.get(raw[0] & 0x3F) if raw else None
        if stream is None:
            self.unexpected_notifications += 1
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
        if stream.beats is not None:
            self._push_ppi(stream, frame, arrival)
            return
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
            self._reset_timing()
            for other in self._active.values():
                if other is not stream and other.timer is not None:
                    other.timer.reset()
            self._emit("clock_jump", marker=True, stream=stream.kind.label, device_ns=frame.timestamp_ns)
        self._mapper.observe(frame.timestamp_ns, arrival)
        if not self._drift_reported and self._mapper.drift_estimated:
            self._drift_reported = True
            estimate = self._mapper.estimate()
            self._emit(
                "clock_drift",
                marker=True,
                drift_ppm=round(self._mapper.drift_ppm, 3),
                offset_s=None if estimate is None else estimate.offset_ns / NS,
            )
        host = self._mapper.to_host_many(placement.device_ns)
        if placement.kind == "gap":
            start, end = (
                self._mapper.to_host(placement.gap_from_ns),
                self._mapper.to_host(placement.gap_to_ns),
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
        stamps = stream.beats.place([row[1] * 1_000_000 for row in frame.samples], arrival - self._latency_ns)
        rows = [row for row in frame.samples if row[1] > 0]
        self._push(
            stream.kind.key, stamps, [[float(r[1]), float(r[2]), float(r[0]), float(r[3])] for r in rows]
        )

    def _on_heart_rate(self, _char: Any, data: bytearray) -> None:
        arrival = self._now_ns()
        raw = bytes(data)
        self._record("notify", HEART_RATE_MEASUREMENT, raw, arrival / NS)
        try:
            hr = decode_heart_rate(raw)
        except PolarProtocolError as exc:
            for key in self._hr_streams:
                self.stats[key].decode_errors += 1
            self._warnings.report(
                "decode-hr", f"HR: undecodable notification ({exc})", "notification(s) dropped"
            )
            return
        at = arrival - self._latency_ns
        if "hr" in self._hr_streams:
            self.stats["hr"].frames += 1
            self._push("hr", [at], [[float(hr.bpm)]])
        rr_stream = self._hr_streams.get("rr")
        if rr_stream is not None and rr_stream.beats is not None and hr.rr_1024:
            self.stats["rr"].frames += 1
            stamps = rr_stream.beats.place([(rr * NS * 2 + 1024) // 2048 for rr in hr.rr_1024], at)
            valid = [rr for rr in hr.rr_1024 if rr > 0]  # the intervals the timer placed
            self._push("rr", stamps, [[rr * 1000.0 / 1024.0] for rr in valid])

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


async def scan_for_polar(scanner: Scanner, timeout: float) -> list[Advertisement]:
    """Polar sensors nearby, strongest signal first."""
    found = await scanner.scan(timeout)
    polar = [a for a in found if family_of(a.name) is not None or (a.name or "").startswith("Polar")]
    return sorted(polar, key=lambda a: -(a.rssi if a.rssi is not None else -999))


def describe_adverts(adverts: list[Advertisement]) -> list[str]:
    """Lines for ``--scan``: name, address, RSSI, the id to pass as --device, the family."""
    if not adverts:
        return ["no Polar device found (is it worn, charged, near, and not connected to another app?)"]
    lines = [f"{'name':<24} {'address':<20} {'RSSI':>5}  {'device id':<9}  streams"]
    for a in adverts:
        family = family_of(a.name)
        streams = ",".join(family.streams) if family else "-"
        rssi = "?" if a.rssi is None else str(a.rssi)
        lines.append(
            f"{(a.name or '?'):<24} {a.address:<20} {rssi:>5}  {device_id_of(a.name) or '-':<9}  {streams}"
        )
    return lines

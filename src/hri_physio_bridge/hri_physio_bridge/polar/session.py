"""One Polar sensor's life cycle: find, connect, start its streams, watch them, reconnect.

:class:`PolarSession` runs on an asyncio loop and knows nothing of bleak, rclpy or pylsl: the
BLE stack comes in as a :class:`~hri_physio_bridge.polar.ble.Scanner` and a client factory, the
outputs as a :class:`~hri_physio_bridge.polar.output.Sink`, time as an injected clock (seconds on
the LSL clock) and sleep.

Life cycle, until stopped: scan for the device (id, address or name prefix), connect, read the
link's MTU, read its features, subscribe to the control point and the data (and the Heart Rate
Measurement), switch SDK mode on if asked, ask each requested measurement's settings, start it at
the requested rate/range, then stream (:mod:`~hri_physio_bridge.polar.data_path`) while a
:class:`~hri_physio_bridge.polar.watchdog.StreamWatchdog` checks that every stream's data starts
and keeps coming: a silent stream gets a ``stall`` marker, a warning and a restart, and a
reconnection if it stays silent. When the link drops (or the watchdog asks), the outputs stay
open (consumers keep their inlets), the session backs off with jitter (1 -> 30 s), scans,
reconnects, re-subscribes, restarts the streams and restarts all timing. INVALID_MTU is retried
the same way. Before any deliberate disconnect every started measurement is stopped (an H10 left
streaming drains its battery) and SDK mode switched off. Problems a retry cannot fix end the run
with a one-line message: no Bluetooth, pairing required, a stream, a setting or SDK mode the
device does not offer.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import random
import time
from collections.abc import Awaitable, Callable
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
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.control_channel import ControlPointChannel, UnsupportedError
from hri_physio_bridge.polar.data_path import ActiveStream, DataPath, StreamStats
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
from hri_physio_bridge.polar.mtu import PREFERRED_MTU, short_mtu_warning
from hri_physio_bridge.polar.output import OutputStream, Sink
from hri_physio_bridge.polar.protocol import Measurement, PolarProtocolError
from hri_physio_bridge.polar.timing import NS, BeatTimer
from hri_physio_bridge.polar.watchdog import RESTART, START, Alarm, StreamWatchdog
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.waiting import Backoff

T = TypeVar("T")

__all__ = ["FATAL_ERRORS", "PolarSession", "Stopped", "StreamStats", "UnsupportedError", "describe_adverts",
           "scan_for_polar"]

#: PPI arrives in batches (the first after ~25 s): its chain may lag the arrival this much.
PPI_MAX_LAG_NS = 30 * NS
#: The watchdog looks at least this often (s), and logs a first data later than this after a start.
WATCHDOG_TICK = 1.0
LATE_FIRST_DATA_S = 5.0


class Stopped(Exception):
    """A stop was requested while waiting."""


#: Errors that end the run at once (exit status 2): retrying cannot fix them.
FATAL_ERRORS = (BleUnavailableError, PairingRequiredError, UnsupportedError)


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
        watchdog: bool = True,
        arrival_clock: Callable[[], float] | None = None,
    ) -> None:
        """``watchdog`` False: no stall detection (a replay plays its capture's silences as they were).
        ``arrival_clock``: when a notification arrived, if not ``clock`` (a replay: when the capture says
        it arrived, so its timing does not depend on the replay speed or on this machine's load)."""
        self.config = config
        self.scanner = scanner
        self.connect = connect
        self.sink = sink
        self.clock = clock
        self.arrival_clock = arrival_clock or clock
        self._sleep: Sleep = sleep or asyncio.sleep
        self.log = log or logging.getLogger("polar_streamer")
        self.capture = capture
        self.backoff = Backoff(config.backoff_initial, config.backoff_max, jitter=0.3, rng=rng)
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self._warnings = RateLimitedLog(self.log.warning, period=10.0, monotonic=clock)
        self._latency_ns = round(config.ble_latency * NS)
        self.data = DataPath(
            sink,
            clock=clock,
            emit=self._emit,
            log=self.log,
            warnings=self._warnings,
            latency_ns=self._latency_ns,
            on_data=self._data_seen,
        )
        self.channel = ControlPointChannel(
            config.response_timeout,
            record=lambda op, char, data: self._record(op, char, data),
            on_stop=self._on_device_stop,
            warn=lambda text: self._warnings.report("cp", text, "indication(s)"),
        )
        self.watchdog = StreamWatchdog() if watchdog else None
        # device
        self.family: Family | None = None
        self.device_id: str | None = None
        self.advert: Advertisement | None = None
        self.battery: int | None = None
        self.mtu: int | None = None
        self.sdk_mode = False
        # state
        self.state = "idle"
        self.error: str | None = None
        self.connections = 0
        self.reconnects = 0
        self.device_stops = 0
        self.stalls = 0
        self.stall_reconnects = 0
        self._client: BleClient | None = None
        self._reconnect: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: set[asyncio.Task[Any]] = set()

    @property
    def stats(self) -> dict[str, StreamStats]:
        return self.data.stats

    # ------------------------------------------------------------------------------------------
    # Events and status
    def _emit(self, event: str, marker: bool = False, **fields: Any) -> None:
        item = {"event": event, "t": self.clock(), **fields}
        if marker and "markers" in self.data.opened:
            self.sink.marker("markers", float(fields.get("at", item["t"])), json.dumps(item, sort_keys=True))
        for listener in list(self.listeners):
            listener(item)

    def _set_state(self, state: str, **fields: Any) -> None:
        self.state = state
        self._emit("state", state=state, **fields)

    def status(self) -> dict[str, Any]:
        estimate = self.data.mapper.estimate()
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
            "mtu": self.mtu,
            "sdk_mode": self.sdk_mode,
            "connections": self.connections,
            "reconnects": self.reconnects,
            "device_stops": self.device_stops,
            "stalls": self.stalls,
            "stall_reconnects": self.stall_reconnects,
            "mtu_refusals": self.channel.mtu_refusals,
            "unexpected_notifications": self.channel.unexpected + self.data.unexpected,
            "drift_ppm": round(self.data.mapper.drift_ppm, 3),
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

    def _spawn(self, awaitable: Awaitable[Any]) -> asyncio.Task[Any]:
        task = asyncio.ensure_future(awaitable)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

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
        streams = self._streams_for(family)
        missing = [s for s in streams if s not in family.streams]
        if missing:
            raise UnsupportedError(
                f"a Polar {family.name} has no {', '.join(missing)} stream; it offers "
                f"{', '.join(family.streams)}"
            )
        return family, device_id, streams

    def _streams_for(self, family: Family) -> list[str]:
        """The streams asked for; by default the family's, without what SDK mode switches off."""
        if self.config.streams:
            return list(self.config.streams)
        defaults = list(family.default_streams)
        if self.config.sdk_mode:
            defaults = [s for s in defaults if not STREAM_KINDS[s].computed]
        return defaults

    async def _connect_and_stream(self, advert: Advertisement, stop: asyncio.Event) -> bool:
        family, device_id, streams = self._identify(advert)
        self.family, self.device_id, self.advert = family, device_id, advert
        loop = self._loop or asyncio.get_running_loop()
        disconnected = asyncio.Event()
        self._reconnect = reconnect = asyncio.Event()

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
        self.data.reset_timing()
        self.channel.reset()
        started: list[ActiveStream] = []
        watching: asyncio.Task[None] | None = None
        try:
            await self._read_mtu(client, streams, stop)
            if self.capture is not None:
                self.capture.note(
                    device={
                        "name": advert.name,
                        "address": advert.address,
                        "id": device_id,
                        "family": family.name,
                    },
                    mtu=self.mtu,
                    t=self.clock(),
                )
            self._set_state("starting")
            await self._start(client, streams, started, stop)
            self.connections += 1
            if self.connections > 1:
                self.reconnects += 1
            self.error = None
            self._set_state("streaming", streams=streams, connection=self.connections)
            self._emit("connected", marker=True, device=device_id, connection=self.connections)
            self.log.info(f"streaming {', '.join(streams)} from {advert.name} ({advert.address})")
            if self.watchdog is not None:
                watching = self._spawn(self._watch(client))
            ended = await self._race(self._link_ends(disconnected, reconnect), stop)
            if ended == "disconnected":
                self.error = f"lost the connection to {advert.name}"
                self._emit("disconnected", marker=True, device=device_id)
                self.log.warning(f"{self.error}; the LSL streams stay open while reconnecting")
            return True
        except Stopped:
            raise
        finally:
            if watching is not None:
                watching.cancel()
            if self.watchdog is not None:
                self.watchdog.clear()
            await self._shutdown(client, started)
            self.data.end_connection()
            self.channel.reset()
            self._client = None

    @staticmethod
    async def _link_ends(disconnected: asyncio.Event, reconnect: asyncio.Event) -> str:
        """Wait until the link drops (``disconnected``) or the watchdog asks for a new one (``reconnect``)."""
        waits = {asyncio.ensure_future(disconnected.wait()): "disconnected",
                 asyncio.ensure_future(reconnect.wait()): "reconnect"}
        try:
            done, _ = await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in waits:
                task.cancel()
        return "disconnected" if any(waits[t] == "disconnected" for t in done) else "reconnect"

    async def _read_mtu(self, client: BleClient, streams: list[str], stop: asyncio.Event) -> None:
        """Ask for a large MTU and keep what the link has; warn when PMD frames cannot fit."""
        try:
            asked = client.request_mtu(PREFERRED_MTU)
            self.mtu = await self._race(asked, stop, timeout=self.config.response_timeout)
        except (BleError, TimeoutError) as exc:
            self.log.info(f"the link's MTU is unknown ({exc or 'no answer'})")
            self.mtu = None
        self.channel.mtu = self.mtu
        pmd = [STREAM_KINDS[s].label for s in streams if STREAM_KINDS[s].measurement is not None]
        warning = short_mtu_warning(self.mtu, pmd)
        if warning:
            self._warnings.report("mtu", warning, "connection(s)")

    async def _shutdown(self, client: BleClient, started: list[ActiveStream]) -> None:
        """Stop every started measurement and SDK mode, then disconnect (never the other way round)."""
        if not client.is_connected:
            self.sdk_mode = False
            return
        for stream in reversed(started):
            if stream.kind.measurement is None:
                continue
            try:
                await self._request(client, cp.stop_request(stream.kind.measurement), allow_refusal=True)
            except (BleError, TimeoutError, PolarProtocolError) as exc:
                self.log.warning(f"could not stop {stream.kind.label} before disconnecting: {exc}")
        if self.sdk_mode:
            try:
                await self._request(client, cp.sdk_mode_request(False), allow_refusal=True)
            except (BleError, TimeoutError, PolarProtocolError) as exc:
                self.log.warning(f"could not switch SDK mode off before disconnecting: {exc}")
            self.sdk_mode = False
        with contextlib.suppress(BleError, TimeoutError):
            await asyncio.wait_for(client.disconnect(), self.config.response_timeout)

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
        if pmd or self.config.sdk_mode:
            features_data = await self._race(client.read_gatt_char(PMD_CONTROL_POINT), stop)
            self._record("read", PMD_CONTROL_POINT, features_data)
            features = cp.decode_features(features_data)
            offered = ", ".join(sorted(m.name.lower() for m in features)) or "nothing"
            missing = [k.key for k in pmd if k.measurement not in features]
            if missing:
                raise UnsupportedError(
                    f"{self._device_name()} does not offer {', '.join(missing)} (its PMD features: {offered})"
                )
            if self.config.sdk_mode and not cp.has_sdk_mode(features_data):
                raise UnsupportedError(
                    f"sdk_mode: {self._device_name()} has no SDK mode (its PMD features: {offered}); "
                    "run without --sdk-mode"
                )
            # Subscribe to the control point and the data before sending any request.
            await self._race(client.start_notify(PMD_CONTROL_POINT, self._on_control_point), stop)
            await self._race(client.start_notify(PMD_DATA, self._on_data), stop)
            if self.config.sdk_mode:
                await self._race(self._request(client, cp.sdk_mode_request(True)), stop)
                self.sdk_mode = True
                self.log.info(f"SDK mode on: {self._device_name()} computes no HR, RR or PPI now")
        if heart:
            await self._race(client.start_notify(HEART_RATE_MEASUREMENT, self._on_heart_rate), stop)
            for kind in heart:
                stream = ActiveStream(kind, rate=kind.nominal_rate or 0.0)
                if kind.key == "rr":
                    stream.beats = BeatTimer(counts=self.data.stream_stats(kind, stream.rate).timing)
                self.data.hr_streams[kind.key] = stream
                self._open_output(kind, stream.rate)
            self._watch_source(heart[0])
        for kind in pmd:
            stream = await self._start_measurement(client, kind, stop)
            started.append(stream)
        self._open_markers()

    def _device_name(self) -> str:
        return self.advert.name or self.advert.address if self.advert else "the device"

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
            counts = self.data.stream_stats(kind, stream.rate).timing
            stream.beats = BeatTimer(max_lag_ns=PPI_MAX_LAG_NS, counts=counts)
        else:
            reported = stream.selected.get(cp.SettingType.SAMPLE_RATE, 0)
            announced = float(actual_rate(self.family, kind.key, reported))
            if announced <= 0:
                raise UnsupportedError(f"{kind.label}: the device gave no sample rate")
            self.data.begin_timing(stream, announced)
        self.data.active[m] = stream
        self._open_output(kind, stream.rate)
        self._watch_source(kind)
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
                hint = "" if self.sdk_mode else " (an SDK-mode value? see --sdk-mode)"
                raise UnsupportedError(
                    f"{name} {want}: {self._device_name()} offers "
                    f"{', '.join(str(v) for v in ints)} for {kind.label}{hint}"
                )
            selected[setting] = want or ints[-1]
        return selected

    def _open_output(self, kind: StreamKind, rate: float) -> None:
        assert self.family is not None and self.device_id is not None
        name = stream_name(self.family, self.device_id, kind.key, self.config.name_prefix)
        source_id = f"{self.device_id}-{kind.label}"
        device = self._device_description()
        declared = self.data.declare(kind, rate, name=name, source_id=source_id, device=device)
        if not declared:
            raise UnsupportedError(
                f"{kind.label} restarted at {rate:g} Hz but its LSL stream declares "
                f"{self.data.opened[kind.key].nominal_rate:g} Hz"
            )

    def _open_markers(self) -> None:
        if "markers" in self.data.opened or self.family is None or self.device_id is None:
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
        self.data.opened["markers"] = stream

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
        return await self.channel.request(client, payload, allow_refusal)

    def _on_control_point(self, _char: Any, data: bytearray) -> None:
        self.channel.on_indication(bytes(data))

    def _on_device_stop(self, message: cp.StopIndication) -> None:
        client = self._client
        for m in message.measurements:
            stream = self.data.active.get(m)
            if stream is None:
                continue
            self.device_stops += 1
            self._emit("device_stopped", marker=True, stream=stream.kind.label)
            self.log.warning(f"the device stopped {stream.kind.label} by itself; restarting it")
            if client is not None:
                self._spawn(self._restart(client, stream))

    async def _restart(self, client: BleClient, stream: ActiveStream, stop_first: bool = False) -> bool:
        """Start a measurement again (after stopping it, for a silent one); False if that failed."""
        assert stream.kind.measurement is not None
        m = int(stream.kind.measurement)
        try:
            if stop_first:
                await self._request(client, cp.stop_request(m), allow_refusal=True)
            await self._request(client, cp.start_request(m, stream.selected))
        except (BleError, cp.ControlPointRefused, UnsupportedError, PolarProtocolError) as exc:
            self.log.error(f"could not restart {stream.kind.label}: {exc}")
            return False
        if stream.timer is not None:
            stream.timer.reset()
        self._watch_source(stream.kind)
        self._emit("stream_restarted", stream=stream.kind.label)
        return True

    # ------------------------------------------------------------------------------------------
    # Watchdog
    def _watch_source(self, kind: StreamKind) -> None:
        """(Re)arm the watchdog for ``kind``'s source: first data due within its start timeout."""
        if self.watchdog is None:
            return
        start = self.config.start_timeout or kind.first_data_s
        stall = max(self.config.stall_timeout, kind.min_stall_s)
        self.watchdog.watch(kind.source, self.clock(), start, stall)

    def _data_seen(self, source: str) -> None:
        if self.watchdog is None:
            return
        first = self.watchdog.data(source, self.clock())
        if first is not None and first > LATE_FIRST_DATA_S:
            self.log.info(f"{self._source_label(source)}: first data {first:.1f} s after its start")

    def _source_keys(self, source: str) -> list[str]:
        """The streams a watched source feeds (``hr``: the HR and RR streams)."""
        if source == "hr":
            return list(self.data.hr_streams)
        return [source] if source in self.stats else []

    def _source_label(self, source: str) -> str:
        return "/".join(STREAM_KINDS[k].label for k in self._source_keys(source)) or source

    async def _watch(self, client: BleClient) -> None:
        """Check the watchdog at its next deadline (at least every ``WATCHDOG_TICK``) and act on alarms."""
        assert self.watchdog is not None
        while True:
            due = self.watchdog.next_due()
            wait = WATCHDOG_TICK if due is None else min(WATCHDOG_TICK, max(0.0, due - self.clock()))
            await asyncio.sleep(wait)
            for alarm in self.watchdog.check(self.clock()):
                await self._on_alarm(client, alarm)

    async def _on_alarm(self, client: BleClient, alarm: Alarm) -> None:
        label = self._source_label(alarm.source)
        self.stalls += 1
        for key in self._source_keys(alarm.source):
            self.stats[key].stalls += 1
        self._emit(
            "stall",
            marker=True,
            stream=label,
            phase=alarm.phase,
            silent_s=round(alarm.silent_s, 3),
            since=alarm.since,
            action=alarm.action,
        )
        what = "since its start" if alarm.phase == START else "while streaming"
        if alarm.action == RESTART:
            self.log.warning(f"{label}: no data for {alarm.silent_s:.1f} s {what}, no disconnect: restarting")
            if await self._restart_source(client, alarm.source):
                return
            reason = f"{label} could not be restarted"
        else:
            reason = f"{label} stayed silent after a restart ({alarm.silent_s:.1f} s {what})"
        self.stall_reconnects += 1
        self.log.warning(f"{reason}: reconnecting")
        self._emit("reconnecting", marker=True, reason=reason)
        if self._reconnect is not None:
            self._reconnect.set()

    async def _restart_source(self, client: BleClient, source: str) -> bool:
        if source != "hr":
            stream = next((s for s in self.data.active.values() if s.kind.key == source), None)
            return stream is not None and await self._restart(client, stream, stop_first=True)
        try:
            await client.stop_notify(HEART_RATE_MEASUREMENT)
            await client.start_notify(HEART_RATE_MEASUREMENT, self._on_heart_rate)
        except BleError as exc:
            self.log.error(f"could not subscribe to the heart rate again: {exc}")
            return False
        self._watch_source(STREAM_KINDS["hr"])
        return True

    # ------------------------------------------------------------------------------------------
    # Data
    def _on_data(self, _char: Any, data: bytearray) -> None:
        arrival = round(self.arrival_clock() * NS)
        raw = bytes(data)
        self._record("notify", PMD_DATA, raw, arrival / NS)
        self.data.on_pmd(raw, arrival)

    def _on_heart_rate(self, _char: Any, data: bytearray) -> None:
        arrival = round(self.arrival_clock() * NS)
        raw = bytes(data)
        self._record("notify", HEART_RATE_MEASUREMENT, raw, arrival / NS)
        self.data.on_heart_rate(raw, arrival)


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

"""A faithful fake of a Polar sensor at the BLE boundary: scripted answers, byte-exact notifications.

:class:`FakePolarDevice` answers what a real sensor answers on the calls the streamer makes
(connect, disconnect, is_connected, the link's MTU, read/write a characteristic, start/stop
notifications, the disconnected callback): the feature read, the battery level, control point
requests answered with indications (settings, start/stop status, SDK mode, scripted refusals),
and a timeline of recorded notifications (PMD data, Heart Rate Measurement, device-initiated
stops) replayed byte for byte. A capture file becomes such a timeline
(:meth:`FakePolarDevice.from_capture`).

Timeline times are seconds on the device's own axis. Playback starts when the session says it
is streaming (:meth:`FakePolarDevice.release`), the first notification due at once; every
notification of the timeline is delivered on time, except those that fall due while the link is
down or while the device does not send that data (as with a real sensor), which are counted in
:attr:`FakePolarDevice.lost`.

Faults seen on real sensors, each scriptable: failed connects, pairing required, dropping the
link after N data notifications, stopping a stream by itself, a link MTU too small for its
frames (INVALID_MTU) or INVALID_MTU now and then whatever the MTU, error answers that name no
op (``F0 00 <measurement> <status>``), a stream that falls silent without any indication
(``stall_after``) and heals on a restart, a reconnection or never, and a stream whose first data
comes late after its start (``start_delays``).

Time: inside :func:`~hri_physio_bridge.polar.virtual_time.run_virtual` with a
:class:`FakeClock`, everything runs in virtual time (no real waiting); without a clock, in real
time at ``speed``.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.ble import (
    Advertisement,
    ConnectionLostError,
    NotifyCallback,
    PairingRequiredError,
)
from hri_physio_bridge.polar.capture import Capture, CaptureError, CaptureRecord
from hri_physio_bridge.polar.devices import STREAM_KINDS
from hri_physio_bridge.polar.gatt import BATTERY_LEVEL, HEART_RATE_MEASUREMENT, PMD_CONTROL_POINT, PMD_DATA
from hri_physio_bridge.polar.protocol import Measurement, PolarProtocolError, decode_heart_rate
from hri_physio_bridge.polar.virtual_time import FakeClock

if TYPE_CHECKING:
    from hri_physio_bridge.polar.session import PolarSession

__all__ = [
    "FakeBleClient", "FakeClock", "FakePolarDevice", "FakeScanner", "Notification", "fake_client_factory",
    "play_through",
]

#: The source name of Heart Rate Measurement notifications in ``stall_after`` (PMD sources are
#: measurement types).
HR_SOURCE = "hr"
KNOWN_MEASUREMENTS = frozenset(int(m) for m in Measurement)
#: What heals a stalled source: a restart of it, a new connection, or nothing.
STALL_HEALS = ("restart", "reconnect", "never")


@dataclass(frozen=True)
class Notification:
    t: float  # seconds on the device's timeline
    char: str  # characteristic UUID
    data: bytes


class FakePolarDevice:
    """One scripted sensor; :meth:`client` gives the BLE client the session talks to."""

    def __init__(
        self,
        name: str = "Polar H10 0A1B2C3D",
        address: str = "A0:9E:1A:00:00:01",
        *,
        features: Iterable[int] = (0, 2),
        battery: int | None = 90,
        settings: dict[int, bytes] | None = None,
        start_params: dict[int, bytes] | None = None,
        start_status: dict[int, int] | None = None,
        timeline: Sequence[Notification] = (),
        rssi: int = -60,
        clock: FakeClock | None = None,
        speed: float = 1.0,
        connect_failures: int = 0,
        pairing_required: bool = False,
        disconnect_after: Sequence[int] = (),
        stop_indication_after: int | None = None,
        visible: bool = True,
        mtu: int | None = 247,
        min_mtu: int = 232,
        invalid_mtu_answers: int = 0,
        unnamed_errors: bool = False,
        stall_after: Mapping[int | str, int] | None = None,
        stall_heals: str = "restart",
        start_delays: Mapping[int, Sequence[float]] | None = None,
        sdk_mode: bool = False,
        sdk_settings: dict[int, bytes] | None = None,
    ) -> None:
        """``mtu``: the largest ATT MTU the link negotiates (None: the stack cannot tell);
        ``min_mtu``: below it the device answers INVALID_MTU (its frames do not fit);
        ``invalid_mtu_answers``: that many settings/start requests answered INVALID_MTU anyway;
        ``unnamed_errors``: error answers carry op 0; ``stall_after``: a source (measurement type
        or ``"hr"``) falls silent after that many notifications on a connection (once), healed by
        ``stall_heals``; ``start_delays``: per measurement, the delay of the first data after each
        start, one per start (later starts: none); ``sdk_mode``: the device offers SDK mode, in
        which get-settings answers ``sdk_settings``."""
        if stall_heals not in STALL_HEALS:
            raise ValueError(f"stall_heals must be one of {', '.join(STALL_HEALS)}, got {stall_heals!r}")
        self.name, self.address, self.rssi = name, address, rssi
        self.features = set(features)
        self.battery = battery
        self.settings = dict(settings or {})
        self.start_params = dict(start_params or {})
        self.start_status = dict(start_status or {})
        self.timeline = sorted(timeline, key=lambda n: n.t)
        self.delivering: Notification | None = None  # the notification being handed to its callback
        self.clock = clock
        self.speed = speed
        self.connect_failures = connect_failures
        self.pairing_required = pairing_required
        self.disconnect_after = list(disconnect_after)
        self.stop_indication_after = stop_indication_after
        self.visible = visible
        self.mtu, self.min_mtu = mtu, min_mtu
        self.invalid_mtu_answers = invalid_mtu_answers
        self.unnamed_errors = unnamed_errors
        self.stall_after = dict(stall_after or {})
        self.stall_heals = stall_heals
        self.start_delays = {m: list(delays) for m, delays in (start_delays or {}).items()}
        self.sdk_mode_offered = sdk_mode
        self.sdk_settings = dict(sdk_settings or {})
        # observable state
        self.operations: list[tuple[str, ...]] = []
        self.connected = False
        self.connections = 0
        self.active: set[int] = set()
        self.subscriptions: dict[str, NotifyCallback] = {}
        self.sdk_mode = False
        self.link_mtu: int | None = None
        self.delivered = 0
        self.lost = 0
        self.stalls = 0
        self._on_disconnect: Callable[[], None] | None = None
        self._base: float | None = None  # host time of timeline time 0
        self._released_from = 0.0  # timeline time from which notifications are delivered
        self._release: asyncio.Event | None = None
        self._finished: asyncio.Event | None = None
        self._playback: asyncio.Task[None] | None = None
        self._data_this_connection = 0
        self._sent: dict[int | str, int] = {}  # notifications sent per source on this connection
        self._stalled: set[int | str] = set()
        self._quiet_until: dict[int, float] = {}  # first data of a started measurement not before
        self._stop_sent = False

    # -- construction from a capture ---------------------------------------------------------------
    @classmethod
    def from_capture(cls, capture: Capture, **kwargs: Any) -> FakePolarDevice:
        """A device that answers and notifies exactly what the capture recorded."""
        features: set[int] = set()
        battery = None
        settings: dict[int, bytes] = {}
        start_params: dict[int, bytes] = {}
        timeline: list[Notification] = []
        for rec in capture.records:
            try:
                cls._take_record(rec, features, settings, start_params, timeline, kwargs)
            except PolarProtocolError as exc:
                raise CaptureError(f"{capture.where(rec)}: {exc}") from None
            if rec.op == "read" and rec.char == BATTERY_LEVEL and battery is None and len(rec.data) == 1:
                battery = rec.data[0]
        device = capture.header.get("device", {}) if isinstance(capture.header.get("device"), dict) else {}
        kwargs.setdefault("name", device.get("name", "Polar H10 0A1B2C3D"))
        kwargs.setdefault("address", device.get("address", "A0:9E:1A:00:00:01"))
        return cls(
            features=features,
            battery=battery,
            settings=settings,
            start_params=start_params,
            timeline=timeline,
            **kwargs,
        )

    @staticmethod
    def _take_record(rec: CaptureRecord, features: set[int], settings: dict[int, bytes],
                     start_params: dict[int, bytes], timeline: list[Notification],
                     kwargs: dict[str, Any]) -> None:
        """What one capture record tells about the device (features, settings, start answers) or
        adds to its timeline; :class:`PolarProtocolError` when a control-point record is not one."""
        if rec.op == "read" and rec.char == PMD_CONTROL_POINT and not features:
            features.update(cp.decode_features(rec.data))
            kwargs.setdefault("sdk_mode", cp.has_sdk_mode(rec.data))
        elif rec.op == "notify" and rec.char == PMD_CONTROL_POINT:
            message = cp.decode_control_point(rec.data)
            if isinstance(message, cp.StopIndication):
                timeline.append(Notification(rec.t, rec.char, rec.data))
            elif message.op == cp.OpCode.GET_SETTINGS and message.measurement not in settings:
                settings[message.measurement] = message.params
            elif message.op == cp.OpCode.START and message.measurement not in start_params:
                start_params[message.measurement] = message.params
        elif rec.op == "notify" and rec.char in (PMD_DATA, HEART_RATE_MEASUREMENT):
            timeline.append(Notification(rec.t, rec.char, rec.data))

    def recorded_streams(self) -> list[str]:
        """The streams the timeline holds data for (``ecg``, ``acc``, ..., ``hr``, ``rr``)."""
        pmd = [k for k in STREAM_KINDS.values() if k.measurement is not None]
        by_measurement = {int(k.measurement): k.key for k in pmd if k.measurement is not None}
        keys: set[str] = set()
        for note in self.timeline:
            source = self._source(note)
            if isinstance(source, int) and source in by_measurement:
                keys.add(by_measurement[source])
            elif source == HR_SOURCE:
                keys.add("hr")
                with contextlib.suppress(PolarProtocolError):
                    if decode_heart_rate(note.data).rr_1024:
                        keys.add("rr")
        return [key for key in STREAM_KINDS if key in keys]

    @property
    def advertisement(self) -> Advertisement:
        return Advertisement(self.name, self.address, self.rssi, handle=self)

    def _now(self) -> float:
        return self.clock() if self.clock is not None else time.monotonic()

    # -- playback ----------------------------------------------------------------------------------
    def release(self) -> None:
        """Let the timeline play on the current connection (call when the session streams).

        The first release puts the timeline's first notification at this instant (exactly: it
        is never late). A later one (after a reconnection) resumes where the timeline is by
        now; what fell due in between was lost with the link.
        """
        if not self.connected:
            return
        now = self._now()
        if self._base is None:
            first = self.timeline[0].t if self.timeline else 0.0
            self._base = now - first / self.speed
            self._released_from = first
        else:
            self._released_from = (now - self._base) * self.speed
        self._events()[0].set()
        if self._playback is None:
            self._playback = asyncio.ensure_future(self._play())

    def _events(self) -> tuple[asyncio.Event, asyncio.Event]:
        if self._release is None or self._finished is None:
            self._release, self._finished = asyncio.Event(), asyncio.Event()
        return self._release, self._finished

    @property
    def finished(self) -> bool:
        return self._finished is not None and self._finished.is_set()

    async def wait_finished(self) -> None:
        await self._events()[1].wait()

    async def _play(self) -> None:
        release, finished = self._events()
        try:
            for note in self.timeline:
                await release.wait()
                assert self._base is not None
                wait = self._base + note.t / self.speed - self._now()
                if wait > 0:
                    await asyncio.sleep(wait)
                # Compared on the timeline's own axis: the first notification is never "before" the release.
                if not self.connected or note.t < self._released_from:
                    self.lost += 1
                    continue
                self._deliver(note)
        finally:
            finished.set()

    @staticmethod
    def _source(note: Notification) -> int | str | None:
        if note.char == PMD_DATA:
            return note.data[0] & cp.MEASUREMENT_MASK if note.data else None
        return HR_SOURCE if note.char == HEART_RATE_MEASUREMENT else None

    def _sends(self, source: int | str | None) -> bool:
        """Whether the device sends this source's notification now (started, not stalled, not late)."""
        if source is None:
            return True
        if source in self._stalled:
            return False
        if isinstance(source, int) and source not in KNOWN_MEASUREMENTS:
            return True  # a recorded notification of a kind no device model knows: passed on as it came
        if isinstance(source, int) and (
            source not in self.active or self._now() < self._quiet_until.get(source, float("-inf"))
        ):
            return False  # not started, or its first data is not due yet
        limit = self.stall_after.get(source)
        if limit is not None and self._sent.get(source, 0) >= limit:
            del self.stall_after[source]
            self._stalled.add(source)
            self.stalls += 1
            self.operations.append(("stalled", str(source)))
            return False
        return True

    def _deliver(self, note: Notification) -> None:
        callback = self.subscriptions.get(note.char)
        source = self._source(note)
        if callback is None or not self._sends(source):
            self.lost += 1
            return
        if source is not None:
            self._sent[source] = self._sent.get(source, 0) + 1
        self.delivered += 1
        self.delivering = note
        try:
            callback(note.char, bytearray(note.data))
        finally:
            self.delivering = None
        if note.char != PMD_DATA:
            return
        self._data_this_connection += 1
        if (
            self.stop_indication_after is not None
            and not self._stop_sent
            and self._data_this_connection >= self.stop_indication_after
            and self.active
        ):
            self._stop_sent = True
            stopped = min(self.active)
            self.active.discard(stopped)
            self._indicate(bytes([cp.STOP_INDICATION_CODE, stopped]))
        if self.disconnect_after and self._data_this_connection >= self.disconnect_after[0]:
            self.disconnect_after.pop(0)
            self.drop_link()

    def drop_link(self) -> None:
        """The link drops (out of range, strap taken off): the client's disconnected callback fires."""
        if not self.connected:
            return
        self.operations.append(("link_lost",))
        self._lose()
        if self._on_disconnect is not None:
            self._on_disconnect()

    def _lose(self) -> None:
        """The link is gone: streams and subscriptions end; SDK mode stays (Polar: only a stop request
        or switching the sensor off ends it)."""
        self.connected = False
        self.active.clear()
        self.subscriptions.clear()
        if self._release is not None:
            self._release.clear()

    def _indicate(self, data: bytes) -> None:
        callback = self.subscriptions.get(PMD_CONTROL_POINT)
        if callback is not None:
            asyncio.get_running_loop().call_soon(callback, PMD_CONTROL_POINT, bytearray(data))

    # -- the client side ---------------------------------------------------------------------------
    def client(self, on_disconnect: Callable[[], None]) -> FakeBleClient:
        return FakeBleClient(self, on_disconnect)

    async def _connect(self, on_disconnect: Callable[[], None]) -> None:
        self.operations.append(("connect",))
        await asyncio.sleep(0)
        if self.connect_failures > 0:
            self.connect_failures -= 1
            raise ConnectionLostError(f"{self.name}: connection failed (scripted)")
        self.connected = True
        self.connections += 1
        self._on_disconnect = on_disconnect
        self._data_this_connection = 0
        self._sent.clear()
        self._quiet_until.clear()
        self.link_mtu = self.mtu
        if self.stall_heals in ("restart", "reconnect"):
            self._stalled.clear()

    async def _request_mtu(self, wanted: int) -> int | None:
        self._check()
        self.operations.append(("request_mtu", str(wanted)))
        await asyncio.sleep(0)
        self.link_mtu = None if self.mtu is None else min(wanted, self.mtu)
        return self.link_mtu

    async def _disconnect(self) -> None:
        self.operations.append(("disconnect",))
        was = self.connected
        self._lose()
        if was and self._on_disconnect is not None:
            self._on_disconnect()

    def _check(self) -> None:
        if not self.connected:
            raise ConnectionLostError(f"{self.name} is not connected")

    async def _read(self, uuid: str) -> bytes:
        self._check()
        self.operations.append(("read", uuid))
        await asyncio.sleep(0)
        if uuid == PMD_CONTROL_POINT:
            return cp.encode_features(self.features, sdk_mode=self.sdk_mode_offered)
        if uuid == BATTERY_LEVEL and self.battery is not None:
            return bytes([self.battery])
        raise ConnectionLostError(f"{self.name} has no readable characteristic {uuid}")

    async def _write(self, uuid: str, data: bytes) -> None:
        self._check()
        self.operations.append(("write", uuid, bytes(data).hex()))
        await asyncio.sleep(0)
        if uuid != PMD_CONTROL_POINT or len(data) < 2:
            raise ConnectionLostError(f"write to {uuid} rejected")
        if self.pairing_required:
            raise PairingRequiredError(f"{self.name} requires pairing (scripted)")
        op, m = data[0], data[1] & cp.MEASUREMENT_MASK
        if m == cp.SDK_MODE and op in (cp.OpCode.START, cp.OpCode.STOP):
            self._answer_sdk_mode(op)
        elif m not in self.features:
            self._answer(op, m, cp.Status.NOT_SUPPORTED)
        elif op in (cp.OpCode.GET_SETTINGS, cp.OpCode.START) and self._refuses_mtu():
            self._answer(op, m, cp.Status.INVALID_MTU)
        elif op == cp.OpCode.GET_SETTINGS:
            offered = self.sdk_settings if self.sdk_mode else self.settings
            self._answer(op, m, cp.Status.SUCCESS, offered.get(m, b""))
        elif op == cp.OpCode.START:
            status = self.start_status.get(m, cp.Status.SUCCESS)
            if status == cp.Status.SUCCESS and m in self.active:
                status = cp.Status.ALREADY_IN_STATE
            if status in (cp.Status.SUCCESS, cp.Status.ALREADY_IN_STATE):
                self._started(m)
            self._answer(op, m, status, self.start_params.get(m, b""))
        elif op == cp.OpCode.STOP:
            status = cp.Status.SUCCESS if m in self.active else cp.Status.ALREADY_IN_STATE
            self.active.discard(m)
            self._answer(op, m, status)
        else:
            self._answer(op, m, cp.Status.INVALID_OP_CODE)

    def _refuses_mtu(self) -> bool:
        if self.link_mtu is not None and self.link_mtu < self.min_mtu:
            return True
        if self.invalid_mtu_answers > 0:
            self.invalid_mtu_answers -= 1
            return True
        return False

    def _started(self, m: int) -> None:
        if m not in self.active:
            delays = self.start_delays.get(m)
            self._quiet_until[m] = self._now() + (delays.pop(0) if delays else 0.0)
        self.active.add(m)
        if self.stall_heals == "restart":
            self._stalled.discard(m)
        self._sent.pop(m, None)

    def _answer_sdk_mode(self, op: int) -> None:
        if not self.sdk_mode_offered:
            self._answer(op, cp.SDK_MODE, cp.Status.NOT_SUPPORTED)
            return
        enable = op == cp.OpCode.START
        status = cp.Status.ALREADY_IN_STATE if self.sdk_mode == enable else cp.Status.SUCCESS
        if enable and self.active:
            status = cp.Status.INVALID_STATE  # SDK mode cannot change while a stream runs
        elif status == cp.Status.SUCCESS:
            self.sdk_mode = enable
        self._answer(op, cp.SDK_MODE, status)

    def _answer(self, op: int, m: int, status: int, params: bytes = b"") -> None:
        """A response indication; with ``unnamed_errors`` an error names no op (``F0 00 m status``)."""
        if status != cp.Status.SUCCESS and status != cp.Status.ALREADY_IN_STATE and self.unnamed_errors:
            self._indicate(bytes([cp.RESPONSE_CODE, 0, m, status]))
            return
        self._indicate(cp.encode_response(op, m, status, params))


class FakeBleClient:
    """The session's view of a :class:`FakePolarDevice` (bleak's BleakClient subset)."""

    def __init__(self, device: FakePolarDevice, on_disconnect: Callable[[], None]) -> None:
        self.device = device
        self._on_disconnect = on_disconnect

    async def connect(self) -> None:
        await self.device._connect(self._on_disconnect)

    async def disconnect(self) -> None:
        await self.device._disconnect()

    @property
    def is_connected(self) -> bool:
        return self.device.connected

    async def request_mtu(self, wanted: int) -> int | None:
        return await self.device._request_mtu(wanted)

    async def read_gatt_char(self, uuid: str) -> bytes:
        return await self.device._read(uuid)

    async def write_gatt_char(self, uuid: str, data: bytes, response: bool = True) -> None:
        await self.device._write(uuid, bytes(data))

    async def start_notify(self, uuid: str, callback: NotifyCallback) -> None:
        self.device._check()
        self.device.operations.append(("start_notify", uuid))
        self.device.subscriptions[uuid] = callback
        if uuid == HEART_RATE_MEASUREMENT and self.device.stall_heals == "restart":
            self.device._stalled.discard(HR_SOURCE)
            self.device._sent.pop(HR_SOURCE, None)

    async def stop_notify(self, uuid: str) -> None:
        self.device.operations.append(("stop_notify", uuid))
        self.device.subscriptions.pop(uuid, None)


class RecordedArrivalClock:
    """A replay's arrival clock: a notification arrives when the capture says it did, on ``host_clock``.

    The first one delivered anchors the capture's times to the host clock; each later one arrives that
    much later as recorded, at any replay speed and however late this machine hands it over. A device
    clock mapped against these arrivals is mapped as the session that recorded them mapped it (at 1000x
    the real arrivals come 1000 times too soon: a false drift, and samples lost after a clock jump).
    Between notifications (reads, writes, control point) it is ``host_clock`` itself.
    """

    def __init__(self, device: FakePolarDevice, host_clock: Callable[[], float]) -> None:
        self.device = device
        self.host_clock = host_clock
        self._origin: tuple[float, float] | None = None  # (host time, capture time) of the first arrival

    def __call__(self) -> float:
        note = self.device.delivering
        if note is None:
            return self.host_clock()
        if self._origin is None:
            self._origin = (self.host_clock(), note.t)
        return self._origin[0] + (note.t - self._origin[1])


class FakeScanner:
    """Finds the visible fake devices; a scan that finds nothing takes its whole timeout."""

    def __init__(self, devices: Sequence[FakePolarDevice], clock: FakeClock | None = None) -> None:
        self.devices = list(devices)
        self.clock = clock
        self.scans = 0

    async def _wait(self, seconds: float) -> None:
        if self.clock is not None:
            await self.clock.sleep(seconds)
        else:
            await asyncio.sleep(seconds)

    async def scan(self, timeout: float) -> list[Advertisement]:
        self.scans += 1
        await self._wait(timeout)
        return [d.advertisement for d in self.devices if d.visible]

    async def find(self, match: Callable[[Advertisement], bool], timeout: float) -> Advertisement | None:
        self.scans += 1
        for device in self.devices:
            if device.visible and not device.connected and match(device.advertisement):
                await asyncio.sleep(0)
                return device.advertisement
        await self._wait(timeout)
        return None


def fake_client_factory(advert: Advertisement, on_disconnect: Callable[[], None]) -> FakeBleClient:
    """The client factory for fake devices (the advertisement's handle is the device)."""
    device = advert.handle
    if not isinstance(device, FakePolarDevice):
        raise ConnectionLostError(f"{advert.address} is not a fake device")
    return device.client(on_disconnect)


async def play_through(session: PolarSession, device: FakePolarDevice) -> int:
    """Run ``session`` on ``device`` until its timeline is played (or the session ends); its exit status.

    The device plays from the moment the session streams, as ``polar_streamer --replay`` does.
    """
    session.listeners.append(lambda e: device.release() if e.get("state") == "streaming" else None)
    stop = asyncio.Event()
    task = asyncio.ensure_future(session.run(stop))
    finished = asyncio.ensure_future(device.wait_finished())
    await asyncio.wait({task, finished}, return_when=asyncio.FIRST_COMPLETED)
    finished.cancel()
    stop.set()
    return await task

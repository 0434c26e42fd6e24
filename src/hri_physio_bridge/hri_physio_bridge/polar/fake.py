"""A faithful fake of a Polar sensor at the BLE boundary: scripted answers, byte-exact notifications.

:class:`FakePolarDevice` answers what a real sensor answers on the calls the streamer makes
(connect, disconnect, is_connected, read/write a characteristic, start/stop notifications, the
disconnected callback): the feature read, the battery level, control point requests answered
with indications (settings, start/stop status, scripted refusals), and a timeline of recorded
notifications (PMD data, Heart Rate Measurement, device-initiated stops) replayed byte for byte.
A capture file becomes such a timeline (:meth:`FakePolarDevice.from_capture`).

Timeline times are seconds on the device's own axis. Playback starts when the session says it
is streaming (:meth:`FakePolarDevice.release`), aligned so the first notification is due at
once; notifications that fall due while the link is down are lost, as with a real sensor.
Faults: failed connects, pairing required, dropping the link after N data notifications,
stopping a stream by itself. With a :class:`FakeClock` everything runs in virtual time
(no real waiting); without one, in real time at ``speed``.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.ble import (
    Advertisement,
    ConnectionLostError,
    NotifyCallback,
    PairingRequiredError,
)
from hri_physio_bridge.polar.capture import Capture
from hri_physio_bridge.polar.gatt import BATTERY_LEVEL, HEART_RATE_MEASUREMENT, PMD_CONTROL_POINT, PMD_DATA


class FakeClock:
    """Virtual seconds: only :meth:`advance`/:meth:`set`/:meth:`sleep` move it."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = float(start)

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += max(0.0, seconds)

    def set(self, t: float) -> None:
        self.now = max(self.now, t)

    async def sleep(self, seconds: float) -> None:
        self.advance(seconds)
        await asyncio.sleep(0)


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
    ) -> None:
        self.name, self.address, self.rssi = name, address, rssi
        self.features = set(features)
        self.battery = battery
        self.settings = dict(settings or {})
        self.start_params = dict(start_params or {})
        self.start_status = dict(start_status or {})
        self.timeline = sorted(timeline, key=lambda n: n.t)
        self.clock = clock
        self.speed = speed
        self.connect_failures = connect_failures
        self.pairing_required = pairing_required
        self.disconnect_after = list(disconnect_after)
        self.stop_indication_after = stop_indication_after
        self.visible = visible
        # observable state
        self.operations: list[tuple[str, ...]] = []
        self.connected = False
        self.connections = 0
        self.active: set[int] = set()
        self.subscriptions: dict[str, NotifyCallback] = {}
        self.delivered = 0
        self.lost = 0
        self._on_disconnect: Callable[[], None] | None = None
        self._released_at: float | None = None
        self._base: float | None = None
        self._release: asyncio.Event | None = None
        self._finished: asyncio.Event | None = None
        self._playback: asyncio.Task[None] | None = None
        self._data_this_connection = 0
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
            if rec.op == "read" and rec.char == PMD_CONTROL_POINT and not features:
                features = cp.decode_features(rec.data)
            elif rec.op == "read" and rec.char == BATTERY_LEVEL and battery is None and len(rec.data) == 1:
                battery = rec.data[0]
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

    @property
    def advertisement(self) -> Advertisement:
        return Advertisement(self.name, self.address, self.rssi, handle=self)

    def _now(self) -> float:
        return self.clock() if self.clock is not None else time.monotonic()

    # -- playback ----------------------------------------------------------------------------------
    def release(self) -> None:
        """Let the timeline play on the current connection (call when the session streams)."""
        if not self.connected:
            return
        self._released_at = self._now()
        if self._base is None:
            self._base = self._released_at - (self.timeline[0].t / self.speed if self.timeline else 0.0)
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
                assert self._base is not None and self._released_at is not None
                due = self._base + note.t / self.speed
                if self.clock is not None:
                    self.clock.set(due)
                    await asyncio.sleep(0)
                else:
                    await asyncio.sleep(max(0.0, due - time.monotonic()))
                if not self.connected or due < self._released_at:
                    self.lost += 1
                    continue
                self._deliver(note)
        finally:
            finished.set()

    def _deliver(self, note: Notification) -> None:
        callback = self.subscriptions.get(note.char)
        if note.char == PMD_DATA and (not note.data or note.data[0] & 0x3F not in self.active):
            callback = None
        if callback is None:
            self.lost += 1
            return
        self.delivered += 1
        callback(note.char, bytearray(note.data))
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
            return cp.encode_features(self.features)
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
        op, m = data[0], data[1] & 0x3F
        if m not in self.features:
            self._indicate(cp.encode_response(op, m, cp.Status.NOT_SUPPORTED))
        elif op == cp.OpCode.GET_SETTINGS:
            self._indicate(cp.encode_response(op, m, cp.Status.SUCCESS, self.settings.get(m, b"")))
        elif op == cp.OpCode.START:
            status = self.start_status.get(m, cp.Status.SUCCESS)
            if status == cp.Status.SUCCESS and m in self.active:
                status = cp.Status.ALREADY_IN_STATE
            if status in (cp.Status.SUCCESS, cp.Status.ALREADY_IN_STATE):
                self.active.add(m)
            self._indicate(cp.encode_response(op, m, status, self.start_params.get(m, b"")))
        elif op == cp.OpCode.STOP:
            status = cp.Status.SUCCESS if m in self.active else cp.Status.ALREADY_IN_STATE
            self.active.discard(m)
            self._indicate(cp.encode_response(op, m, status))
        else:
            self._indicate(cp.encode_response(op, m, cp.Status.INVALID_OP_CODE))


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

    async def read_gatt_char(self, uuid: str) -> bytes:
        return await self.device._read(uuid)

    async def write_gatt_char(self, uuid: str, data: bytes, response: bool = True) -> None:
        await self.device._write(uuid, bytes(data))

    async def start_notify(self, uuid: str, callback: NotifyCallback) -> None:
        self.device._check()
        self.device.operations.append(("start_notify", uuid))
        self.device.subscriptions[uuid] = callback

    async def stop_notify(self, uuid: str) -> None:
        self.device.operations.append(("stop_notify", uuid))
        self.device.subscriptions.pop(uuid, None)


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

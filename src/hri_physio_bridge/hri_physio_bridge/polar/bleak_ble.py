"""The real Bluetooth stack: bleak behind the streamer's :mod:`~hri_physio_bridge.polar.ble` interface.

The only module that imports bleak. Every bleak (and D-Bus) exception is turned into one of
the streamer's errors with a message that says what to do: no Bluetooth at all (no adapter,
adapter off, BlueZ not running, no system D-Bus), pairing required, device not found, or a
connection problem worth retrying.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from bleak import BleakClient, BleakScanner
from bleak.exc import (
    BleakBluetoothNotAvailableError,
    BleakDBusError,
    BleakDeviceNotFoundError,
    BleakError,
    BleakGATTProtocolError,
    BleakGATTProtocolErrorCode,
)

from hri_physio_bridge.polar.ble import (
    Advertisement,
    BleError,
    BleUnavailableError,
    ConnectionLostError,
    DeviceNotFoundError,
    NotifyCallback,
    PairingRequiredError,
)

T = TypeVar("T")

_PAIRING_CODES = {
    BleakGATTProtocolErrorCode.INSUFFICIENT_AUTHENTICATION,
    BleakGATTProtocolErrorCode.INSUFFICIENT_AUTHORIZATION,
    BleakGATTProtocolErrorCode.INSUFFICIENT_ENCRYPTION,
    BleakGATTProtocolErrorCode.INSUFFICIENT_ENCRYPTION_KEY_SIZE,
}
_PAIRING_HINT = (
    "pair it first (Linux: bluetoothctl, then 'pair <address>' and 'trust <address>'), or run with --pair"
)
_NO_BLUEZ_HINT = (
    "no Bluetooth: cannot reach BlueZ over the system D-Bus (is bluetoothd running and is there "
    "a Bluetooth adapter? in a container, share the host's D-Bus and adapter)"
)


def translate(exc: BaseException) -> BleError:
    """The streamer's error for a bleak / D-Bus / OS exception (one clear line)."""
    if isinstance(exc, BleError):
        return exc
    if isinstance(exc, BleakBluetoothNotAvailableError):
        reason = getattr(exc.reason, "name", "UNKNOWN").lower().replace("_", " ")
        return BleUnavailableError(
            f"no Bluetooth ({reason}): {exc.args[0]}; check that an adapter is "
            "present and switched on (bluetoothctl power on)"
        )
    if isinstance(exc, BleakGATTProtocolError):
        if exc.code in _PAIRING_CODES:
            return PairingRequiredError(
                f"the device requires pairing ({exc.code.name.lower()}): {_PAIRING_HINT}"
            )
        return ConnectionLostError(f"GATT error: {exc.args[-1]}")
    if isinstance(exc, BleakDBusError):
        name = exc.dbus_error or ""
        if name in ("org.freedesktop.DBus.Error.ServiceUnknown", "org.freedesktop.DBus.Error.AccessDenied"):
            return BleUnavailableError(f"{_NO_BLUEZ_HINT} ({name})")
        if name in ("org.bluez.Error.NotReady", "org.bluez.Error.NotAvailable"):
            return BleUnavailableError(
                f"no Bluetooth: the adapter is not ready ({name}); bluetoothctl power on"
            )
        if name in (
            "org.bluez.Error.AuthenticationFailed",
            "org.bluez.Error.AuthenticationRejected",
            "org.bluez.Error.AuthenticationCanceled",
            "org.bluez.Error.NotPermitted",
        ):
            return PairingRequiredError(f"the device refused access ({name}): {_PAIRING_HINT}")
        return ConnectionLostError(f"Bluetooth: {name} {exc.dbus_error_details or ''}".strip())
    if isinstance(exc, BleakDeviceNotFoundError):
        return DeviceNotFoundError(f"the device went out of reach ({exc.args[0] if exc.args else ''})")
    if isinstance(exc, BleakError):
        text = " ".join(str(a) for a in exc.args)
        lowered = text.lower()
        if "authenticat" in lowered or "encryption" in lowered:
            return PairingRequiredError(f"the device requires pairing ({text}): {_PAIRING_HINT}")
        if "adapter" in lowered and ("not found" in lowered or "no " in lowered):
            return BleUnavailableError(f"no Bluetooth adapter: {text}")
        return ConnectionLostError(f"Bluetooth: {text}")
    if isinstance(exc, FileNotFoundError | ConnectionRefusedError | PermissionError):
        return BleUnavailableError(f"{_NO_BLUEZ_HINT} ({type(exc).__name__}: {exc})")
    if isinstance(exc, TimeoutError):
        return ConnectionLostError("the device did not answer in time")
    return ConnectionLostError(f"Bluetooth: {type(exc).__name__}: {exc}")


async def _call(awaitable: Awaitable[T]) -> T:
    try:
        return await awaitable
    except (BleakError, OSError, TimeoutError) as exc:
        raise translate(exc) from exc


class BleakBle:
    """Scanner and client factory on bleak."""

    def __init__(self, *, pair: bool = False, connect_timeout: float = 20.0) -> None:
        self.pair = pair
        self.connect_timeout = connect_timeout

    async def scan(self, timeout: float) -> list[Advertisement]:
        found = await _call(BleakScanner.discover(timeout=timeout, return_adv=True))
        return [
            Advertisement(adv.local_name or device.name, device.address, adv.rssi, handle=device)
            for device, adv in found.values()
        ]

    async def find(self, match: Callable[[Advertisement], bool], timeout: float) -> Advertisement | None:
        seen: dict[str, Advertisement] = {}

        def accept(device: Any, adv: Any) -> bool:
            advert = Advertisement(adv.local_name or device.name, device.address, adv.rssi, handle=device)
            if match(advert):
                seen[device.address] = advert
                return True
            return False

        device = await _call(BleakScanner.find_device_by_filter(accept, timeout=timeout))
        return None if device is None else seen.get(device.address)

    def client(self, advert: Advertisement, on_disconnect: Callable[[], None]) -> BleakBleClient:
        return BleakBleClient(advert, on_disconnect, pair=self.pair, timeout=self.connect_timeout)


class BleakBleClient:
    """One connection through bleak; every failure comes out as a streamer error."""

    def __init__(
        self, advert: Advertisement, on_disconnect: Callable[[], None], *, pair: bool, timeout: float
    ) -> None:
        self._client = BleakClient(
            advert.handle or advert.address,
            disconnected_callback=lambda _client: on_disconnect(),
            timeout=timeout,
            pair=pair,
        )

    async def connect(self) -> None:
        await _call(self._client.connect())

    async def disconnect(self) -> None:
        await _call(self._client.disconnect())

    @property
    def is_connected(self) -> bool:
        return bool(self._client.is_connected)

    async def request_mtu(self, wanted: int) -> int | None:
        """The link's MTU. bleak offers no request: its Android backend asks for 517 at connection,
        Windows and macOS negotiate their largest, BlueZ exchanges its configured ExchangeMTU. BlueZ
        reports 23 until the MTU is acquired (bleak's documented workaround: ``_acquire_mtu``)."""
        backend = getattr(self._client, "_backend", None)
        acquire = getattr(backend, "_acquire_mtu", None)
        if acquire is not None:
            await _call(acquire())
        try:
            return int(self._client.mtu_size)
        except (BleakError, AttributeError, NotImplementedError):
            return None

    async def read_gatt_char(self, uuid: str) -> bytes:
        return bytes(await _call(self._client.read_gatt_char(uuid)))

    async def write_gatt_char(self, uuid: str, data: bytes, response: bool = True) -> None:
        await _call(self._client.write_gatt_char(uuid, data, response=response))

    async def start_notify(self, uuid: str, callback: NotifyCallback) -> None:
        await _call(self._client.start_notify(uuid, callback))

    async def stop_notify(self, uuid: str) -> None:
        await _call(self._client.stop_notify(uuid))

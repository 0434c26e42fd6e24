"""The Bluetooth boundary: what the streamer needs from a BLE stack, and the errors it understands.

The session talks to a :class:`BleClient` and a :class:`Scanner`. The real ones wrap bleak
(:mod:`hri_physio_bridge.polar.bleak_ble`, the only module importing it); the fake ones
(:mod:`hri_physio_bridge.polar.fake`) replay byte-exact notifications. Only the methods below are
used, with bleak's names and meanings.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Protocol

NotifyCallback = Callable[[Any, bytearray], None]


@dataclass(frozen=True)
class Advertisement:
    """A device seen while scanning. ``handle`` is whatever the stack needs to connect (bleak's BLEDevice)."""

    name: str | None
    address: str
    rssi: int | None
    handle: Any = None


class BleClient(Protocol):
    """The calls the session makes on one connection (bleak's ``BleakClient`` subset)."""

    async def connect(self) -> None: ...

    async def disconnect(self) -> None: ...

    @property
    def is_connected(self) -> bool: ...

    async def request_mtu(self, wanted: int) -> int | None:
        """Ask for an ATT MTU of ``wanted`` bytes where the stack allows it; the link's MTU after
        that (bleak's ``mtu_size``), None when the stack cannot tell."""
        ...

    async def read_gatt_char(self, uuid: str) -> bytes: ...

    async def write_gatt_char(self, uuid: str, data: bytes, response: bool = True) -> None: ...

    async def start_notify(self, uuid: str, callback: NotifyCallback) -> None: ...

    async def stop_notify(self, uuid: str) -> None: ...


#: Builds a client for an advertisement; the callback is called when the link drops.
ClientFactory = Callable[[Advertisement, Callable[[], None]], BleClient]


class Scanner(Protocol):
    async def scan(self, timeout: float) -> list[Advertisement]: ...

    async def find(self, match: Callable[[Advertisement], bool], timeout: float) -> Advertisement | None: ...


Sleep = Callable[[float], Awaitable[None]]


# ----------------------------------------------------------------------------------------------
# Errors (the adapter turns the stack's exceptions into these)
class BleError(RuntimeError):
    """A Bluetooth problem; the message says what to do."""


class BleUnavailableError(BleError):
    """No Bluetooth here: no adapter, adapter off, no BlueZ / D-Bus, no permission. Not retried."""


class PairingRequiredError(BleError):
    """The device refused access until it is paired (bonded). Not retried."""


class ConnectionLostError(BleError):
    """The link failed or dropped (connect timeout, out of range, device busy). Retried with backoff."""


class DeviceNotFoundError(BleError):
    """No matching device answered a scan. Retried with backoff."""

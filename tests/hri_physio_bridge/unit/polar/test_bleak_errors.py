"""bleak's exceptions become the streamer's errors (the real adapter, no hardware needed)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from bleak.exc import (
    BleakBluetoothNotAvailableError,
    BleakBluetoothNotAvailableReason,
    BleakDBusError,
    BleakDeviceNotFoundError,
    BleakError,
    BleakGATTProtocolError,
)

from hri_physio_bridge.polar.ble import (
    BleUnavailableError,
    ConnectionLostError,
    DeviceNotFoundError,
    PairingRequiredError,
)
from hri_physio_bridge.polar.bleak_ble import BleakBle, translate


@pytest.mark.parametrize(
    "exc, kind, words",
    [
        (
            BleakBluetoothNotAvailableError("no adapter", BleakBluetoothNotAvailableReason.NO_BLUETOOTH),
            BleUnavailableError,
            "no bluetooth",
        ),
        (
            BleakBluetoothNotAvailableError("off", BleakBluetoothNotAvailableReason.POWERED_OFF),
            BleUnavailableError,
            "powered off",
        ),
        (FileNotFoundError(2, "No such file or directory"), BleUnavailableError, "bluez"),
        (BleakDBusError("org.freedesktop.DBus.Error.ServiceUnknown", []), BleUnavailableError, "bluez"),
        (BleakDBusError("org.bluez.Error.NotReady", []), BleUnavailableError, "power on"),
        (BleakGATTProtocolError(5), PairingRequiredError, "pair"),
        (BleakGATTProtocolError(15), PairingRequiredError, "pair"),
        (BleakDBusError("org.bluez.Error.AuthenticationFailed", []), PairingRequiredError, "bluetoothctl"),
        (BleakError("Insufficient Authentication"), PairingRequiredError, "pair"),
        (BleakGATTProtocolError(14), ConnectionLostError, "gatt"),
        (
            BleakDBusError("org.bluez.Error.Failed", ["le-connection-abort-by-local"]),
            ConnectionLostError,
            "bluetooth",
        ),
        (BleakDeviceNotFoundError("AA:BB:CC:DD:EE:FF"), DeviceNotFoundError, "out of reach"),
        (TimeoutError(), ConnectionLostError, "in time"),
        (BleakError("Not connected"), ConnectionLostError, "not connected"),
    ],
)
def test_translate(exc: BaseException, kind: type, words: str) -> None:
    error = translate(exc)
    assert type(error) is kind
    assert words in str(error).lower() and "\n" not in str(error)


@pytest.mark.skipif(
    Path("/run/dbus/system_bus_socket").exists(),
    reason="this machine has a system D-Bus: the no-Bluetooth path needs a machine without",
)
def test_real_scan_without_bluez_is_one_clear_error() -> None:
    """The real bleak path on this machine (no D-Bus / BlueZ / adapter): our error, not bleak's."""
    with pytest.raises(BleUnavailableError, match="no Bluetooth"):
        asyncio.run(BleakBle().scan(0.5))

"""GATT characteristics the streamer uses, and the battery level decoder (no Bluetooth stack here)."""

from __future__ import annotations

from hri_physio_bridge.polar.protocol import PolarProtocolError

PMD_SERVICE = "fb005c80-02e7-f387-1cad-8acd2d8df0c8"
PMD_CONTROL_POINT = "fb005c81-02e7-f387-1cad-8acd2d8df0c8"
PMD_DATA = "fb005c82-02e7-f387-1cad-8acd2d8df0c8"
HEART_RATE_SERVICE = "0000180d-0000-1000-8000-00805f9b34fb"
HEART_RATE_MEASUREMENT = "00002a37-0000-1000-8000-00805f9b34fb"
BATTERY_LEVEL = "00002a19-0000-1000-8000-00805f9b34fb"

#: Short names used in captures and logs.
SHORT_NAMES = {
    PMD_CONTROL_POINT: "pmd_cp",
    PMD_DATA: "pmd_data",
    HEART_RATE_MEASUREMENT: "hr",
    BATTERY_LEVEL: "battery",
}
BY_SHORT_NAME = {short: uuid for uuid, short in SHORT_NAMES.items()}


def normalise_uuid(uuid: str) -> str:
    """Full lower-case 128-bit form of a characteristic (``2a37`` -> ``00002a37-0000-1000-...``)."""
    text = str(uuid).strip().lower()
    if text in BY_SHORT_NAME:
        return BY_SHORT_NAME[text]
    if len(text) == 4:
        return f"0000{text}-0000-1000-8000-00805f9b34fb"
    return text


def decode_battery(data: bytes) -> int:
    """Battery Level (0x2A19): one byte, percent."""
    data = bytes(data)
    if len(data) != 1 or data[0] > 100:
        raise PolarProtocolError(f"battery level {data.hex(' ')!r} is not one byte 0..100")
    return data[0]

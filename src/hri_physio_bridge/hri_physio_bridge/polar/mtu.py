"""The link's MTU: what PMD frames need, what the streamer asks for, and what to say when it is short.

A notification carries at most MTU - 3 bytes (the ATT header). An H10's ECG frame is 229 bytes
(a 10-byte header and 73 samples of 3 bytes), so PMD streams need an ATT MTU of 232 or more; at
the default 23 a sensor answers its settings and start requests with INVALID_MTU. Polar's own
SDK asks for 512. bleak has no call to ask for an MTU: Android's backend asks for 517, Windows
and macOS negotiate the largest their stack allows, and on Linux BlueZ exchanges its configured
``ExchangeMTU`` (517 unless lowered) when it connects; the streamer reads what was negotiated.
"""

from __future__ import annotations

#: What the streamer asks for (Polar's SDK asks for the same).
PREFERRED_MTU = 512
#: Bytes of a notification that are not data (the ATT header).
ATT_HEADER = 3
#: The largest PMD frame a Polar sensor sends at its default settings: an H10 ECG frame.
LARGEST_PMD_FRAME = 229
#: The smallest MTU that carries it.
MIN_PMD_MTU = LARGEST_PMD_FRAME + ATT_HEADER

_FIX = (
    "on Linux set ExchangeMTU = 517 in the [GATT] section of /etc/bluetooth/main.conf and restart "
    "bluetoothd; an adapter that cannot negotiate more cannot stream ECG, PPG or ACC"
)


def describe_mtu(mtu: int | None) -> str:
    return "unknown" if mtu is None else f"{mtu} bytes"


def short_mtu_warning(mtu: int | None, streams: list[str]) -> str | None:
    """A warning when a known MTU is below what PMD frames need (None when it is enough or unknown)."""
    if mtu is None or mtu >= MIN_PMD_MTU or not streams:
        return None
    return (
        f"the link's MTU is {mtu} bytes, below the {MIN_PMD_MTU} bytes the sensor's "
        f"{', '.join(streams)} frames need (up to {LARGEST_PMD_FRAME} bytes each): the sensor may answer "
        f"INVALID_MTU; {_FIX}"
    )


def refused_mtu_message(request: str, mtu: int | None) -> str:
    """The line for an INVALID_MTU answer to ``request`` (e.g. "start ECG at sample rate 130 Hz")."""
    return (
        f"{request}: the sensor answered INVALID_MTU: the link's MTU ({describe_mtu(mtu)}) is too small "
        f"for these settings (PMD frames need {MIN_PMD_MTU} bytes or more); owners see this now and "
        f"then and a new connection cures it, so the streamer reconnects; if it keeps coming, {_FIX}"
    )

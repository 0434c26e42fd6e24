"""What each Polar sensor offers, and how its streams are named on LSL.

Values from Polar's BLE SDK product pages (H10, OH1, Verity Sense) and its known-issues list:

- H10: HR + RR (1 Hz notifications), ECG 130 Hz (µV, 14-bit), ACC 25/50/100/200 Hz at
  +-2/4/8 G (mG).
- OH1: HR, PPG (the device reports 130 Hz but samples at 135 Hz: known issue), PPI, ACC 50 Hz
  at +-8 G.
- Verity Sense (advertises as "Polar Sense"): HR, PPG 55 Hz (28/44/135/176 Hz in SDK mode), PPI,
  ACC 52 Hz at +-8 G (26..416 Hz, +-2..16 G in SDK mode).

LSL names: ``PolarH10/<device-id>/<ECG|ACC|HR|RR>`` and ``PolarOH1/<device-id>/<PPG|ACC|HR|PPI>``
(the Verity Sense uses the OH1 family name), plus ``.../Markers`` for gaps and clock events.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from hri_physio_bridge.polar.protocol import Measurement

#: Rates and ranges the streamer accepts; the device's own settings response decides at connect time.
ECG_RATES = (130,)
ACC_RATES = (25, 26, 50, 52, 100, 104, 200, 208, 416)
ACC_RANGES = (2, 4, 8, 16)
PPG_RATES = (28, 44, 55, 130, 135, 176)
#: The rates Polar sensors sample at, per stream: a measured effective rate near one is given as it.
KNOWN_RATES: dict[str, tuple[int, ...]] = {"ecg": ECG_RATES, "acc": ACC_RATES, "ppg": PPG_RATES}


@dataclass(frozen=True)
class StreamKind:
    """One output stream: its LSL type and channels; ``measurement`` None = Heart Rate service."""

    key: str  # option value: ecg, acc, ...
    label: str  # LSL name suffix and type: ECG, ACC, ...
    measurement: Measurement | None
    channels: tuple[str, ...]
    units: tuple[str, ...]
    #: Fixed nominal rate (Hz); None = the rate the device was started at; 0 = irregular.
    nominal_rate: float | None
    #: Computed by the sensor's own algorithms (HR, RR, PPI): not available in SDK mode.
    computed: bool = False
    #: How long the first data may take after a start (the watchdog's default start timeout).
    first_data_s: float = 10.0
    #: The shortest silence the watchdog may call a stall (data that comes in batches).
    min_stall_s: float = 0.0

    @property
    def source(self) -> str:
        """What the watchdog watches: the measurement, or ``hr`` (one notification feeds HR and RR)."""
        return self.key if self.measurement is not None else "hr"


STREAM_KINDS: dict[str, StreamKind] = {
    # An H10's ECG may start 20-30 s after its start was accepted (owners' reports).
    "ecg": StreamKind("ecg", "ECG", Measurement.ECG, ("ECG",), ("microvolts",), None, first_data_s=40.0),
    "acc": StreamKind("acc", "ACC", Measurement.ACC, ("X", "Y", "Z"), ("mG", "mG", "mG"), None),
    "ppg": StreamKind(
        "ppg", "PPG", Measurement.PPG, ("PPG0", "PPG1", "PPG2", "Ambient"), ("a.u.",) * 4, None
    ),
    # PPI: the first batch about 25 s after the start, then batches of a few beats (Polar's documentation).
    "ppi": StreamKind(
        "ppi",
        "PPI",
        Measurement.PPI,
        ("PPI", "PPIError", "HR", "Flags"),
        ("ms", "ms", "bpm", "bits: 0 invalid, 1 skin contact, 2 contact supported"),
        0.0,
        computed=True,
        first_data_s=40.0,
        min_stall_s=30.0,
    ),
    "hr": StreamKind("hr", "HR", None, ("HR",), ("bpm",), 1.0, computed=True),
    "rr": StreamKind("rr", "RR", None, ("RR",), ("ms",), 0.0, computed=True),
}


@dataclass(frozen=True)
class Family:
    """A kind of Polar sensor: how it advertises, its LSL family name, what it streams."""

    name: str
    lsl_family: str
    name_prefixes: tuple[str, ...]
    streams: tuple[str, ...]
    default_streams: tuple[str, ...]
    #: Sample rates some firmware reports wrongly: reported -> actual (Polar's known issues).
    rate_quirks: tuple[tuple[str, int, int], ...] = ()


FAMILIES: tuple[Family, ...] = (
    Family("H10", "PolarH10", ("Polar H10", "Polar H9"), ("ecg", "acc", "hr", "rr"), ("ecg", "hr", "rr")),
    Family(
        "OH1",
        "PolarOH1",
        ("Polar OH1", "Polar Sense"),
        ("ppg", "ppi", "acc", "hr"),
        ("ppg", "hr"),
        rate_quirks=(("ppg", 130, 135),),
    ),
)

_ID = re.compile(r"\b([0-9A-Fa-f]{8})\b")
_ADDRESS = re.compile(r"^([0-9A-Fa-f]{2}[:-]){5}[0-9A-Fa-f]{2}$|^[0-9A-Fa-f-]{36}$")


def family_of(name: str | None) -> Family | None:
    """The family of a device from its advertised name (``Polar H10 A1B2C3D4`` -> H10)."""
    if not name:
        return None
    for family in FAMILIES:
        if any(name.startswith(prefix) for prefix in family.name_prefixes):
            return family
    return None


def device_id_of(name: str | None) -> str | None:
    """The 8-hex-digit id in an advertised name (printed on the sensor too)."""
    if not name:
        return None
    match = _ID.search(name)
    return match.group(1).upper() if match else None


def is_address(text: str) -> bool:
    """A Bluetooth address (``AA:BB:CC:DD:EE:FF``) or a macOS device UUID."""
    return bool(_ADDRESS.match(text.strip()))


def matches(query: str, name: str | None, address: str) -> bool:
    """Whether an advertisement is the device the user asked for (id, address or name prefix)."""
    q = query.strip()
    if not q:
        return family_of(name) is not None
    if is_address(q):
        return address.replace("-", ":").lower() == q.replace("-", ":").lower()
    if re.fullmatch(r"[0-9A-Fa-f]{8}", q):
        return device_id_of(name) == q.upper()
    return bool(name) and name.lower().startswith(q.lower())


def stream_name(family: Family, device_id: str, kind: str, prefix: str = "") -> str:
    """``[prefix/]PolarH10/<id>/ECG``; ``kind`` is a stream key or ``Markers``."""
    label = STREAM_KINDS[kind].label if kind in STREAM_KINDS else kind
    prefix = prefix.strip("/")
    return f"{prefix + '/' if prefix else ''}{family.lsl_family}/{device_id}/{label}"


def actual_rate(family: Family, kind: str, reported: int) -> int:
    """The rate a stream really has when the firmware reports ``reported`` (known issues)."""
    for quirk_kind, wrong, right in family.rate_quirks:
        if quirk_kind == kind and reported == wrong:
            return right
    return reported


def help_values() -> str:
    """The valid rates and ranges per device, for ``--help``."""
    return (
        "Valid values per device (Polar BLE SDK): H10: ECG 130 Hz; ACC 25, 50, 100, 200 Hz at 2, 4, 8 G. "
        "OH1: PPG 130 Hz as reported (135 Hz real); ACC 50 Hz at 8 G. Verity Sense: PPG 55 Hz "
        "(28, 44, 135, 176 Hz in SDK mode); ACC 52 Hz at 8 G (26-416 Hz, 2-16 G in SDK mode). "
        "SDK mode (--sdk-mode) is a Verity Sense's; it switches HR, RR and PPI off. "
        "The device's own settings are checked at connect time, and each stream's rate is measured "
        "on its first frames (a rate announced wrongly is corrected, with a rate_corrected marker)."
    )

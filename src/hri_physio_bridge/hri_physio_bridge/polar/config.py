"""The Polar streamer's options, declared once (flags, --conf YAML, ROS parameters, --help)."""

from __future__ import annotations

from pydantic import field_validator, model_validator

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_bridge.polar.devices import ACC_RANGES, ACC_RATES, ECG_RATES, PPG_RATES, STREAM_KINDS


def _one_of(name: str, value: int, valid: tuple[int, ...], zero: bool) -> int:
    allowed = ((0,) if zero else ()) + valid
    if value not in allowed:
        raise ValueError(f"must be one of {', '.join(str(v) for v in allowed)}")
    return value


class PolarConfig(NodeConfig):
    """Options of ``polar_streamer``."""

    device: str = option(
        "",
        "the sensor to stream: its 8-hex-digit id (printed on it and listed by --scan), "
        "its Bluetooth address, or a name prefix such as 'Polar H10'",
    )
    streams: list[str] = option(
        [],
        "comma-separated streams: ecg, acc, hr, rr (H10); ppg, ppi, acc, hr "
        "(OH1 / Verity Sense); empty = ecg,hr,rr on an H10, ppg,hr on an OH1",
    )
    ecg_rate: int = option(130, "ECG sample rate (H10: 130)", unit="Hz")
    acc_rate: int = option(
        0,
        "accelerometer sample rate; 0 = the highest the device offers "
        "(H10: 25, 50, 100, 200; OH1: 50; Verity Sense: 52, SDK mode 26-416)",
        unit="Hz",
    )
    acc_range: int = option(
        8, "accelerometer range (H10: 2, 4, 8; OH1 and Verity Sense: 8, SDK mode 2-16)", unit="G"
    )
    ppg_rate: int = option(
        0,
        "PPG sample rate; 0 = the highest the device offers (OH1: 130 as reported, "
        "135 real; Verity Sense: 55, SDK mode 28, 44, 135, 176)",
        unit="Hz",
    )
    sdk_mode: bool = option(
        False,
        "switch the sensor into Polar's SDK mode for its wider rates and ranges (Verity Sense; an H10 "
        "and an OH1 have none); the sensor then computes no HR, RR or PPI",
        switch=True,
    )
    start_timeout: float = option(
        0.0,
        "the watchdog's wait for a stream's first data after its start; 0 = per stream: 40 s for ECG "
        "(an H10 may start it 20-30 s late) and PPI (first batch after ~25 s), 10 s otherwise",
        unit="s",
        ge=0,
    )
    stall_timeout: float = option(
        5.0,
        "longest silence of a streaming stream before the watchdog marks a stall and restarts it "
        "(reconnecting if it stays silent); PPI, sent in batches, at least 30 s",
        unit="s",
        gt=0,
    )
    scan_timeout: float = option(10.0, "length of one scan for the device", unit="s", gt=0)
    connect_timeout: float = option(20.0, "how long one connection attempt may take", unit="s", gt=0)
    response_timeout: float = option(
        5.0, "how long to wait for the device to answer a request", unit="s", gt=0
    )
    backoff_initial: float = option(
        1.0,
        "first delay before reconnecting (doubles up to backoff_max, +-30 percent jitter)",
        unit="s",
        gt=0,
    )
    backoff_max: float = option(30.0, "longest delay between reconnection attempts", unit="s", gt=0)
    give_up_after: float = option(
        0.0,
        "exit (status 1) after this long without a connection; 0 = keep trying until stopped",
        unit="s",
        ge=0,
    )
    pair: bool = option(False, "pair (bond) with the device when connecting (if it requires it)", switch=True)
    ble_latency: float = option(
        0.0, "known Bluetooth delivery latency subtracted from every timestamp", unit="s", ge=0, le=1
    )
    name_prefix: str = option("", "prefix of every LSL stream name, e.g. lab1 -> lab1/PolarH10/<id>/ECG")
    capture: str = option(
        "", "write every notification (characteristic, host time, bytes) to this JSON lines file"
    )
    replay: str = option("", "replay a capture file instead of a real device (tests, demos)")
    replay_speed: float = option(
        1.0, "replay speed (1 = as recorded); a replay pushes every notification it holds at any speed",
        gt=0, le=1000,
    )
    status_period: float = option(5.0, "time between status reports (log and ~/status)", unit="s", gt=0)

    @field_validator("streams")
    @classmethod
    def _streams(cls, value: list[str]) -> list[str]:
        out = [v.strip().lower() for v in value if v.strip()]
        unknown = [v for v in out if v not in STREAM_KINDS]
        if unknown:
            raise ValueError(f"unknown stream(s) {', '.join(unknown)}; known: {', '.join(STREAM_KINDS)}")
        if len(set(out)) != len(out):
            raise ValueError(f"a stream is listed twice: {','.join(out)}")
        return out

    @field_validator("ecg_rate")
    @classmethod
    def _ecg_rate(cls, value: int) -> int:
        return _one_of("ecg_rate", value, ECG_RATES, zero=False)

    @field_validator("acc_rate")
    @classmethod
    def _acc_rate(cls, value: int) -> int:
        return _one_of("acc_rate", value, ACC_RATES, zero=True)

    @field_validator("acc_range")
    @classmethod
    def _acc_range(cls, value: int) -> int:
        return _one_of("acc_range", value, ACC_RANGES, zero=False)

    @field_validator("ppg_rate")
    @classmethod
    def _ppg_rate(cls, value: int) -> int:
        return _one_of("ppg_rate", value, PPG_RATES, zero=True)

    @model_validator(mode="after")
    def _consistent(self) -> PolarConfig:
        if self.backoff_initial > self.backoff_max:
            raise ValueError(
                f"backoff_initial ({self.backoff_initial:g} s) must be <= backoff_max "
                f"({self.backoff_max:g} s)"
            )
        if self.replay and self.capture:
            raise ValueError("capture and replay cannot be used together")
        computed = [s for s in self.streams if STREAM_KINDS[s].computed]
        if self.sdk_mode and computed:
            raise ValueError(
                f"sdk_mode: a sensor in SDK mode computes no {', '.join(computed)}; "
                "choose among ecg, acc, ppg (or leave SDK mode off)"
            )
        return self

"""A synthetic Polar H10 for the fake device: byte-exact notifications with a known truth.

The device samples on its own crystal (``ppm`` fast or slow against the host), stamps every
PMD frame with the device time of its last sample (ns since 2000-01-01, from the H10's reset
date 2019-01-01 by default) and notifies it after a latency plus random BLE jitter. Beats follow a
slowly varying rhythm; the ECG has an R wave at every beat; the Heart Rate Measurement reports
the beats' RR intervals about once a second. Frames can be lost or duplicated on purpose. The
truth (host time of every ECG sample and beat) comes back with the timeline, so tests can
measure the streamer's timestamp error. :func:`write_capture` writes one as a capture file (the
shape ``polar_streamer --capture`` writes), for ``--replay`` soaks and benchmarks.
"""

from __future__ import annotations

import bisect
import math
import random
from dataclasses import dataclass, field
from pathlib import Path

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.capture import CaptureWriter
from hri_physio_bridge.polar.encode import encode_acc_frame, encode_ecg_frame, encode_heart_rate
from hri_physio_bridge.polar.fake import Notification
from hri_physio_bridge.polar.gatt import BATTERY_LEVEL, HEART_RATE_MEASUREMENT, PMD_CONTROL_POINT, PMD_DATA
from hri_physio_bridge.polar.protocol import Measurement

NS = 1_000_000_000
#: 2019-01-01T00:00:00Z in ns since 2000-01-01: where an H10's clock starts after power-off.
H10_RESET_TIME_NS = 599_616_000_000_000_000

#: The parameters of an H10's real answer to a start (``F0 02 00 00 00 00``): one byte, no settings.
H10_START_PARAMS = b"\x00"

H10_SETTINGS = {
    Measurement.ECG: cp.encode_offered_settings(
        {cp.SettingType.SAMPLE_RATE: [130], cp.SettingType.RESOLUTION: [14]}
    ),
    Measurement.ACC: cp.encode_offered_settings(
        {
            cp.SettingType.SAMPLE_RATE: [25, 50, 100, 200],
            cp.SettingType.RESOLUTION: [16],
            cp.SettingType.RANGE: [2, 4, 8],
        }
    ),
}


@dataclass
class SyntheticH10:
    """The script of a fake H10 plus the truth behind it."""

    timeline: list[Notification] = field(default_factory=list)
    ecg_host_s: list[float] = field(default_factory=list)  # true host time of every ECG sample sent
    ecg_values: list[int] = field(default_factory=list)
    beat_host_s: list[float] = field(default_factory=list)
    frames_sent: int = 0
    frames_lost: int = 0
    features: tuple[int, ...] = (Measurement.ECG, Measurement.ACC)
    settings: dict[int, bytes] = field(default_factory=lambda: dict(H10_SETTINGS))


def synthetic_h10(
    seconds: float = 60.0,
    *,
    ppm: float = 0.0,
    latency_ms: float = 8.0,
    jitter_ms: float = 10.0,
    seed: int = 1,
    ecg_frame_samples: int = 73,
    acc_rate: int = 0,
    acc_frame_samples: int = 36,
    heart_rate: bool = True,
    bpm: float = 72.0,
    lose_ecg_frames: frozenset[int] = frozenset(),
    duplicate_ecg_frames: frozenset[int] = frozenset(),
    device_start_ns: int = H10_RESET_TIME_NS + 28 * NS,
) -> SyntheticH10:
    """``seconds`` of an H10 streaming ECG (130 Hz), optionally ACC (``acc_rate`` Hz) and HR/RR."""
    rng = random.Random(seed)
    out = SyntheticH10()
    scale = 1.0 + ppm * 1e-6  # device seconds per host second

    def arrival(host_s: float) -> float:
        return (
            host_s + (latency_ms + rng.expovariate(1.0 / jitter_ms) if jitter_ms > 0 else latency_ms) / 1000.0
        )

    # beats: a rhythm around bpm with slow variation
    beats, t = [], 0.4
    while t < seconds + 2:
        beats.append(t)
        t += 60.0 / bpm * (1.0 + 0.05 * math.sin(2 * math.pi * t / 20.0))
    out.beat_host_s = beats

    def ecg_at(host_s: float) -> int:
        i = bisect.bisect_left(beats, host_s)
        nearest = min(beats[max(0, i - 1) : i + 1], key=lambda b: abs(b - host_s))
        r = 1200.0 * math.exp(-(((host_s - nearest) / 0.012) ** 2))
        return round(r + 80.0 * math.sin(2 * math.pi * host_s * 0.3))

    def device_ns(index: int, rate: int) -> int:
        return device_start_ns + (index * NS) // rate

    total = int(seconds * 130)
    for frame, first in enumerate(range(0, total - ecg_frame_samples + 1, ecg_frame_samples)):
        indices = range(first, first + ecg_frame_samples)
        host = [i / 130 / scale for i in indices]
        values = [ecg_at(h) for h in host]
        data = encode_ecg_frame(device_ns(indices[-1], 130), values)
        if frame in lose_ecg_frames:
            out.frames_lost += 1
        else:
            out.timeline.append(Notification(arrival(host[-1]), PMD_DATA, data))
            out.ecg_host_s.extend(host)
            out.ecg_values.extend(values)
            out.frames_sent += 1
            if frame in duplicate_ecg_frames:
                out.timeline.append(Notification(arrival(host[-1]) + 0.001, PMD_DATA, data))

    if acc_rate:
        total = int(seconds * acc_rate)
        for first in range(0, total - acc_frame_samples + 1, acc_frame_samples):
            indices = range(first, first + acc_frame_samples)
            rows = [[-187 + i % 5, -28, 949 + i % 7] for i in indices]
            last_host = indices[-1] / acc_rate / scale
            out.timeline.append(
                Notification(
                    arrival(last_host), PMD_DATA, encode_acc_frame(device_ns(indices[-1], acc_rate), rows)
                )
            )

    if heart_rate:
        last = 0  # index of the last beat whose interval was reported (the first beat has none)
        t = 1.0
        while t < seconds:
            count = bisect.bisect_right(beats, t)
            rr = [round((beats[j] - beats[j - 1]) * 1024) for j in range(last + 1, count)]
            last = max(last, count - 1)
            hr = round(60.0 / (beats[count - 1] - beats[count - 2])) if count > 1 else round(bpm)
            out.timeline.append(Notification(arrival(t), HEART_RATE_MEASUREMENT, encode_heart_rate(hr, rr)))
            t += 1.0
    out.timeline.sort(key=lambda n: n.t)
    return out


def write_capture(
    path: str | Path,
    syn: SyntheticH10,
    *,
    name: str = "Polar H10 0A1B2C3D",
    address: str = "A0:9E:1A:00:00:01",
    host_start: float = 5000.0,
    battery: int = 90,
) -> int:
    """Write ``syn`` as a capture file: the reads and the settings / start exchange of every
    measurement it has (answered as a real H10 answers), then its notifications. Returns the
    number of notifications written."""
    writer = CaptureWriter(path, {"program": "synthetic", "synthetic": True,
                                  "device": {"name": name, "address": address}})
    try:
        t = host_start
        writer.record(t, "read", PMD_CONTROL_POINT, cp.encode_features(set(syn.features)))
        writer.record(t, "read", BATTERY_LEVEL, bytes([battery]))
        measurements = sorted({n.data[0] for n in syn.timeline if n.char == PMD_DATA})
        for m in measurements:
            offered = cp.decode_settings(syn.settings.get(m, b""))
            chosen = {k: int(values[-1]) for k, values in offered.items() if k != cp.SettingType.FACTOR}
            t += 0.01
            writer.record(t, "write", PMD_CONTROL_POINT, cp.get_settings_request(m))
            answer = cp.encode_response(cp.OpCode.GET_SETTINGS, m, params=syn.settings.get(m, b""))
            writer.record(t + 0.005, "notify", PMD_CONTROL_POINT, answer)
            writer.record(t + 0.01, "write", PMD_CONTROL_POINT, cp.start_request(m, chosen))
            writer.record(t + 0.015, "notify", PMD_CONTROL_POINT,
                          cp.encode_response(cp.OpCode.START, m, params=H10_START_PARAMS))
        start = t + 0.1
        for note in syn.timeline:
            writer.record(start + note.t, "notify", note.char, note.data)
    finally:
        writer.close()
    return len(syn.timeline)

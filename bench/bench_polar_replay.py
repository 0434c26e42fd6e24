"""Benchmark polar_streamer's replay of 130-Hz H10 ECG against real time, side by side in one run.

A synthetic capture of --minutes of H10 ECG (73 samples a notification, the device clock from
2019, a 20 ppm crystal, BLE jitter) goes through:

1. decode only: ``decode_pmd_frame`` on every notification (the floor: no timing, no output);
2. the session unpaced: the whole streamer (control point, rate check, watchdog, per-sample timing,
   clock mapping) on the fake BLE client in virtual time, into memory and into real LSL outlets;
3. the session paced: the fake device in real time at --speeds (default 100 and 1000), into real
   LSL outlets, as ``polar_streamer --replay --replay-speed`` runs it.

Each line gives capture seconds per wall second (x real time), the same per CPU second of this
process (what a loaded machine cannot take away; LSL's own threads not counted), and the samples
pushed out of those sent (a replay must push every notification it holds). The goal: >= 100x for
a paced replay.

``--capture FILE`` replays a capture of your own instead (``polar_streamer --capture``; its ECG is
counted), e.g. one recorded from a real strap.

Run:  source scripts/env.sh && python bench/bench_polar_replay.py [--minutes 30] [--speeds 100,1000]
      [--capture FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import pylsl

from hri_physio_bridge.polar.capture import read_capture
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.fake import (
    FakeClock,
    FakePolarDevice,
    FakeScanner,
    fake_client_factory,
    play_through,
)
from hri_physio_bridge.polar.gatt import PMD_DATA
from hri_physio_bridge.polar.lsl_output import LslSink
from hri_physio_bridge.polar.output import MemorySink, Sink
from hri_physio_bridge.polar.protocol import Measurement, decode_pmd_frame
from hri_physio_bridge.polar.session import PolarSession
from hri_physio_bridge.polar.synthetic import synthetic_h10, write_capture
from hri_physio_bridge.polar.virtual_time import run_virtual


@dataclass
class Line:
    path: str
    wall: float
    cpu: float
    pushed: int


class Timed:
    """Wall and CPU seconds of a ``with`` block."""

    def __enter__(self) -> Timed:
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.wall, self.cpu = time.perf_counter() - self.wall, time.process_time() - self.cpu


async def stream(device: FakePolarDevice, sink: Sink, clock) -> int:
    """Run a session on ``device`` until its timeline is played; the ECG samples pushed."""
    session = PolarSession(
        PolarConfig(device=device.name.split()[-1], streams=["ecg"]),
        FakeScanner([device], clock if isinstance(clock, FakeClock) else None),
        fake_client_factory, sink, clock=clock, watchdog=False,
    )
    await play_through(session, device)
    return session.status()["streams"]["ecg"]["samples"]


def lsl_sink() -> LslSink:
    return LslSink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="length of the capture (default 30)")
    parser.add_argument("--speeds", default="100,1000", help="paced replay speeds (default 100,1000)")
    parser.add_argument("--capture", type=Path, help="replay this capture file instead of a synthetic one")
    args = parser.parse_args()
    if args.capture is None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ecg.jsonl"
            syn = synthetic_h10(args.minutes * 60, heart_rate=False, ppm=20.0, jitter_ms=6.0, seed=1)
            write_capture(path, syn, name=f"Polar H10 {uuid.uuid4().hex[:8].upper()}")
            capture = read_capture(path)
    else:
        capture = read_capture(args.capture)
    notifications = [r for r in capture.records if r.op == "notify" and r.char == PMD_DATA]
    frames = [r.data for r in notifications if r.data[0] == Measurement.ECG]
    span = notifications[-1].t - notifications[0].t
    lines: list[Line] = []

    with Timed() as timed:
        sent = sum(decode_pmd_frame(f).sample_count for f in frames)
    lines.append(Line("decode only (decode_pmd_frame)", timed.wall, timed.cpu, sent))

    unpaced = (("session unpaced, memory sink", MemorySink), ("session unpaced, LSL outlets", lsl_sink))
    for label, make_sink in unpaced:
        clock = FakeClock()
        device = FakePolarDevice.from_capture(capture, clock=clock)
        sink = make_sink()
        with Timed() as timed:
            pushed = run_virtual(stream(device, sink, clock), clock)
        lines.append(Line(label, timed.wall, timed.cpu, pushed))
        sink.close()

    for speed in [float(s) for s in args.speeds.split(",") if s.strip()]:
        device = FakePolarDevice.from_capture(capture, speed=speed)
        sink = lsl_sink()
        with Timed() as timed:
            pushed = asyncio.run(stream(device, sink, pylsl.local_clock))
        lines.append(Line(f"session paced at {speed:g}x, LSL outlets", timed.wall, timed.cpu, pushed))
        sink.close()

    what = args.capture or f"synthetic, {args.minutes:g} min of 130-Hz H10 ECG"
    print(f"capture: {what}: {span / 60:.1f} min, {len(frames)} ECG notifications, {sent} samples")
    print(f"{'path':<38} {'wall s':>7} {'x real time':>11} {'CPU s':>6} {'x per CPU s':>11} "
          f"{'pushed':>8} {'of sent':>7}")
    for line in lines:
        print(f"{line.path:<38} {line.wall:7.2f} {span / line.wall:11.0f} {line.cpu:6.2f} "
              f"{span / max(line.cpu, 1e-9):11.0f} {line.pushed:8d} {line.pushed / sent:7.1%}")


if __name__ == "__main__":
    main()

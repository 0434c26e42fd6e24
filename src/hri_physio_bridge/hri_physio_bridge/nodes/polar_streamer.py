"""polar_streamer: a Polar H10 / OH1 / Verity Sense over Bluetooth LE into LSL, with honest timestamps.

Streams ``PolarH10/<device-id>/<ECG|ACC|HR|RR>`` or ``PolarOH1/<device-id>/<PPG|ACC|HR|PPI>`` and
``.../Markers`` (gaps, clock events, connection changes) on LSL; reconnects by itself; publishes
its status as JSON on ``~/status``. See docs/POLAR.md.

Examples::

    polar_streamer --scan                                   # nearby Polar sensors and their ids
    polar_streamer --device A1B2C3D4                        # an H10: ECG, HR and RR
    polar_streamer --device A1B2C3D4 --streams ecg,acc,hr --acc-rate 200 --acc-range 4
    polar_streamer --device A1B2C3D4 --capture session1.jsonl   # also record every notification
    polar_streamer --replay session1.jsonl                   # replay a capture as if the strap were there
    polar_streamer --device "Polar Sense" --sdk-mode --streams ppg --ppg-rate 176  # Verity Sense, SDK mode
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import threading
import time
from typing import Any

import pylsl
from std_msgs.msg import String

from hri_physio_bridge.config import ConfigError
from hri_physio_bridge.node_runner import ManagedNode, fail, logic_logger, run_node
from hri_physio_bridge.polar.ble import BleError, ClientFactory, Scanner
from hri_physio_bridge.polar.capture import CaptureError, CaptureWriter, read_capture
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.devices import help_values, matches
from hri_physio_bridge.polar.fake import (
    FakePolarDevice,
    FakeScanner,
    RecordedArrivalClock,
    fake_client_factory,
)
from hri_physio_bridge.polar.lsl_output import LslSink
from hri_physio_bridge.polar.session import PolarSession, describe_adverts, scan_for_polar

PROG = "polar_streamer"


class PolarStreamerNode(ManagedNode):
    """ROS 2 shell around :class:`PolarSession`: options, LSL outlets, status topic, exit status."""

    def __init__(self, config: PolarConfig, scan: bool = False) -> None:
        super().__init__(PROG)
        self.config = cfg = self.declare_config(config)
        self.scan_only = scan
        if not scan and not cfg.device and not cfg.replay:
            raise ConfigError(
                "device: give the sensor's id, address or name prefix (find it with --scan), or --replay FILE"
            )
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.status_pub = self.create_publisher(String, "~/status", 10)
        self.replay_device: FakePolarDevice | None = None
        self.session_config = cfg
        if cfg.replay:
            capture = read_capture(cfg.replay)
            for warning in capture.warnings:
                self.log.warning(warning)
            self.replay_device = FakePolarDevice.from_capture(capture, speed=cfg.replay_speed)
            if not self.replay_device.timeline:
                raise CaptureError(f"capture file {cfg.replay} holds no notification to replay")
            recorded_device = self.replay_device
            if cfg.device and not matches(cfg.device, recorded_device.name, recorded_device.address):
                raise ConfigError(
                    f"device: {cfg.device!r} is not the device of capture {cfg.replay} "
                    f"({recorded_device.name}, {recorded_device.address}); leave --device out to replay it"
                )
            if not cfg.streams:  # what the capture holds, not what the sensor could send
                recorded = self.replay_device.recorded_streams()
                self.session_config = cfg.model_copy(update={"streams": recorded or cfg.streams})
        self.capture = (
            CaptureWriter(cfg.capture, {"program": PROG, "started": time.time()}) if cfg.capture else None
        )
        self.sink = LslSink()
        self.session: PolarSession | None = None

    def _ble(self) -> tuple[Scanner, ClientFactory]:
        if self.replay_device is not None:
            return FakeScanner([self.replay_device]), fake_client_factory
        from hri_physio_bridge.polar.bleak_ble import BleakBle  # bleak only when a real device is used

        ble = BleakBle(pair=self.config.pair, connect_timeout=self.config.connect_timeout)
        return ble, ble.client

    def run(self, stop: threading.Event) -> int:
        if self.scan_only:
            return asyncio.run(self._scan())
        return asyncio.run(self._stream(stop))

    async def _scan(self) -> int:
        scanner, _ = self._ble()
        try:
            adverts = await scan_for_polar(scanner, self.config.scan_timeout)
        except BleError as exc:
            return fail(PROG, str(exc))
        for line in describe_adverts(adverts):
            print(line, flush=True)
        return 0

    async def _stream(self, stop_thread: threading.Event) -> int:
        scanner, factory = self._ble()
        device = self.replay_device
        session = PolarSession(
            self.session_config,
            scanner,
            factory,
            self.sink,
            clock=pylsl.local_clock,
            log=self.log,
            capture=self.capture,
            # A replay plays the capture's silences as they were recorded: nothing to restart.
            watchdog=device is None,
            # ... and its notifications arrive when they were recorded, at any replay speed.
            arrival_clock=RecordedArrivalClock(device, pylsl.local_clock) if device is not None else None,
        )
        self.session = session
        stop = asyncio.Event()
        if device is not None:
            session.listeners.append(
                lambda ev: (
                    device.release() if ev["event"] == "state" and ev.get("state") == "streaming" else None
                )
            )

        async def watch() -> None:
            while not stop_thread.is_set() and not (device is not None and device.finished):
                await asyncio.sleep(0.05)
            stop.set()

        async def report() -> None:
            while True:
                await asyncio.sleep(self.config.status_period)
                self._publish_status(log=True)

        tasks = [asyncio.ensure_future(watch()), asyncio.ensure_future(report())]
        try:
            status = await session.run(stop)
        finally:
            for task in tasks:
                task.cancel()
        final = self._publish_status(log=status != 2)
        if final is not None and status != 2:  # one machine-readable line: pushed, gaps, stalls, ...
            self.log.info(f"final status: {json.dumps(final, sort_keys=True)}")
        if status == 2:
            return fail(PROG, session.error or "stopped")
        return status

    def _publish_status(self, log: bool = False) -> dict[str, Any] | None:
        if self.session is None:
            return None
        status = self.session.status()
        status["t"] = time.time()
        status["node"] = self.get_fully_qualified_name()
        if self.replay_device is not None:
            # Recorded notifications the replay did not pass on: link down, or their stream not started.
            status["replay_undelivered"] = self.replay_device.lost
        self.status_pub.publish(String(data=json.dumps(status)))
        if log:
            streams = ", ".join(
                f"{k} {s['samples']} samples ({s['gaps']} gaps, {s['dropped_frames']} dropped, "
                f"{s['stalls']} stalls)"
                for k, s in status["streams"].items()
            )
            self.log.info(
                f"{status['state']}: {streams or 'no stream yet'}; reconnects {status['reconnects']}, "
                f"drift {status['drift_ppm']:+.1f} ppm, MTU {status['mtu'] or 'unknown'}"
            )
        return status

    def close(self) -> None:
        if self.capture is not None:
            self.capture.close()
        self.sink.close()


def _extra_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scan",
        action="store_true",
        help="list nearby Polar sensors (name, address, RSSI, device id) and exit",
    )


def _make_node(config: PolarConfig, args: argparse.Namespace) -> PolarStreamerNode:
    return PolarStreamerNode(config, scan=bool(args.scan))


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG,
        PolarConfig,
        _make_node,
        argv=argv,
        extra_arguments=_extra_arguments,
        startup_errors=(CaptureError, BleError),
        description="Stream a Polar H10 (ECG, ACC, HR, RR) or OH1 / Verity Sense (PPG, PPI, ACC, HR) over "
        "Bluetooth LE onto LSL as PolarH10/<id>/<stream> or PolarOH1/<id>/<stream>, with per-sample "
        "timestamps mapped from the device clock onto the LSL clock, gap markers and automatic reconnection.",
        epilog=help_values() + "\n\nExit status: 0 stopped, 1 gave up (give_up_after), 2 configuration "
        "problem, no Bluetooth, pairing required or a stream, setting or SDK mode the device does not offer.",
    )


if __name__ == "__main__":
    sys.exit(main())

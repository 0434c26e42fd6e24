"""physio_bridge_demo (alias hri_physio_demo): the bridge alone, with no hardware.

Starts the NeuroKit2 simulator as a Polar H10 (ECG at 130 Hz and HR at 1 Hz on LSL), one
physio_receiver per stream (LSL -> ROS 2 topics), and watches the ROS 2 topics from this
process, printing live progress. When the simulated session ends, everything is stopped
cleanly and a summary says how many samples arrived versus how many were sent. (The whole
study session, coach and robot included, is hri_physio_session.)

A launcher, not a node: its options are checked (the simulator's too) before anything starts.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np
from pydantic import model_validator

from hri_physio_bridge.config import (
    ConfigError,
    NodeConfig,
    OneLineErrorParser,
    add_config_arguments,
    given_options,
    option,
)
from hri_physio_bridge.launcher import ManagedProcess, ProcessGroup
from hri_physio_bridge.ros_tools import BackgroundNode
from hri_physio_bridge.simulator import SimulatorConfig
from hri_physio_bridge.stop_signals import install_stop_handlers
from hri_physio_bridge.topics import POLAR_H10_ECG, POLAR_H10_HR
from hri_physio_bridge.waiting import wait_until

PROG = "physio_bridge_demo"
#: The older name of the same command (kept: the README and users type it).
ALIAS = "hri_physio_demo"
ECG_RATE = 130.0
REPORT_EVERY = 2.0  # seconds between progress lines
SIMULATOR_WAIT = 30.0  # seconds the simulator waits for both receivers before streaming


class DemoConfig(NodeConfig):
    """The demo's options; the simulated ones are checked by the simulator's own model."""

    seconds: float = option(30.0, "length of the simulated session", unit="s", gt=0)
    bpm: float = option(70.0, "simulated heart rate", unit="bpm")
    device_id: str = option("SIM0001", "simulated Polar device id")
    quiet_nodes: bool = option(False, "do not echo the nodes' own log lines", switch=True)

    @model_validator(mode="after")
    def _simulator_accepts(self) -> DemoConfig:
        SimulatorConfig.from_mapping(self.simulator_options(), "physio_simulator")
        return self

    def simulator_options(self) -> dict[str, object]:
        return {"seconds": self.seconds, "signals": ["ecg", "hr"], "device_id": self.device_id,
                "rate": ECG_RATE, "bpm": self.bpm, "wait_for_consumers": SIMULATOR_WAIT}


class TopicWatcher(BackgroundNode):
    """Counts ECG samples and keeps the latest HR, from the ROS 2 topics."""

    def __init__(self) -> None:
        from std_msgs.msg import Float64MultiArray

        from hri_physio_bridge.qos import frame_qos
        from hri_physio_bridge.ros_frames import msg_to_frame

        super().__init__("demo_watcher")
        self.ecg_samples = 0
        self.ecg_counter_ok = True
        self.last_ecg_t = float("nan")
        self.hr: float = float("nan")
        self.hr_samples = 0
        self._prev_t: float | None = None

        def on_ecg(msg: Float64MultiArray) -> None:
            f = msg_to_frame(msg)
            if self._prev_t is not None and f.timestamps[0] <= self._prev_t:
                self.ecg_counter_ok = False  # duplicated or reordered samples
            if f.num_samples > 1 and np.any(np.diff(f.timestamps) <= 0):
                self.ecg_counter_ok = False
            self._prev_t = float(f.timestamps[-1])
            self.ecg_samples += f.num_samples
            self.last_ecg_t = self._prev_t

        def on_hr(msg: Float64MultiArray) -> None:
            f = msg_to_frame(msg)
            self.hr = float(f.values[-1, 0])
            self.hr_samples += f.num_samples

        self.node.create_subscription(Float64MultiArray, POLAR_H10_ECG, on_ecg, frame_qos())
        self.node.create_subscription(Float64MultiArray, POLAR_H10_HR, on_hr, frame_qos())
        self.start()


def parse_options(prog: str, argv: list[str] | None) -> DemoConfig:
    parser = OneLineErrorParser(
        prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_arguments(parser, DemoConfig)
    args = parser.parse_args(argv)
    return DemoConfig.from_mapping(given_options(args, DemoConfig), "command line")


def start_nodes(group: ProcessGroup, cfg: DemoConfig, echo: bool) -> ManagedProcess:
    """One receiver per stream, then the simulator (which waits for them); returns the simulator."""
    dev = cfg.device_id
    for stream, topic, frame, rate, node in (("ECG", POLAR_H10_ECG, 13, ECG_RATE, "ecg_receiver"),
                                             ("HR", POLAR_H10_HR, 1, 1.0, "hr_receiver")):
        group.start(node, "physio_receiver", [
            "--input", f"lsl:PolarH10/{dev}/{stream}", "--output", f"ros:{topic}",
            "--output-frame", str(frame), "--sampling-rate", f"{rate:g}",
            "--resolve-timeout", "30", "--wait-for-consumers", "10",
            "--ros-args", "-r", f"__node:={node}",
        ], echo=echo)
    return group.start("simulator", "physio_simulator", [
        "--seconds", f"{cfg.seconds:g}", "--signals", "ecg,hr", "--device-id", dev,
        "--rate", f"{ECG_RATE:g}", "--bpm", f"{cfg.bpm:g}", "--wait-for-consumers", f"{SIMULATOR_WAIT:g}",
    ], echo=echo)


def main(argv: list[str] | None = None) -> int:
    prog = ALIAS if Path(sys.argv[0]).name == ALIAS else PROG
    try:
        cfg = parse_options(prog, argv)
    except ConfigError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr, flush=True)
        return 2
    group = ProcessGroup()
    stop = install_stop_handlers(lambda name: print(f"\n{name}: stopping the demo", flush=True))
    watcher = TopicWatcher()
    print(f"HRI Physio demo: simulated Polar H10 '{cfg.device_id}' for {cfg.seconds:g} s "
          f"-> LSL -> physio_receiver -> ROS 2 {POLAR_H10_ECG}, {POLAR_H10_HR}", flush=True)
    expected = round(cfg.seconds * ECG_RATE)
    failed: dict[str, str] = {}  # process name -> its error line
    try:
        sim = start_nodes(group, cfg, echo=not cfg.quiet_nodes)
        started = time.monotonic()
        while not stop.is_set():
            exited = group.wait_any_exit(REPORT_EVERY, stop=stop)
            if exited is not None:
                if exited.returncode != 0:
                    failed[exited.name] = exited.error_line()
                break
            print(f"[demo] {time.monotonic() - started:5.1f} s: ECG samples on ROS 2: {watcher.ecg_samples}, "
                  f"HR: {watcher.hr:.0f} bpm ({watcher.hr_samples} values)", flush=True)
        if not failed and sim.returncode == 0:
            # Let the receivers forward the tail of the stream before stopping them.
            wait_until(lambda: watcher.ecg_samples >= expected, 5.0, stop=stop)
    finally:
        codes = group.stop()
        time.sleep(0.3)
        watcher.close()
    for name, line in failed.items():
        print(f"[demo] {name} failed (exit status {codes.get(name)}): {line}", flush=True)
    sent = "not simulated: the simulator failed" if "simulator" in failed else f"{expected} simulated"
    print(f"[demo] done: {watcher.ecg_samples} ECG samples received on ROS 2 "
          f"({sent} at {ECG_RATE:g} Hz), {watcher.hr_samples} HR values, "
          f"timestamps strictly increasing: {watcher.ecg_counter_ok}; node exit codes {codes}", flush=True)
    if failed or any(c != 0 for c in codes.values()) or not watcher.ecg_counter_ok:
        return 1
    if not stop.is_set() and watcher.ecg_samples != expected:
        return 1
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())

"""hri_physio_demo: the built-in default session, with no hardware.

Starts the NeuroKit2 simulator as a Polar H10 (ECG at 130 Hz and HR at 1 Hz on
LSL), one physio_receiver per stream (LSL -> ROS 2 topics of DESIGN.md), and
watches the ROS 2 topics from this process, printing live progress. When the
simulated session ends, everything is stopped cleanly and a summary says how
many samples arrived versus how many were sent.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time

import numpy as np

from hri_physio_bridge.launcher import ProcessGroup
from hri_physio_bridge.nodes.common import install_stop_handlers
from hri_physio_bridge.ros_tools import BackgroundNode

ECG_TOPIC = "/physio/polar_h10/ecg"
HR_TOPIC = "/physio/polar_h10/hr"


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

        self.node.create_subscription(Float64MultiArray, ECG_TOPIC, on_ecg, frame_qos())
        self.node.create_subscription(Float64MultiArray, HR_TOPIC, on_hr, frame_qos())
        self.start()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hri_physio_demo",
        description="Simulated participant (NeuroKit2 ECG + HR as a Polar H10) -> LSL -> physio_receiver "
        "-> ROS 2, with live progress. No hardware needed.",
    )
    p.add_argument("--seconds", type=float, default=30.0, help="length of the simulated session (default 30)")
    p.add_argument("--bpm", type=float, default=70.0, help="simulated heart rate (default 70)")
    p.add_argument("--device-id", default="SIM0001", help="simulated Polar device id (default SIM0001)")
    p.add_argument("--quiet-nodes", action="store_true", help="do not echo the nodes' own log lines")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.seconds <= 0:
        print("hri_physio_demo: error: --seconds must be > 0", file=sys.stderr)
        return 2
    rate = 130.0
    dev = args.device_id
    echo = not args.quiet_nodes
    group = ProcessGroup()
    stop = install_stop_handlers(lambda name: print(f"\n{name}: stopping the demo", flush=True))
    watcher = TopicWatcher()
    print(f"HRI Physio demo: simulated Polar H10 '{dev}' for {args.seconds:g} s "
          f"-> LSL -> physio_receiver -> ROS 2 {ECG_TOPIC}, {HR_TOPIC}", flush=True)
    code = 0
    try:
        for stream, topic, frame, node in (("ECG", ECG_TOPIC, 13, "ecg_receiver"),
                                           ("HR", HR_TOPIC, 1, "hr_receiver")):
            group.start(node, "physio_receiver", [
                "--input", f"lsl:PolarH10/{dev}/{stream}", "--output", f"ros:{topic}",
                "--output-frame", str(frame), "--sampling-rate", str(rate if stream == "ECG" else 1.0),
                "--resolve-timeout", "30", "--wait-for-consumers", "10",
                "--ros-args", "-r", f"__node:={node}",
            ], echo=echo)
        sim = group.start("simulator", "physio_simulator", [
            "--seconds", f"{args.seconds:g}", "--signals", "ecg,hr", "--device-id", dev,
            "--rate", f"{rate:g}", "--bpm", f"{args.bpm:g}", "--wait-for-consumers", "30",
        ], echo=echo)
        started = time.monotonic()
        next_report = started + 2.0
        while not stop.wait(0.1):
            if sim.returncode is not None:
                break
            dead = [p for p in group.procs if p.returncode is not None]
            if dead:
                print(f"{dead[0].name} exited early with code {dead[0].returncode}", flush=True)
                code = 1
                break
            if time.monotonic() >= next_report:
                next_report += 2.0
                print(f"[demo] {time.monotonic() - started:5.1f} s: ECG samples on ROS 2: "
                      f"{watcher.ecg_samples}, HR: {watcher.hr:.0f} bpm ({watcher.hr_samples} values)",
                      flush=True)
        if sim.returncode not in (None, 0):
            code = 1
        # Let the receivers forward the tail of the stream before stopping them.
        expected = round(args.seconds * rate)
        deadline = time.monotonic() + 5.0
        while watcher.ecg_samples < expected and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.05)
    finally:
        codes = group.stop()
        time.sleep(0.3)
        watcher.close()
    expected = round(args.seconds * rate)
    print(f"[demo] done: {watcher.ecg_samples} ECG samples received on ROS 2 "
          f"({expected} simulated at {rate:g} Hz), {watcher.hr_samples} HR values, "
          f"timestamps strictly increasing: {watcher.ecg_counter_ok}; node exit codes {codes}", flush=True)
    if any(c != 0 for c in codes.values()) or not watcher.ecg_counter_ok:
        code = 1
    if not stop.is_set() and watcher.ecg_samples != expected:
        code = 1
    return code


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())

"""physio_receiver: forward a physiological stream (LSL, ROS 2 or CSV) to another, losing nothing.

Examples::

    physio_receiver --input lsl:PolarH10/SIM0001/ECG --output ros:/physio/polar_h10/ecg
    physio_receiver --conf receiver.yaml --interactive
    physio_receiver --ros-args --params-file params.yaml
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from hri_physio_bridge.nodes.common import (
    CliError,
    fail,
    install_stop_handlers,
    load_yaml_conf,
    logic_logger,
    split_ros_args,
)
from hri_physio_bridge.receiver import ConfigError, PhysioReceiver, ReceiverConfig
from hri_physio_bridge.streamers import OpenCancelled, StreamerError, create_streamer

PROG = "physio_receiver"
_HELP = {
    "input": "source stream address: lsl:<name>[?type=&source_id=], ros:/<topic>, csv:<file>[?rate=]",
    "output": "destination stream address (same schemes)",
    "dtype": "channel format: float64|float32|int64|int32|int16|int8|string "
    "(aliases: double, float, char...)",
    "sampling_rate": "nominal rate in Hz (0 = irregular); used for gap detection and LSL outputs",
    "input_frame": "largest chunk pulled from the input at once (samples)",
    "output_frame": "samples per published frame",
    "num_channels": "channels per sample (the input must match)",
    "sample_overlap": "samples each frame shares with the previous one (sliding window)",
    "buffer_length": "ring buffer capacity in samples",
    "log_data": "write every received sample to a CSV log before buffering it",
    "log_name": "CSV log path (default logs/<stream>_<time>.csv); never overwritten",
    "overflow_policy": "full buffer: block (wait, lose nothing) or drop_oldest (drop, report a gap)",
    "resolve_timeout": "seconds to wait for the input stream to appear",
    "reconnect": "when the input is lost, keep waiting for it to come back",
    "stream_type": "stream type declared on LSL outputs (default: the input's)",
    "channel_names": "comma-separated channel labels (default: the input's)",
    "wait_for_consumers": "seconds to wait for a listener on the output before reading input (0 = no wait)",
    "min_consumers": "with wait_for_consumers: how many listeners to wait for, e.g. 2 for a processor "
    "and a recorder (ros: outputs only)",
}


def _to_bool(text: str) -> bool:
    low = text.strip().lower()
    if low in ("1", "true", "yes", "on"):
        return True
    if low in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true/false, got {text!r}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Forward a physiological stream between LSL, ROS 2 and CSV through a ring buffer "
        "(sliding-window frames, CSV logging, gap and overflow reporting).",
        epilog="Precedence: defaults < --conf file < command-line options < --ros-args parameters.",
    )
    parser.add_argument("--conf", help="YAML file with the options below (the seed's receiver keys)")
    parser.add_argument(
        "--interactive", action="store_true", help="text console on stdin: status, pause, resume, quit"
    )
    parser.add_argument(
        "--status-period", type=float, default=5.0, help="seconds between progress reports (default 5)"
    )
    defaults = ReceiverConfig()
    for f in dataclasses.fields(ReceiverConfig):
        default = getattr(defaults, f.name)
        kind = {bool: _to_bool, int: int, float: float}.get(type(default), str)
        parser.add_argument(
            "--" + f.name.replace("_", "-"), dest=f.name, type=kind, default=None,
            help=f"{_HELP[f.name]} (default: {default!r})",
        )
    return parser


def _param_value(value: Any) -> Any:
    return ",".join(value) if isinstance(value, list) else value


class PhysioReceiverNode(Node):
    """ROS 2 shell around :class:`PhysioReceiver`: parameters, streamers, status topic."""

    def __init__(self, options: dict[str, Any], **kwargs: Any) -> None:
        super().__init__("physio_receiver", **kwargs)
        merged = dataclasses.asdict(ReceiverConfig())
        merged.update(options)
        for key in ReceiverConfig.KEYS:
            self.declare_parameter(key, _param_value(merged[key]))
        values = {key: self.get_parameter(key).value for key in ReceiverConfig.KEYS}
        names = values["channel_names"]
        values["channel_names"] = [n.strip() for n in names.split(",") if n.strip()] if names else []
        self.config = ReceiverConfig.from_mapping(values, source="physio_receiver parameters")
        self.status_pub = self.create_publisher(String, "~/status", 10)
        self.receiver: PhysioReceiver | None = None

    def build_receiver(self) -> PhysioReceiver:
        cfg = self.config
        source = create_streamer(cfg.input, node=self, max_chunk=cfg.input_frame)
        sink = create_streamer(cfg.output, node=self, max_chunk=cfg.output_frame)
        log = logic_logger(self.get_name(), self.get_logger())
        self.receiver = PhysioReceiver(cfg, source, sink, log=log)
        return self.receiver

    def publish_status(self) -> dict[str, Any]:
        status = self.receiver.status() if self.receiver else {}
        status["t"] = time.time()
        status["node"] = self.get_fully_qualified_name()
        self.status_pub.publish(String(data=json.dumps(status)))
        return status


def _console(receiver: PhysioReceiver, stop: threading.Event, stream: Any = sys.stdin) -> None:
    print("commands: status | pause | resume | quit | help", flush=True)
    for line in stream:
        cmd = line.strip().lower()
        if cmd in ("quit", "exit", "q"):
            stop.set()
            return
        if cmd == "status":
            print(json.dumps(receiver.status()), flush=True)
        elif cmd == "pause":
            receiver.pause()
        elif cmd == "resume":
            receiver.resume()
        elif cmd in ("help", "?", ""):
            print("status: counters as JSON | pause: hold output (input still logged) | "
                  "resume | quit: flush and exit", flush=True)
        else:
            print(f"unknown command {cmd!r}; try: status, pause, resume, quit", flush=True)
    stop.set()  # stdin closed


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    try:
        options = load_yaml_conf(args.conf, "physio_receiver") if args.conf else {}
        unknown = sorted(set(options) - set(ReceiverConfig.KEYS))
        if unknown:
            raise CliError(f"{args.conf}: unknown option(s) {unknown}; known: {list(ReceiverConfig.KEYS)}")
        options.update({k: v for k, v in vars(args).items() if k in ReceiverConfig.KEYS and v is not None})
    except CliError as exc:
        fail(PROG, str(exc))

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node: PhysioReceiverNode | None = None
    executor = SingleThreadedExecutor()
    spin: threading.Thread | None = None
    code = 0
    try:
        try:
            node = PhysioReceiverNode(options)
            receiver = node.build_receiver()
        except (ConfigError, ValueError, StreamerError) as exc:
            fail(PROG, str(exc))
        log = node.get_logger()

        def on_stop(name: str) -> None:
            log.info(f"{name} received: flushing and exiting")
            receiver.request_stop()  # ends the waits for the input and for a consumer too

        stop = install_stop_handlers(on_stop)
        executor.add_node(node)
        spin = threading.Thread(target=_spin, args=(executor,), name="ros-spin")
        spin.start()
        try:
            receiver.open()
        except OpenCancelled:
            log.info(f"stopped before the input {receiver.source.uri} appeared")
            return 0
        except StreamerError as exc:
            log.error(str(exc))
            return 1
        receiver.start()
        if args.interactive:
            threading.Thread(target=_console, args=(receiver, stop), daemon=True).start()
        next_status = time.monotonic() + args.status_period
        while not stop.wait(0.1):
            if receiver.finished:
                break
            if time.monotonic() >= next_status:
                status = node.publish_status()
                log.info(
                    f"received {status['received_samples']} samples, published "
                    f"{status['published_samples']} in {status['published_frames']} frames, "
                    f"gaps {status['gaps']}, NaN/inf {status['nonfinite_samples']}, "
                    f"rejected {status['rejected_messages'] + status['rejected_chunks']}"
                )
                next_status += args.status_period
        receiver.stop()
        node.publish_status()
        if receiver.fatal is not None:
            log.error(f"stopped on error: {receiver.fatal}")
            code = 1
        # Give subscribers a moment to take the last frames before the publisher goes.
        time.sleep(0.2)
    finally:
        executor.shutdown(timeout_sec=1.0)
        if spin is not None:
            spin.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code


def _spin(executor: SingleThreadedExecutor) -> None:
    with contextlib.suppress(ExternalShutdownException, KeyboardInterrupt):
        executor.spin()


if __name__ == "__main__":
    sys.exit(main())

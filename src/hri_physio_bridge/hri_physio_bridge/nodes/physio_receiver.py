"""physio_receiver: forward a physiological stream (LSL, ROS 2 or CSV) to another, losing nothing.

Examples::

    physio_receiver --input lsl:PolarH10/SIM0001/ECG --output ros:/physio/polar_h10/ecg
    physio_receiver --conf receiver.yaml --interactive
    physio_receiver --ros-args --params-file params.yaml
"""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Any

from rclpy.exceptions import InvalidTopicNameException
from std_msgs.msg import String

from hri_physio_bridge.config import ConfigError
from hri_physio_bridge.node_runner import ManagedNode, fail, logic_logger, one_line, run_node
from hri_physio_bridge.receiver import PhysioReceiver, ReceiverConfig
from hri_physio_bridge.streamers import OpenCancelled, Streamer, StreamerError, create_streamer

PROG = "physio_receiver"


class PhysioReceiverNode(ManagedNode):
    """ROS 2 shell around :class:`PhysioReceiver`: parameters, streamers, status topic."""

    def __init__(self, config: ReceiverConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = self.declare_config(config)
        self.status_pub = self.create_publisher(String, "~/status", 10)
        cfg = self.config
        source = _streamer("input", cfg.input, node=self, max_chunk=cfg.input_frame)
        sink = _streamer("output", cfg.output, node=self, max_chunk=cfg.output_frame)
        log = logic_logger(self.get_name(), self.get_logger())
        self.receiver = PhysioReceiver(cfg, source, sink, log=log)

    def publish_status(self) -> dict[str, Any]:
        status = self.receiver.status()
        status["t"] = time.time()
        status["node"] = self.get_fully_qualified_name()
        self.status_pub.publish(String(data=json.dumps(status)))
        return status

    def on_stop(self, signal_name: str) -> None:
        self.get_logger().info(f"{signal_name} received: flushing and exiting")
        self.receiver.request_stop()  # ends the waits for the input and for a consumer too

    def run(self, stop: threading.Event) -> int:
        receiver, log = self.receiver, self.get_logger()
        try:
            receiver.open()
        except OpenCancelled:
            log.info(f"stopped before the input {receiver.source.uri} appeared")
            return 0
        except StreamerError as exc:
            log.error(str(exc))
            return 1
        except (InvalidTopicNameException, OSError) as exc:  # a topic or a file the options name
            receiver.request_stop()
            return fail(PROG, f"cannot open {receiver.source.uri} -> {receiver.sink.uri}: {one_line(exc)}")
        receiver.on_finished = stop.set  # a finite input's end or a fatal error ends the wait below
        receiver.start()
        if self.config.interactive:
            threading.Thread(target=_console, args=(receiver, stop), daemon=True).start()
        period = self.config.status_period
        next_status = time.monotonic() + period
        while not stop.wait(max(0.0, next_status - time.monotonic())) and not receiver.finished:
            if time.monotonic() >= next_status:
                status = self.publish_status()
                log.info(
                    f"received {status['received_samples']} samples, published "
                    f"{status['published_samples']} in {status['published_frames']} frames, "
                    f"gaps {status['gaps']}, clock jumps {status['clock_jumps']}, "
                    f"NaN/inf {status['nonfinite_samples']}, "
                    f"rejected {status['rejected_messages'] + status['rejected_chunks']}"
                )
                next_status += period
        receiver.stop()
        self.publish_status()
        time.sleep(0.2)  # give subscribers a moment to take the last frames before the publisher goes
        if receiver.fatal is not None:
            log.error(f"stopped on error: {receiver.fatal}")
            return 1
        return 0

    def close(self) -> None:
        self.receiver.request_stop()


def _streamer(option: str, uri: str, **kwargs: Any) -> Streamer:
    """The streamer for ``uri``; an address its transport refuses is a configuration error."""
    try:
        return create_streamer(uri, **kwargs)
    except ValueError as exc:
        raise ConfigError(f"{option}: {exc}") from None


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
    return run_node(
        PROG, ReceiverConfig, PhysioReceiverNode, argv=argv, startup_errors=(StreamerError,),
        description="Forward a physiological stream between LSL, ROS 2 and CSV through a ring buffer "
        "(sliding-window frames, CSV logging, gap and overflow reporting).",
    )


if __name__ == "__main__":
    sys.exit(main())

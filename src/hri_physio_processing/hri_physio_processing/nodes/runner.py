"""The ROS 2 shell of neurokit_processor: parameters, input streamer, output topics, main loop.

Kept apart from the console entry point so tests can run the node in-process on their own
rclpy context.
"""

from __future__ import annotations

import json
import math
import threading
import time
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from std_msgs.msg import String

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.nodes.common import logic_logger
from hri_physio_bridge.qos import frame_qos
from hri_physio_bridge.streamers import (
    OpenCancelled,
    Streamer,
    StreamerError,
    StreamLostError,
    StreamNotFoundError,
    StreamSpec,
    create_streamer,
)
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import SCALARS, SIGNAL_FEATURES
from hri_physio_processing.processor import FrameOutput, NeurokitProcessor, Output, StatusOutput

NODE_NAME = "neurokit_processor"


class NeurokitProcessorNode(Node):
    """Declares the parameters and owns the output publishers (ROS 2 and, optionally, LSL)."""

    def __init__(self, options: dict[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        merged = {f: getattr(ProcessorConfig(), f) for f in ProcessorConfig.KEYS}
        merged.update(options or {})
        dynamic = ParameterDescriptor(dynamic_typing=True)  # YAML may say 130 for a float option
        for key in ProcessorConfig.KEYS:
            self.declare_parameter(key, merged[key], dynamic)
        values = {key: self.get_parameter(key).value for key in ProcessorConfig.KEYS}
        self.config = ProcessorConfig.from_mapping(values, source=f"{NODE_NAME} parameters")
        self.prefix = self.config.resolved_output_prefix()
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.outputs: dict[str, list[Streamer]] = {}
        self.status_pub = self.create_publisher(String, f"{self.prefix}/status", frame_qos(100))
        self._open_outputs()

    def _open_outputs(self) -> None:
        cfg = self.config
        features = (*SIGNAL_FEATURES[cfg.mode], *SCALARS[cfg.mode])
        lsl_prefix = cfg.resolved_lsl_prefix()
        for feature in features:
            rate = cfg.sampling_rate if feature in ("clean", "rpeaks", "peaks", "scr_peaks") else 0.0
            sinks: list[Streamer] = []
            ros = create_streamer(f"ros:{self.prefix}/{feature}", node=self)
            ros.open_output(
                StreamSpec(name=f"{self.prefix}/{feature}", nominal_rate=rate, channels=(feature,))
            )
            sinks.append(ros)
            if cfg.lsl_output:
                name = f"{lsl_prefix}/{feature}"
                lsl = create_streamer(f"lsl:{name}")
                lsl.open_output(StreamSpec(
                    name=name, type=f"{cfg.mode.upper()}-{feature}", nominal_rate=rate,
                    source_id=f"{NODE_NAME}{name}", channels=(feature,),
                ))
                sinks.append(lsl)
            self.outputs[feature] = sinks

    def emit(self, out: Output) -> None:
        if isinstance(out, FrameOutput):
            for sink in self.outputs[out.feature]:
                sink.publish(out.frame)
        elif isinstance(out, StatusOutput):
            self.status_pub.publish(String(data=json.dumps(out.payload, allow_nan=False)))

    def close_outputs(self) -> None:
        for sinks in self.outputs.values():
            for sink in sinks:
                sink.close()
        self.outputs.clear()


class ProcessorRunner:
    """Input streamer -> :class:`NeurokitProcessor` -> node outputs, until stopped or the input ends."""

    def __init__(self, node: NeurokitProcessorNode) -> None:
        self.node = node
        self.cfg = node.config
        self.processor = NeurokitProcessor(self.cfg)
        self.source = create_streamer(self.cfg.input, node=node, max_chunk=max(1, self.cfg.hop_samples))
        self._flags: tuple[str, ...] = ()
        self._stop = threading.Event()

    def open(self, stop: threading.Event) -> bool:
        """Connect to the input, retrying until it appears or ``stop`` is set."""
        cfg = self.cfg
        expected = None
        if self.source.scheme == "ros":
            expected = StreamSpec(
                name=cfg.input, channel_count=cfg.num_channels, nominal_rate=cfg.sampling_rate
            )
        while not stop.is_set():
            try:
                spec = self.source.open_input(expected, timeout=cfg.resolve_timeout, stop=stop)
            except OpenCancelled:
                return False
            except StreamNotFoundError as exc:
                self.node.log.warning(f"{exc}; still waiting")
                continue
            if spec.channel_count <= cfg.channel:
                raise StreamerError(
                    f"{cfg.input} has {spec.channel_count} channel(s); channel {cfg.channel} was asked for"
                )
            if spec.nominal_rate > 0 and not math.isclose(spec.nominal_rate, cfg.sampling_rate, rel_tol=1e-6):
                self.node.log.warning(
                    f"{cfg.input} declares {spec.nominal_rate:g} Hz but sampling_rate is "
                    f"{cfg.sampling_rate:g} Hz: windows will be flagged rate_mismatch"
                )
            self.node.log.info(
                f"connected to {cfg.input}; {cfg.mode} windows of {cfg.window_seconds:g} s every "
                f"{cfg.hop_seconds:g} s -> {self.node.prefix}/*"
            )
            return True
        return False

    def step(self, timeout: float = 0.1) -> bool:
        """Process whatever arrived; False when the input has ended (CSV exhausted)."""
        try:
            frame = self.source.receive(timeout)
        except StreamLostError as exc:
            self.node.log.warning(f"{exc}: closing the current segment and waiting for it to return")
            self.publish(self.processor.finish())
            self.source.close()
            return self.open(self._stop)
        if frame is not None:
            self.publish(self.processor.push(_numeric(frame)))
            return True
        return not getattr(self.source, "exhausted", False)

    def publish(self, outputs: list[Output]) -> None:
        for out in outputs:
            self.node.emit(out)
            if isinstance(out, StatusOutput):
                self._log_status(out.payload)

    def _log_status(self, status: dict[str, Any]) -> None:
        log = self.node.log
        if status.get("event") != "window":
            log.warning(f"input discontinuity: {status['reason']}")
            return
        flags = tuple(f["code"] for f in status["flags"])
        feats = status["features"]
        text = (f"window {status['window']['index']} ending t={status['t']:.3f}: "
                + ", ".join(f"{k}={v:.4g}" if v is not None else f"{k}=NaN" for k, v in feats.items()))
        if flags != self._flags:
            if flags:
                log.warning(f"{text}; flagged: " + "; ".join(f["reason"] for f in status["flags"]))
            else:
                log.info(f"{text}; signal OK again" if self._flags else text)
            self._flags = flags
        elif self.cfg.verbose or status["window"]["index"] % 12 == 0:
            log.info(text)

    def wait_for_consumers(self, stop: threading.Event) -> None:
        timeout = self.cfg.wait_for_consumers
        if timeout <= 0:
            return
        ros = [sinks[0] for sinks in self.node.outputs.values()]
        deadline = time.monotonic() + timeout
        while not all(s.has_consumers() for s in ros) or self.node.status_pub.get_subscription_count() == 0:
            if time.monotonic() >= deadline:
                self.node.log.warning(f"not every output has a listener after {timeout:g} s; starting anyway")
                return
            if stop.wait(0.05):
                return
        self.node.log.info("every output has a consumer")

    def run(self, stop: threading.Event) -> int:
        self._stop = stop
        try:
            self.wait_for_consumers(stop)
            if not self.open(stop):
                return 0
            while not stop.is_set():
                if not self.step(0.1):
                    self.node.log.info(f"{self.cfg.input} ended")
                    break
            self.publish(self.processor.finish())
        except StreamerError as exc:
            self.node.log.error(str(exc))
            return 1
        finally:
            self.source.close()
        return 0


def _numeric(frame: Frame) -> Frame:
    if frame.values.dtype.kind not in "fiu":
        raise StreamerError(f"input carries {frame.values.dtype} values; the processor needs numbers")
    return frame

"""neurokit_processor's loop: input streamer -> :class:`NeurokitProcessor` -> outputs (no rclpy).

The node wires the streamers and publishers; this module decides when to wait and for how
long. A file input that is not there is an error at once; a stream that may still appear
(LSL, ROS) is waited for by :class:`~hri_physio_bridge.waiting.StreamOpener`: bounded
attempts, an idle backoff between them and a rate-limited "still waiting" line, until it
appears or the node is stopped. A lost input closes the current segment and is waited for
the same way.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.streamers.base import (
    OpenCancelled,
    Streamer,
    StreamerError,
    StreamLostError,
    StreamSpec,
)
from hri_physio_bridge.waiting import Backoff, Clock, Sleeper, StreamOpener, wait_for_consumers
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.processor import NeurokitProcessor, Output, StatusOutput

#: Inputs that are there or not (a file): never waited for.
NOT_WAITED_FOR = frozenset({"csv"})


class ProcessingPipeline:
    """Runs one processor over one input until the input ends or a stop; returns an exit status."""

    def __init__(
        self,
        cfg: ProcessorConfig,
        source: Streamer,
        emit: Callable[[Output], None],
        log: logging.Logger,
        *,
        consumers: Callable[[], int] | None = None,
        outputs_label: str = "the outputs",
        clock: Clock = time.monotonic,
        backoff: Backoff | None = None,
        sleep: Sleeper | None = None,
        log_period: float = 30.0,
    ) -> None:
        self.cfg = cfg
        self.source = source
        self.emit = emit
        self.log = log
        self.processor = NeurokitProcessor(cfg)
        self._consumers = consumers
        self._outputs_label = outputs_label
        self._clock = clock
        self._backoff = backoff
        self._sleep = sleep
        self._log_period = log_period
        self._flags: tuple[str, ...] = ()
        self.opener: StreamOpener | None = None
        self.connected = False

    @property
    def waits_for_input(self) -> bool:
        """Whether a missing input is waited for (a stream) or an error at once (a file)."""
        return self.source.scheme not in NOT_WAITED_FOR

    # -- the loop --------------------------------------------------------------------------------
    def run(self, stop: threading.Event) -> int:
        """0 when the input ended or a stop came, 1 on an input error (logged in one line)."""
        try:
            if self._consumers is not None and self.cfg.wait_for_consumers > 0:
                wait_for_consumers(self._consumers, 1, self.cfg.wait_for_consumers,
                                   what=f"every output under {self._outputs_label}/", log=self.log,
                                   clock=self._clock, stop=stop)
            if stop.is_set() or not self.open(stop):
                return 0
            while not stop.is_set():
                if not self.step(stop):
                    self.log.info(f"{self.cfg.input} ended")
                    break
            self.publish(self.processor.finish())
        except StreamerError as exc:
            self.log.error(str(exc))
            return 1
        finally:
            self.source.close()
        return 0

    def open(self, stop: threading.Event) -> bool:
        """Connect to the input (waiting for a stream to appear); False when stopped first."""
        cfg = self.cfg
        expected = None
        if self.source.scheme == "ros":
            expected = StreamSpec(name=cfg.input, channel_count=cfg.num_channels,
                                  nominal_rate=cfg.sampling_rate)
        self.opener = StreamOpener(
            self.source, expected, timeout=cfg.resolve_timeout, retry=self.waits_for_input, log=self.log,
            stop=stop, clock=self._clock, backoff=self._backoff, log_period=self._log_period,
            sleep=self._sleep,
        )
        wait = (f"; waiting for it to appear ({cfg.resolve_timeout:g} s per attempt)"
                if self.waits_for_input and self.source.scheme != "ros" else "")
        self.log.info(f"opening {cfg.input}{wait}")
        try:
            spec = self.opener.open()
        except OpenCancelled:
            self.log.info(f"stopped before the input {cfg.input} appeared")
            return False
        if spec.channel_count <= cfg.channel:
            raise StreamerError(
                f"{cfg.input} has {spec.channel_count} channel(s); channel {cfg.channel} was asked for")
        if spec.nominal_rate > 0 and not math.isclose(spec.nominal_rate, cfg.sampling_rate, rel_tol=1e-6):
            self.log.warning(
                f"{cfg.input} declares {spec.nominal_rate:g} Hz but sampling_rate is "
                f"{cfg.sampling_rate:g} Hz: windows will be flagged rate_mismatch")
        self.connected = True
        self.log.info(f"connected to {cfg.input}; {cfg.mode} windows of {cfg.window_seconds:g} s every "
                      f"{cfg.hop_seconds:g} s -> {self._outputs_label}/*")
        return True

    def step(self, stop: threading.Event, timeout: float = 0.1) -> bool:
        """Process whatever arrived; False when the input has ended (or was lost and a stop came)."""
        try:
            frame = self.source.receive(timeout)
        except StreamLostError as exc:
            self.connected = False
            self.log.warning(f"{exc}: closing the current segment and waiting for it to return")
            self.publish(self.processor.finish())
            self.source.close()
            return self.open(stop)
        if frame is not None:
            self.push(frame)
            return True
        return not getattr(self.source, "exhausted", False)

    def push(self, frame: Frame) -> None:
        if frame.values.dtype.kind not in "fiu":
            raise StreamerError(f"{self.cfg.input} carries {frame.values.dtype} values; the processor "
                                "needs numbers")
        try:
            outputs = self.processor.push(frame)
        except ValueError as exc:  # a frame of another shape than the stream's
            raise StreamerError(f"{self.cfg.input}: {exc}") from None
        self.publish(outputs)

    def publish(self, outputs: list[Output]) -> None:
        for out in outputs:
            self.emit(out)
            if isinstance(out, StatusOutput):
                self._log_status(out.payload)

    # -- logging ---------------------------------------------------------------------------------
    def _log_status(self, status: dict[str, Any]) -> None:
        log = self.log
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

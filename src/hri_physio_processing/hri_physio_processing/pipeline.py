"""neurokit_processor's loop: input streamer -> :class:`NeurokitProcessor` -> outputs (no rclpy).

The node wires the streamers and publishers; this module decides when to wait and for how
long. A file input that is not there is an error at once; a stream that may still appear
(LSL, ROS) is waited for by :class:`~hri_physio_bridge.streamers.opener.StreamOpener`: bounded
attempts, an idle backoff between them and a rate-limited "still waiting" line, until it
appears or the node is stopped. A lost input closes the current segment and is waited for
the same way.

The input side loses nothing silently: a ros: input's subscription only queues frames (the
transport's own thread takes them off the middleware at once, into an unbounded queue) and
this loop processes them. When processing falls behind, the queued frames are counted
(``input_backlog``, a rate-limited warning); frames the middleware itself lost before they were
taken are counted too (``dropped_frames``, reported in an ``input_lost`` status event). Both are
in every window's status under ``input``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.rate_limit import RateLimitedLog
from hri_physio_bridge.streamers.base import (
    OpenCancelled,
    Streamer,
    StreamerError,
    StreamLostError,
    StreamSpec,
)
from hri_physio_bridge.streamers.opener import StreamOpener
from hri_physio_bridge.waiting import Backoff, Clock, Sleeper, wait_for_consumers
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import load_neurokit
from hri_physio_processing.processor import NeurokitProcessor, Output, StatusOutput

#: Inputs that are there or not (a file): never waited for.
NOT_WAITED_FOR = frozenset({"csv"})
#: Queued input frames from which "processing is behind the input" is logged (rate-limited).
BACKLOG_WARNING_FRAMES = 1000
#: Seconds between two backlog warnings, and between two ``input_lost`` status events.
INPUT_REPORT_PERIOD = 10.0
#: When frames are queued, up to this many are joined into one chunk per step (catches up faster;
#: the outputs do not depend on the chunking).
MAX_BATCH_FRAMES = 256


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
        self.max_backlog = 0  # most input frames ever queued at once
        self._backlog_log = RateLimitedLog(log.warning, period=INPUT_REPORT_PERIOD, monotonic=clock)
        self._lost_reported = 0
        self._lost_reported_at = -math.inf
        self._last_t = math.nan  # source time of the newest sample taken off the input
        self.drained = 0  # frames processed after a stop (received before it)

    @property
    def waits_for_input(self) -> bool:
        """Whether a missing input is waited for (a stream) or an error at once (a file)."""
        return self.source.scheme not in NOT_WAITED_FOR

    # -- the loop --------------------------------------------------------------------------------
    def run(self, stop: threading.Event) -> int:
        """0 when the input ended or a stop came, 1 on an input error (logged in one line)."""
        try:
            # Seconds of CPU, before the input is open: not in the first window, and not while frames
            # queue up (a stop that comes meanwhile is seen once it is done).
            load_neurokit()
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
            left = self.drain()
            self.publish(self.processor.finish())
            if left:
                self.log.error(f"stopped with {left} input frame(s) received but not processed "
                               f"(drain_timeout {self.cfg.drain_timeout:g} s)")
            self.publish([StatusOutput({
                "t": self._last_t if math.isfinite(self._last_t) else None, "event": "stopped",
                "mode": self.cfg.mode, "ok": not (left or self.source.lost_messages),
                "input": {**self.input_state(), "backlog": left}, "drained_frames": self.drained,
                "stats": self.processor.stats.as_dict()})])
        except StreamerError as exc:
            self.log.error(str(exc))
            return 1
        finally:
            self.source.close()
        return 0

    def drain(self) -> int:
        """Process the frames received before a stop; the number left when ``drain_timeout`` ran out.

        Frames that arrive after the stop are not taken (a stop ends taking new input, not the work
        already received): the count queued at the stop is what is drained.
        """
        queued = self.source.backlog()
        self.drained = 0
        if queued:
            self.log.info(f"stopping: processing the {queued} input frame(s) already received")
        deadline = self._clock() + self.cfg.drain_timeout + self.cfg.drain_per_frame * queued
        while self.drained < queued and self._clock() < deadline:
            frame = self.source.receive(0.0)
            if frame is None:
                break
            self.drained += 1
            if frame.num_samples:
                self._last_t = float(frame.timestamps[-1])
            self.push(frame)
        return queued - self.drained

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
            sleep=self._sleep, on_attempt=self._waiting_for_input,
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

    def _waiting_for_input(self, attempts: int, why: str) -> None:
        """Each attempt that found no input, on the status topic (the log says it once per period)."""
        self.publish([StatusOutput({"t": self._last_t if math.isfinite(self._last_t) else None,
                                    "event": "waiting_for_input", "input": self.cfg.input,
                                    "attempts": attempts, "reason": why})])

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
            self._watch_input()
            frame = self._with_queued(frame)
            if frame.num_samples:
                self._last_t = float(frame.timestamps[-1])
            self.push(frame)
            return True
        self._watch_input()
        return not getattr(self.source, "exhausted", False)

    def _with_queued(self, frame: Frame) -> Frame:
        """``frame`` joined with the frames already queued behind it (same layout), if any."""
        frames = [frame]
        while len(frames) < MAX_BATCH_FRAMES and self.source.backlog() > 0:
            nxt = self.source.receive(0.0)
            if nxt is None:
                break
            if nxt.channels != frames[0].channels or nxt.values.dtype != frames[0].values.dtype:
                self.push(self._join(frames))  # in order; a changed layout is push()'s to judge
                frames = []
            frames.append(nxt)
        return self._join(frames)

    @staticmethod
    def _join(frames: list[Frame]) -> Frame:
        if len(frames) == 1:
            return frames[0]
        return Frame(np.concatenate([f.timestamps for f in frames]),
                     np.concatenate([f.values for f in frames]), frames[0].channels)

    # -- input health ----------------------------------------------------------------------------
    def input_state(self) -> dict[str, int]:
        """Samples processed, frames queued now (and at most), frames the transport lost."""
        return {"samples_in": self.processor.stats.samples_in, "backlog": self.source.backlog(),
                "max_backlog": self.max_backlog, "dropped_frames": self.source.lost_messages}

    def _watch_input(self) -> None:
        backlog = self.source.backlog()
        self.max_backlog = max(self.max_backlog, backlog)
        if backlog >= BACKLOG_WARNING_FRAMES:
            self._backlog_log.report(
                "backlog", f"processing is behind {self.cfg.input}: {backlog} frame(s) queued, outputs come "
                "late", "time(s) behind")
        lost = self.source.lost_messages
        now = self._clock()
        if lost > self._lost_reported and now - self._lost_reported_at >= INPUT_REPORT_PERIOD:
            self.publish([StatusOutput({
                "t": self._last_t if math.isfinite(self._last_t) else None, "event": "input_lost",
                "mode": self.cfg.mode, "ok": False, "dropped_frames": lost, "new": lost - self._lost_reported,
                "backlog": self.source.backlog(),
                "reason": f"{lost} input frame(s) lost by the middleware before the processor took them "
                          f"(its queue of input_depth={self.cfg.input_depth} frames was full); the holes "
                          "show as gaps",
            })])
            self._lost_reported, self._lost_reported_at = lost, now

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
            if isinstance(out, StatusOutput) and out.payload.get("event") == "window":
                out.payload["input"] = self.input_state()
            self.emit(out)
            if isinstance(out, StatusOutput):
                self._log_status(out.payload)

    # -- logging ---------------------------------------------------------------------------------
    def _log_status(self, status: dict[str, Any]) -> None:
        log = self.log
        if status.get("event") == "discontinuity":
            log.warning(f"input discontinuity: {status['reason']}")
            return
        if status.get("event") != "window":
            return  # input_lost: the transport logs its losses itself (rate-limited)
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

"""The video player: requests in, frames to the display at the source's pace, previews and status out.

One thread (the caller's, :meth:`VideoPlayer.run`) renders: it swaps to a new source at the next
frame (no fade), asks the source for the frame due now on the clock, shows it, and hands a copy
to the preview callback ``preview_rate`` times per second of clock time. Requests are queued
from any thread and never dropped; a request that cannot be shown is reported (``error``
status, one log line) and the current source goes on.

A built-in screen is a picture of its time (and tempo): it is drawn again only when that changed
(under sim time the clock moves in steps of 0.1 s, so at real time two frames in three would be
the same picture), and for a display nobody watches (the node's offscreen one) only the frames
that go into a preview are drawn at all; the others are counted as shown, at the same pace.

Frames follow the clock (ROS time: sim time under use_sim_time), but are never shown faster
than ``WALL_RATE_CAP`` x the frame rate in wall time: a simulation at 30x real time shows the
picture due at each moment, skipping frames, instead of rendering 30 times as many.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from audio_video_streamers.pacing import Clock, ClockTicks, Pacer, Sleeper, wait_on_event
from audio_video_streamers.requests import RequestError, parse_video_request, take_queued, unexpected_failure
from audio_video_streamers.status import MediaStatus, RequestLedger, State
from audio_video_streamers.video.display import Display
from audio_video_streamers.video.sources import VideoSource, open_source

StatusCallback = Callable[[MediaStatus], None]
PreviewCallback = Callable[[np.ndarray, float], None]
#: Later than this (clock s), frames are skipped rather than shown in a rush to catch up.
FRAME_LAG = 0.1
#: At most this many times the frame rate per wall second (room to catch up a late frame).
WALL_RATE_CAP = 1.33


class VideoPlayer:
    def __init__(self, display: Display, *, size: tuple[int, int] = (640, 480), fps: float = 30.0,
                 preview_rate: float = 1.0, default_tempo: float = 120.0, title: str = "HRI Physio",
                 clock: Clock = time.time, wall: Clock = time.monotonic,
                 on_status: StatusCallback | None = None, on_preview: PreviewCallback | None = None,
                 media_dir: Path | None = None,
                 log: logging.Logger | None = None, sleep: Sleeper = wait_on_event,
                 ticks: ClockTicks | None = None) -> None:
        self.display, self.size, self.fps, self.preview_rate = display, size, fps, preview_rate
        self.default_tempo, self.title, self.clock, self.media_dir = default_tempo, title, clock, media_dir
        self.on_status = on_status or (lambda status: None)
        self.on_preview = on_preview or (lambda frame, t: None)
        self.log = log or logging.getLogger(__name__)
        # ``ticks``: the clock is sim time, told of each /clock step (the wall clock never is).
        self.pacer, self.wall_pacer = Pacer(clock, sleep=sleep, ticks=ticks), Pacer(wall, sleep=sleep)
        self._next_due: float | None = None  # clock time of the next frame
        self._last_wall: float | None = None
        self.skipped = 0  # frames not shown because the clock ran ahead of the renderer
        self._requests: queue.Queue[str] = queue.Queue()
        self._lock = threading.RLock()  # the source and its time
        self.ledger = RequestLedger()
        self._audio_tempo: float | None = None
        self.source: VideoSource | None = None
        self._source_start: float | None = None
        self._elapsed = 0.0
        self._last_now: float | None = None
        self._next_preview: float | None = None
        self.previews = 0
        self._drawn: tuple[object, np.ndarray] | None = None  # a pure source's last picture, by its key
        self.drawn = 0  # pictures a pure source drew

    # --- inputs (any thread) -----------------------------------------------------------------
    def request(self, text: str) -> None:
        """Queue a request; never blocks, never drops (shown at the next frame)."""
        self.ledger.received(text)
        self._requests.put(text)

    def set_audio_tempo(self, tempo: float | None) -> None:
        """The tempo the audio streamer plays (activities follow it unless the request names one)."""
        self._audio_tempo = tempo

    def current_tempo(self) -> float:
        return self._audio_tempo if self._audio_tempo is not None else self.default_tempo

    # --- rendering ---------------------------------------------------------------------------
    def _apply_requests(self) -> None:
        for text in take_queued(self._requests):
            try:
                request = parse_video_request(text, self.media_dir)
                source = open_source(request, self.size, self.fps, tempo=self.current_tempo, title=self.title)
            except RequestError as exc:
                self._fail(text, str(exc))
                continue
            except Exception as exc:  # a user file may break the decoder in any way: playback goes on
                self._fail(text, str(unexpected_failure(exc)))
                continue
            old = self.source
            with self._lock:
                self.source, self._source_start, self._elapsed = source, None, 0.0
                self._drawn = None
            self.ledger.settle(text, "started")
            if old is not None:
                old.close()
            self.log.info(f"video: showing {text}")

    def _fail(self, text: str, message: str) -> None:
        self.log.error(f"video request {text!r} failed: {message}; what shows goes on")
        self.ledger.settle(text, "failed")
        self.on_status(self.status(error=(text, message)))

    def _clock_jump(self, now: float, period: float) -> bool:
        """True when the clock went back (a replay restarted) or started (sim time reads 0 until the
        first /clock); the source's time then goes on from where it was."""
        last, self._last_now = self._last_now, now
        if last is None or (last <= now and last > 0.0):
            return False
        if self._source_start is not None:
            self._source_start += (now - last) - period
        self._next_preview = None
        return True

    def _wait_for_frame(self, period: float, stop: threading.Event) -> bool:
        if self._next_due is None or self.clock() < self._next_due - period - FRAME_LAG:
            self._next_due = self.clock()  # the first frame, or the clock went back
        if not self.pacer.wait_until(self._next_due, stop):
            return False
        if self._last_wall is not None and not self.wall_pacer.wait_until(
                self._last_wall + period / WALL_RATE_CAP, stop):
            return False
        self._last_wall = self.wall_pacer.clock()
        return True

    def step(self, stop: threading.Event) -> bool:
        """Swap to a requested source, wait for the next frame's time and show it; False when stopped."""
        self._apply_requests()
        fps = self.source.fps if self.source is not None else self.fps
        period = 1.0 / fps
        if not self._wait_for_frame(period, stop):
            return False
        now = self.clock()
        jumped = self._clock_jump(now, period)
        lag = now - self._next_due  # type: ignore[operator]
        if lag > FRAME_LAG:
            if not jumped:
                self.skipped += int(lag * fps)
            self._next_due = now
        self._next_due += period  # type: ignore[operator]
        if self.source is None:
            return True
        preview = self._preview_due(now, period)
        with self._lock:
            if self._source_start is None:  # a new source starts with the frame shown now
                self._source_start = now
            self._elapsed = max(0.0, now - self._source_start)
            source = self.source
            # Nobody sees an unwatched display: a frame is drawn only for a preview (or to keep a
            # file's decoder in step), the others are passed by at the same pace.
            frame = (self._draw(source, self._elapsed)
                     if self.display.watched or preview or not source.pure else None)
        if frame is None:
            self.display.skip()
        else:
            self.display.show(frame)
        if preview:
            assert frame is not None
            self.previews += 1
            self.on_preview(frame.copy(), now)
        self._emit_if_changed()
        return True

    def _preview_due(self, now: float, period: float) -> bool:
        """Whether the frame at ``now`` goes into a preview: one every 1/preview_rate s of clock time,
        on the frame nearest that time."""
        if self.preview_rate <= 0:
            return False
        if self._next_preview is not None and now < self._next_preview - period / 2:
            return False
        step = 1.0 / self.preview_rate
        self._next_preview = (now if self._next_preview is None else self._next_preview) + step
        if self._next_preview <= now:  # fell behind (a fast clock): the next one from now
            self._next_preview = now + step
        return True

    def _draw(self, source: VideoSource, elapsed: float) -> np.ndarray:
        """The source's frame at ``elapsed``. A pure source's picture is drawn again only when its
        key changed: under sim time the clock moves in steps, so frames in between show the same."""
        if not source.pure:
            return source.frame(elapsed)
        key = (source, source.picture_key(elapsed))
        if self._drawn is None or key != self._drawn[0]:
            self._drawn = (key, source.frame(elapsed))
            self.drawn += 1
        return self._drawn[1]

    def run(self, stop: threading.Event) -> int:
        while self.step(stop):
            pass
        return 0

    def _emit_if_changed(self) -> None:
        with self._lock:
            info = self.source.status(self._elapsed) if self.source is not None else {}
            changed = self.ledger.changed((self.source.request if self.source else None, info.get("loops"),
                                           info.get("tempo")))
        if changed:
            self.on_status(self.status())

    # --- status ------------------------------------------------------------------------------
    def status(self, error: tuple[str, str] | None = None) -> MediaStatus:
        with self._lock:
            source = self.source
            extra: dict[str, Any] = {"display": self.display.kind, "shown": self.display.shown,
                                     "previews": self.previews, "skipped": self.skipped}
            fields: dict[str, Any] = {}
            if source is not None:
                info = dict(source.status(self._elapsed))
                fields = dict(source=source.request, kind=source.kind, tempo=info.pop("tempo", None),
                              position=round(info.pop("position"), 3), elapsed=round(info.pop("elapsed"), 3),
                              loops=info.pop("loops", 0), duration=info.pop("duration", None))
                extra.update(info, fps=source.fps)
            state = State.PLAYING if source is not None else State.STOPPED
            return self.ledger.status(self.clock(), state, error, extra, **fields)

    def close(self) -> None:
        with self._lock:
            if self.source is not None:
                self.source.close()
        self.display.close()


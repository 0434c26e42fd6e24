"""The audio player: requests in, the mix out to a sink, status on every change.

Two threads: the **loader** turns requests into tracks (decoding and stretching can take
seconds) while the **playback** loop (the caller's thread, :meth:`AudioPlayer.run`) keeps
rendering the mix into the sink, so what plays never stops for a request.

Every request is accounted for: it is *started*, *failed* (bad file, unknown source, tempo
out of range: one log line and an ``error`` status; what played goes on) or *superseded* (a
newer request was ready before it was heard, as in a burst). Among requests waiting together,
the newest that can be played wins.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from audio_video_streamers.audio.library import AudioLibrary
from audio_video_streamers.audio.mixer import Mixer
from audio_video_streamers.audio.sinks import AudioSink
from audio_video_streamers.audio.track import Track
from audio_video_streamers.pacing import Clock
from audio_video_streamers.requests import RequestError, parse_audio_request, take_queued, unexpected_failure
from audio_video_streamers.status import MediaStatus, RequestLedger

StatusCallback = Callable[[MediaStatus], None]


@dataclass(frozen=True)
class _Command:
    text: str
    track: Track | None  # None: stop


class AudioPlayer:
    def __init__(self, library: AudioLibrary, sink: AudioSink, *, fade: float, block: int = 1024,
                 clock: Clock = time.time, on_status: StatusCallback | None = None,
                 media_dir: Path | None = None, log: logging.Logger | None = None) -> None:
        self.library, self.sink, self.block = library, sink, block
        self.mixer = Mixer(sink.rate, sink.channels, fade)
        self.clock, self.media_dir = clock, media_dir
        self.on_status = on_status or (lambda status: None)
        self.log = log or logging.getLogger(__name__)
        self._requests: queue.Queue[str | None] = queue.Queue()  # None: wakes the loader to stop
        self._commands: queue.Queue[_Command] = queue.Queue()
        self._lock = threading.RLock()  # the mixer
        self.ledger = RequestLedger()
        self._stop = threading.Event()
        self._loader: threading.Thread | None = None

    # --- requests (any thread) ---------------------------------------------------------------
    def request(self, text: str) -> None:
        """Queue a request; never blocks, never drops."""
        self.ledger.received(text)
        self._requests.put(text)

    def start_loader(self) -> None:
        if self._loader is None:
            self._loader = threading.Thread(target=self._load_loop, name="audio-loader", daemon=True)
            self._loader.start()

    def _load_loop(self) -> None:
        while not self._stop.is_set():
            waiting = self._queued(self._requests.get())  # waits for a request, or the stop's None
            if waiting:
                self._prepare(waiting)

    def _queued(self, *first: str | None) -> list[str]:
        """``first`` and the requests queued now, oldest first (the stop's wake-up left out)."""
        return [text for text in (*first, *take_queued(self._requests)) if text is not None]

    def _stop_loader(self) -> None:
        self._stop.set()
        self._requests.put(None)

    def prepare_pending(self) -> None:
        """Prepare every queued request now, on this thread (what the loader does; for tests and tools)."""
        waiting = self._queued()
        if waiting:
            self._prepare(waiting)

    def _prepare(self, waiting: list[str]) -> None:
        """Resolve the newest playable request of ``waiting`` (plus any arriving meanwhile)."""
        ready: _Command | None = None
        while waiting:
            text = waiting.pop()  # the newest not yet tried
            try:
                command = self._resolve(text)
            except RequestError as exc:
                self._fail(text, str(exc))
            else:
                for older in [*waiting, *([ready.text] if ready else [])]:
                    self.ledger.settle(older, "superseded")
                waiting, ready = [], command
            waiting.extend(self._queued())  # newer than everything above: tried first
        if ready is not None:
            self._commands.put(ready)

    def preload(self, texts: list[str]) -> int:
        """Prepare the tracks of ``texts`` now, on this thread (the library keeps them), so a request for
        one later starts at the next block; returns how many are ready. One that cannot be prepared is
        logged (a warning: it is tried again, and reported, when asked for)."""
        ready = 0
        for text in texts:
            try:
                self._resolve(text)
            except RequestError as exc:
                self.log.warning(f"audio preload {text!r}: {exc}; it is tried again when asked for")
            else:
                ready += 1
        return ready

    def _resolve(self, text: str) -> _Command:
        request = parse_audio_request(text, self.media_dir)
        if request.kind == "stop":
            return _Command(text, None)
        try:
            return _Command(text, self.library.load(request))
        except RequestError:
            raise
        except Exception as exc:  # a user file may break a library in any way: the loader goes on
            raise unexpected_failure(exc) from None

    def _fail(self, text: str, message: str) -> None:
        self.log.error(f"audio request {text!r} failed: {message}; what plays goes on")
        self.ledger.settle(text, "failed")
        self.on_status(self.status(error=(text, message)))

    # --- playback (the caller's thread) ------------------------------------------------------
    def run(self, stop: threading.Event) -> int:
        """Start the loader and render the mix into the sink until ``stop``; returns 0."""
        self.start_loader()
        self._emit_if_changed()
        try:
            while not self._stop.is_set() and self.step(stop):
                pass
        finally:
            self._stop_loader()
        return 0

    def step(self, stop: threading.Event) -> bool:
        """Apply prepared requests, render one block and play it; False when stopped."""
        self._apply_commands()
        with self._lock:
            block = self.mixer.render(self.block)
        if not self.sink.write(block, stop):
            return False
        self._emit_if_changed()
        return True

    def _apply_commands(self) -> None:
        for command in take_queued(self._commands):
            with self._lock:
                if command.track is None:
                    self.mixer.stop()
                else:
                    self.mixer.start(command.track)
                self.ledger.settle(command.text, "started")
            self.log.info(f"audio: {'stopping' if command.track is None else 'playing ' + command.text}")

    def _emit_if_changed(self) -> None:
        with self._lock:
            current = self.mixer.current
            changed = self.ledger.changed((self.mixer.state, current.track.source if current else None,
                                           tuple(self.mixer.fading_out())))
        if changed:
            self.on_status(self.status())

    # --- status ------------------------------------------------------------------------------
    def status(self, error: tuple[str, str] | None = None) -> MediaStatus:
        """A snapshot; with ``error`` (request, message) it reports that failure."""
        with self._lock:
            voice = self.mixer.current
            extra: dict = {"fade": self.mixer.fade, "sink": self.sink.kind}
            fading = self.mixer.fading_out()
            if fading:
                extra["fading_out"] = fading
            underruns = getattr(self.sink, "underruns", None)
            if underruns is not None:
                extra["underruns"] = underruns
            state = self.mixer.state
            fields: dict = {}
            if voice is not None:
                track = voice.track
                extra.update(track.info)
                fields = dict(source=track.source, kind=track.kind, tempo=track.tempo,
                              position=round((voice.position % track.frames) / track.rate, 3),
                              elapsed=round(voice.position / track.rate, 3),
                              loops=voice.position // track.frames, duration=round(track.duration, 3))
            return self.ledger.status(self.clock(), state, error, extra, **fields)

    def close(self) -> None:
        self._stop_loader()
        if self._loader is not None:
            self._loader.join(timeout=5.0)
        self.sink.close()


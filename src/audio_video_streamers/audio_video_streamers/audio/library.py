"""From a parsed request to a playable :class:`Track`, with an in-memory cache of recent tracks."""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from pathlib import Path

from audio_video_streamers.audio import synth
from audio_video_streamers.audio.files import decode
from audio_video_streamers.audio.stretch import StretchCache, stretched
from audio_video_streamers.audio.track import Track
from audio_video_streamers.requests import AudioRequest, RequestError


class TrackCache:
    """Least-recently-used tracks up to ``max_bytes`` of samples (the coach returns to the same few)."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._tracks: OrderedDict[tuple, Track] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple) -> Track | None:
        with self._lock:
            track = self._tracks.get(key)
            if track is not None:
                self._tracks.move_to_end(key)
            return track

    def put(self, key: tuple, track: Track) -> None:
        with self._lock:
            self._tracks[key] = track
            self._tracks.move_to_end(key)
            while len(self._tracks) > 1 and sum(t.nbytes for t in self._tracks.values()) > self.max_bytes:
                self._tracks.popitem(last=False)

    def __len__(self) -> int:
        return len(self._tracks)


class AudioLibrary:
    """Builds tracks at the output format: built-in sources, files as they are, files stretched to a tempo."""

    def __init__(self, rate: int, channels: int, *, declick: float, stretch_cache: StretchCache,
                 memory_bytes: int = 512 * 2**20, log: logging.Logger | None = None) -> None:
        self.rate, self.channels, self.declick = rate, channels, declick
        self.stretch_cache = stretch_cache
        self.cache = TrackCache(memory_bytes)
        self.log = log or logging.getLogger(__name__)

    def load(self, request: AudioRequest) -> Track:
        """The track ``request`` names; :class:`RequestError` when it cannot be played."""
        if request.kind == "stop":
            raise ValueError("'stop' names no track")
        key = self._key(request)
        track = self.cache.get(key)
        if track is None:
            track = self._build(request)
            self.cache.put(key, track)
        if track.source != request.text:  # same content, named differently
            track = Track(track.samples, track.rate, request.text, track.kind, track.tempo,
                          track.declick, track.info)
        return track

    def _key(self, request: AudioRequest) -> tuple:
        if request.path is None:
            return (request.kind, request.tempo)
        path = request.path
        try:
            st = path.stat()
            stamp: tuple = (st.st_size, st.st_mtime_ns)
        except OSError:
            stamp = ()
        return (request.kind, request.tempo, str(path.resolve()), *stamp)

    def _build(self, request: AudioRequest) -> Track:
        rate, ch = self.rate, self.channels
        if request.kind == "beat":
            assert request.tempo is not None
            return Track(synth.exercise_beat(request.tempo, rate, ch), rate, request.text, "beat",
                         tempo=request.tempo)
        if request.kind == "relaxing":
            return Track(synth.relaxing_pad(rate, ch), rate, request.text, "relaxing")
        path: Path = request.path  # type: ignore[assignment]
        decoded = decode(path, rate, ch)
        if request.kind == "file":
            return Track(decoded, rate, request.text, "file", declick=self.declick,
                         info={"file": str(path)})
        assert request.tempo is not None
        self.log.info(f"stretching {path} to {request.tempo:g} BPM (cached after the first time)")
        samples, own = stretched(path, decoded, rate, request.tempo, self.stretch_cache)
        if len(samples) == 0:
            raise RequestError(f"{path}: nothing left after stretching")
        return Track(samples, rate, request.text, "stretch", tempo=request.tempo, declick=self.declick,
                     info={"file": str(path), "file_tempo": round(own, 2),
                           "stretch": round(request.tempo / own, 4)})

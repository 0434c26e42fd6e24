"""What the video streamer shows: generated screens and video files (decoded with OpenCV).

A source gives the frame for a time since it started (``frame(elapsed)``), so the display
loop decides the pace and a slow machine skips frames instead of falling behind.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from audio_video_streamers.requests import RequestError, VideoRequest
from audio_video_streamers.video import render

DEFAULT_FILE_FPS = 30.0


class VideoSource(Protocol):
    request: str
    kind: str
    fps: float
    #: True: ``frame(elapsed)`` depends on ``elapsed`` and :meth:`picture_key` only (no state), so a
    #: frame nobody sees need not be drawn, and one whose key did not change need not be drawn again.
    pure: bool

    def picture_key(self, elapsed: float) -> object: ...

    def frame(self, elapsed: float) -> np.ndarray: ...

    def status(self, elapsed: float) -> dict[str, Any]: ...

    def close(self) -> None: ...


class ScreenSource:
    """A generated screen: ``splash``, ``relaxing`` or an activity placeholder at a tempo.

    An activity's tempo is the request's (``marching@125``) or else ``tempo()`` (the tempo the
    audio streamer plays, or a default), read on every frame so it follows the music.
    """

    pure = True

    def __init__(self, request: VideoRequest, size: tuple[int, int], fps: float, *,
                 tempo: Callable[[], float], title: str = "HRI Physio") -> None:
        self.request, self.kind, self.name, self.fps = request.text, request.kind, request.name, fps
        self._fixed_tempo, self._tempo, self.title = request.tempo, tempo, title
        self._canvas = render.blank(*size)

    @property
    def tempo(self) -> float | None:
        if self.kind != "activity":
            return None
        return self._fixed_tempo if self._fixed_tempo is not None else self._tempo()

    def picture_key(self, elapsed: float) -> object:
        """What the picture at ``elapsed`` is drawn from: the same key, the same picture."""
        return elapsed, self.tempo

    def frame(self, elapsed: float) -> np.ndarray:
        if self.kind == "splash":
            return render.draw_splash(self._canvas, elapsed, self.title)
        if self.kind == "relaxing":
            return render.draw_relaxing(self._canvas, elapsed)
        return render.draw_activity(self._canvas, self.name, elapsed, self.tempo or 120.0)

    def status(self, elapsed: float) -> dict[str, Any]:
        return {"tempo": self.tempo, "position": elapsed, "elapsed": elapsed}

    def close(self) -> None:
        pass


def fit_frame(frame: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``frame`` scaled to fit ``size`` (width, height), aspect kept, black bars around."""
    w, h = size
    fh, fw = frame.shape[:2]
    if (fw, fh) == (w, h):
        return frame
    scale = min(w / fw, h / fh)
    nw, nh = max(1, round(fw * scale)), max(1, round(fh * scale))
    scaled = cv2.resize(frame, (nw, nh), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    out = np.zeros((h, w, 3), dtype=np.uint8)
    y, x = (h - nh) // 2, (w - nw) // 2
    out[y:y + nh, x:x + nw] = scaled
    return out


class FileVideo:
    """A video file played at its own frame rate, looping; frames decoded in order, skipped when late."""

    kind = "file"
    pure = False  # frames are decoded in order: each one is read (its position is the status's)

    def __init__(self, request: VideoRequest, size: tuple[int, int],
                 capture: Callable[[str], Any] = cv2.VideoCapture) -> None:
        path: Path = request.path  # type: ignore[assignment]
        if path is None or not path.is_file():
            raise RequestError(f"no such video file: {path}")
        self.request, self.path, self.size = request.text, path, size
        self._capture = capture
        self.cap = capture(str(path))
        if not self.cap.isOpened():
            raise RequestError(f"cannot open video {path}")
        ok, first = self.cap.read()
        if not ok or first is None:
            self.cap.release()
            raise RequestError(f"no decodable frame in {path}")
        fps = float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 1.0 <= fps <= 240.0 else DEFAULT_FILE_FPS
        count = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self.frames: int | None = count if count > 0 else None  # learnt at the first wrap otherwise
        self._index = 0  # index of the frame in self._frame
        self._frame = fit_frame(self._to_bgr(first), size)
        self.loops = 0
        self.decode_failures = 0

    @staticmethod
    def _to_bgr(frame: np.ndarray) -> np.ndarray:
        if frame.ndim == 2:
            return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        if frame.shape[2] == 4:
            return cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
        return frame

    def _rewind(self) -> None:
        if not self.cap.set(cv2.CAP_PROP_POS_FRAMES, 0):
            self.cap.release()
            self.cap = self._capture(str(self.path))

    def _target(self, elapsed: float) -> tuple[int, int]:
        want = max(0, int(elapsed * self.fps + 1e-6))
        if self.frames:
            return divmod(want, self.frames)
        return 0, want

    def picture_key(self, elapsed: float) -> object:
        return self._target(elapsed)

    def frame(self, elapsed: float) -> np.ndarray:
        loops, index = self._target(elapsed)
        if loops != self.loops or index < self._index:  # wrapped: start again from the first frame
            self._rewind()
            self._index = -1
        self.loops = loops
        while self._index < index:
            if self._index < index - 1:
                ok = bool(self.cap.grab())  # skipped: not decoded
            else:
                ok, decoded = self.cap.read()
                ok = bool(ok) and decoded is not None
                if ok:
                    self._frame = fit_frame(self._to_bgr(decoded), self.size)
            if ok:
                self._index += 1
                continue
            if self._index < 0:  # nothing decodes even after a rewind: keep showing the last frame
                self.decode_failures += 1
                self._index = index
                break
            # Fewer frames than announced (or no count): now the length is known; wrap.
            self.frames = self._index + 1
            self._rewind()
            self._index = -1
            self.loops, index = self._target(elapsed)
        return self._frame

    def status(self, elapsed: float) -> dict[str, Any]:
        duration = self.frames / self.fps if self.frames else None
        return {"position": self._index / self.fps, "elapsed": elapsed, "loops": self.loops,
                "duration": duration, "frame": self._index, "frames": self.frames, "file": str(self.path)}

    def close(self) -> None:
        self.cap.release()


def open_source(request: VideoRequest, size: tuple[int, int], fps: float, *,
                tempo: Callable[[], float], title: str = "HRI Physio") -> VideoSource:
    """The source ``request`` names; :class:`RequestError` when it cannot be shown."""
    if request.kind == "file":
        return FileVideo(request, size)
    return ScreenSource(request, size, fps, tempo=tempo, title=title)

"""What a media request names, parsed in one place for each streamer.

Audio (``/audio_streamer/audio_name``):

- ``beat:<bpm>``: the built-in exercise beat at that tempo;
- ``relaxing``: the built-in calm pad;
- ``file:<path>@<bpm>``: a user track time-stretched to ``<bpm>`` (its own tempo is measured);
- ``<path>`` or ``file:<path>``: a user track as it is (wav, flac, ogg);
- ``stop``: fade out to silence.

Video (``/video_streamer/video_name``):

- ``splash``, ``relaxing``: built-in screens;
- ``marching``, ``step_up``, ``lateral``, ``arms_forward`` (optionally ``@<bpm>``): an activity
  placeholder animated at that tempo (default: the tempo the audio streamer plays);
- ``<path>`` or ``file:<path>``: a video file (anything OpenCV decodes).

Tempos are accepted in [40, 240] BPM. Relative paths are taken from a media directory.
"""

from __future__ import annotations

import queue
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, TypeVar

from pydantic import AfterValidator

T = TypeVar("T")

TEMPO_MIN = 40.0
TEMPO_MAX = 240.0
ACTIVITIES = ("marching", "step_up", "lateral", "arms_forward")
VIDEO_SCREENS = ("splash", "relaxing")

AudioKind = Literal["beat", "relaxing", "file", "stretch", "stop"]
VideoKind = Literal["splash", "relaxing", "activity", "file"]

_SCHEME = re.compile(r"^(?P<scheme>[A-Za-z][A-Za-z0-9_+-]*):(?P<rest>.*)$", re.DOTALL)
# ``<path>@<tempo>``: the part after the last '@' is a tempo unless it looks like a path or a file
# name (``me@lab/x.wav``, ``x@2x.wav`` are paths).
_STRETCH = re.compile(r"^(?P<path>.+)@(?P<bpm>[^/\\]*)$", re.DOTALL)
_FILE_NAME = re.compile(r"^.*\.[A-Za-z][A-Za-z0-9]*$")
_ACTIVITY = re.compile(r"^(?P<name>[a-z_]+)(?:@(?P<bpm>.*))?$")


class RequestError(ValueError):
    """A request that cannot be played: one line saying why."""


def unexpected_failure(exc: Exception) -> RequestError:
    """Any exception met while opening a user's file, as a one-line :class:`RequestError`.

    Decoders fail on odd files in many ways; a streamer reports them and goes on playing.
    """
    first_line = (str(exc).strip().splitlines() or [""])[0]
    return RequestError(f"{type(exc).__name__}: {first_line}" if first_line else type(exc).__name__)


@dataclass(frozen=True)
class AudioRequest:
    text: str
    kind: AudioKind
    tempo: float | None = None
    path: Path | None = None


@dataclass(frozen=True)
class VideoRequest:
    text: str
    kind: VideoKind
    name: str = ""
    tempo: float | None = None
    path: Path | None = None


def parse_tempo(text: str, what: str) -> float:
    """A tempo in BPM within [40, 240]; :class:`RequestError` otherwise."""
    try:
        bpm = float(text)
    except ValueError:
        raise RequestError(f"{what}: tempo {text!r} is not a number") from None
    if not TEMPO_MIN <= bpm <= TEMPO_MAX:  # also refuses nan
        raise RequestError(f"{what}: tempo {bpm:g} BPM is outside {TEMPO_MIN:g}-{TEMPO_MAX:g} BPM")
    return bpm


def existing_media_dir(value: str) -> str:
    """A ``media_dir`` option: empty (the working directory) or a directory that exists."""
    if value and not Path(value).expanduser().is_dir():
        what = "is not a directory" if Path(value).expanduser().exists() else "does not exist"
        raise ValueError(f"media directory {value} {what}")
    return value


#: The ``media_dir`` option of the streamers: an existing directory, or empty (the working directory).
MediaDir = Annotated[str, AfterValidator(existing_media_dir)]


def _media_path(text: str, media_dir: Path | None, what: str) -> Path:
    if not text.strip():
        raise RequestError(f"{what}: empty file name")
    path = Path(text).expanduser()
    if not path.is_absolute() and media_dir is not None:
        path = media_dir / path
    return path


def _split_scheme(text: str) -> tuple[str | None, str]:
    match = _SCHEME.match(text)
    # One letter before ':' is a Windows drive, not a scheme.
    if match is None or len(match["scheme"]) == 1:
        return None, text
    return match["scheme"].lower(), match["rest"]


def parse_audio_request(text: str, media_dir: Path | None = None) -> AudioRequest:
    """The audio source ``text`` names (see the module docstring)."""
    request = text.strip()
    if not request:
        raise RequestError("empty audio request")
    if request.lower() == "stop":
        return AudioRequest(request, "stop")
    if request.lower() == "relaxing":
        return AudioRequest(request, "relaxing")
    scheme, rest = _split_scheme(request)
    if scheme == "beat":
        return AudioRequest(request, "beat", tempo=parse_tempo(rest.strip(), request))
    if scheme == "file":
        stretch = _STRETCH.match(rest)
        if stretch is not None and not _FILE_NAME.match(stretch["bpm"]):
            tempo = parse_tempo(stretch["bpm"], request)
            return AudioRequest(request, "stretch", tempo=tempo,
                                path=_media_path(stretch["path"], media_dir, request))
        return AudioRequest(request, "file", path=_media_path(rest, media_dir, request))
    if scheme is not None:
        raise RequestError(f"unknown audio source {scheme + ':'!r} in {request!r} "
                           "(known: beat:<bpm>, relaxing, file:<path>[@<bpm>], stop, or a file path)")
    return AudioRequest(request, "file", path=_media_path(request, media_dir, request))


def parse_video_request(text: str, media_dir: Path | None = None) -> VideoRequest:
    """The video source ``text`` names (see the module docstring)."""
    request = text.strip()
    if not request:
        raise RequestError("empty video request")
    if request.lower() in VIDEO_SCREENS:
        name = request.lower()
        return VideoRequest(request, "splash" if name == "splash" else "relaxing", name=name)
    activity = _ACTIVITY.match(request.lower())
    if activity is not None and activity["name"] in ACTIVITIES:
        bpm = activity["bpm"]
        tempo = None if bpm is None else parse_tempo(bpm, request)
        return VideoRequest(request, "activity", name=activity["name"], tempo=tempo)
    scheme, rest = _split_scheme(request)
    if scheme == "file":
        return VideoRequest(request, "file", path=_media_path(rest, media_dir, request))
    if scheme is not None:
        raise RequestError(f"unknown video source {scheme + ':'!r} in {request!r} (known: "
                           f"{', '.join(VIDEO_SCREENS + ACTIVITIES)}, file:<path>, or a file path)")
    return VideoRequest(request, "file", path=_media_path(request, media_dir, request))


def take_queued(q: queue.Queue[T]) -> list[T]:
    """Everything waiting in ``q`` now, oldest first, without blocking (a player's requests or commands)."""
    out: list[T] = []
    while True:
        try:
            out.append(q.get_nowait())
        except queue.Empty:
            return out

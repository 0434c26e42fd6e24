"""Parsing of audio and video requests (pure logic)."""

from __future__ import annotations

from pathlib import Path

import pytest

from audio_video_streamers.requests import (
    RequestError,
    parse_audio_request,
    parse_tempo,
    parse_video_request,
)


@pytest.mark.parametrize(
    ("text", "kind", "tempo", "path"),
    [
        ("beat:120", "beat", 120.0, None),
        (" beat:123.5 ", "beat", 123.5, None),
        ("beat:40", "beat", 40.0, None),
        ("beat:240", "beat", 240.0, None),
        ("relaxing", "relaxing", None, None),
        ("STOP", "stop", None, None),
        ("music/exercise_125.wav", "file", None, "media/music/exercise_125.wav"),
        ("file:song.flac", "file", None, "media/song.flac"),
        ("file:song.ogg@130", "stretch", 130.0, "media/song.ogg"),
        ("file:/abs/me@lab/song.wav", "file", None, "/abs/me@lab/song.wav"),
        ("file:/abs/x@2x.wav", "file", None, "/abs/x@2x.wav"),
        ("/abs/track.wav", "file", None, "/abs/track.wav"),
    ],
)
def test_audio_requests(text: str, kind: str, tempo: float | None, path: str | None) -> None:
    request = parse_audio_request(text, Path("media"))
    assert request.kind == kind
    assert request.tempo == tempo
    assert request.text == text.strip()
    assert (str(request.path) if request.path else None) == path


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("beat:0", "outside 40-240"),
        ("beat:39.9", "outside 40-240"),
        ("beat:241", "outside 40-240"),
        ("beat:nan", "outside 40-240"),
        ("beat:fast", "not a number"),
        ("beat:", "not a number"),
        ("file:song.wav@300", "outside 40-240"),
        ("file:song.wav@quick", "not a number"),
        ("file:", "empty file name"),
        ("spotify:track:123", "unknown audio source 'spotify:'"),
        ("", "empty audio request"),
        ("   ", "empty audio request"),
    ],
)
def test_bad_audio_requests_say_why(text: str, problem: str) -> None:
    with pytest.raises(RequestError, match=problem):
        parse_audio_request(text)


@pytest.mark.parametrize(
    ("text", "kind", "name", "tempo"),
    [
        ("splash", "splash", "splash", None),
        ("Relaxing", "relaxing", "relaxing", None),
        ("marching", "activity", "marching", None),
        ("step_up@125", "activity", "step_up", 125.0),
        ("lateral", "activity", "lateral", None),
        ("arms_forward@110.5", "activity", "arms_forward", 110.5),
        ("video/marching.mp4", "file", "", None),
        ("file:clip.avi", "file", "", None),
    ],
)
def test_video_requests(text: str, kind: str, name: str, tempo: float | None) -> None:
    request = parse_video_request(text)
    assert (request.kind, request.name, request.tempo) == (kind, name, tempo)
    if kind == "file":
        assert request.path is not None and request.path.name in text


@pytest.mark.parametrize(
    ("text", "problem"),
    [("marching@0", "outside 40-240"), ("lateral@x", "not a number"), ("youtube:abc", "unknown video source"),
     ("", "empty video request")],
)
def test_bad_video_requests_say_why(text: str, problem: str) -> None:
    with pytest.raises(RequestError, match=problem):
        parse_video_request(text)


def test_tempo_bounds_are_inclusive() -> None:
    assert parse_tempo("40", "x") == 40.0
    assert parse_tempo("240.0", "x") == 240.0
    with pytest.raises(RequestError):
        parse_tempo("inf", "x")

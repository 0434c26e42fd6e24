"""A user track at a requested tempo: measured, time-stretched with librosa, cached on disk.

The only media test module that runs librosa's time stretch. Its first call JIT-compiles for
10-50 s, so the module counts as an integration test (left out of scripts/test --fast).
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from audio_video_streamers.audio import stretch as stretch_module
from audio_video_streamers.audio.library import AudioLibrary
from audio_video_streamers.audio.player import AudioPlayer
from audio_video_streamers.audio.sinks import NullSink, RecordingSink
from audio_video_streamers.audio.stretch import StretchCache, nearest_octave
from audio_video_streamers.status import MediaStatus, State
from helpers.media import VirtualClock, capture_logger, measure_tempo, write_drum_clip

RATE = 44100
SOURCE_BPM = 100.0


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_drum_clip(tmp_path_factory.mktemp("clip") / "clip.wav", SOURCE_BPM, beats=16)


def play(request: str, media_dir: Path, cache_dir: Path, wav: Path, seconds: float) -> list[MediaStatus]:
    clock = VirtualClock()
    log, _ = capture_logger(wav.stem)
    sink = RecordingSink(NullSink(RATE, 2, clock, sleep=clock.sleep), wav, "float")
    library = AudioLibrary(RATE, 2, declick=0.02, stretch_cache=StretchCache(cache_dir, log), log=log)
    statuses: list[MediaStatus] = []
    player = AudioPlayer(library, sink, fade=0.0, clock=clock, on_status=statuses.append, media_dir=media_dir,
                         log=log)
    player.request(request)
    player.prepare_pending()
    stop = threading.Event()
    end = clock() + seconds
    while clock() < end:
        player.step(stop)
    statuses.append(player.status())
    player.close()
    return statuses


def test_a_stretched_track_hits_the_requested_tempo_and_is_cached(clip: Path, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    cache = tmp_path / "cache"
    statuses = play(f"file:{clip.name}@120", clip.parent, cache, tmp_path / "stretched.wav", 20.0)
    final = statuses[-1]
    assert (final.state, final.kind, final.tempo) == (State.PLAYING, "stretch", 120.0)
    assert final.extra["file_tempo"] == pytest.approx(SOURCE_BPM, abs=0.5)
    assert final.extra["stretch"] == pytest.approx(1.2, abs=0.006)
    assert final.duration == pytest.approx(16 * 60 / 120, abs=0.01)  # the whole clip, 16 beats at 120
    assert final.loops >= 2

    measured, residual = measure_tempo(tmp_path / "stretched.wav")
    assert abs(measured - 120.0) <= 0.5, f"stretched track measured {measured:.3f} BPM"
    assert residual < 0.01

    # The pitch is kept: the melody's notes are where they were (a resampling would raise them by x1.2).
    y, _ = sf.read(str(tmp_path / "stretched.wav"), always_2d=True)
    spectrum = np.abs(np.fft.rfft(y[: 4 * RATE, 0]))
    freqs = np.fft.rfftfreq(4 * RATE, 1 / RATE)
    band = (freqs > 300) & (freqs < 700)
    assert 320 < freqs[band][np.argmax(spectrum[band])] < 500

    # Cached on disk: a new process (new cache object, no memory cache) neither measures nor stretches.
    assert len(list(cache.glob("*.npy"))) == 1 and len(list(cache.glob("*.json"))) == 1

    def must_not_run(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the cache was not used")

    monkeypatch.setattr(stretch_module, "time_stretch", must_not_run)
    monkeypatch.setattr(stretch_module, "measure_tempo", must_not_run)
    again = play(f"file:{clip.name}@120", clip.parent, cache, tmp_path / "again.wav", 1.0)[-1]
    assert (again.state, again.kind) == (State.PLAYING, "stretch")
    assert again.extra["stretch"] == final.extra["stretch"]
    first, second = (sf.read(str(tmp_path / name))[0][:RATE] for name in ("stretched.wav", "again.wav"))
    assert np.allclose(first, second, atol=1e-6)


def test_a_track_without_beats_cannot_be_stretched_and_says_so(tmp_path: Path) -> None:
    sf.write(str(tmp_path / "hum.wav"), 0.2 * np.sin(2 * np.pi * 220 * np.arange(3 * RATE) / RATE), RATE)
    statuses = play("file:hum.wav@120", tmp_path, tmp_path / "cache", tmp_path / "out.wav", 0.5)
    errors = [s for s in statuses if s.state == State.ERROR]
    assert len(errors) == 1 and errors[0].request == "file:hum.wav@120" and "beats" in (errors[0].error or "")
    assert statuses[-1].state == State.STOPPED  # nothing was playing, nothing plays


@pytest.mark.parametrize(("measured", "target", "own"), [
    (100.0, 120.0, 100.0), (65.0, 130.0, 130.0), (240.0, 110.0, 120.0), (90.0, 240.0, 180.0),
])
def test_the_track_tempo_is_taken_in_the_octave_nearest_the_target(measured: float, target: float,
                                                                     own: float) -> None:
    assert nearest_octave(measured, target) == own
    assert 2**-0.5 <= target / own <= 2**0.5

"""The audio streamer's logic on a virtual clock: tempo, fades, loops, bad requests, bursts, sinks.

Every recording is what the sink was handed (RecordingSink), analysed as a WAV file.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile as sf

from audio_video_streamers.audio.library import AudioLibrary
from audio_video_streamers.audio.mixer import Mixer
from audio_video_streamers.audio.player import AudioPlayer
from audio_video_streamers.audio.sinks import NullSink, RecordingSink
from audio_video_streamers.audio.stretch import StretchCache
from audio_video_streamers.audio.track import Track
from audio_video_streamers.status import MediaStatus, State
from helpers.media import VirtualClock, capture_logger, measure_tempo, write_tone

RATE = 44100


class Rig:
    """A player on a virtual clock, recording to a WAV file; requests prepared synchronously."""

    def __init__(self, tmp: Path, *, fade: float = 1.0, declick: float = 0.02, name: str = "out.wav") -> None:
        self.clock = VirtualClock()
        self.log, self.logs = capture_logger(name)
        self.wav = tmp / name
        self.sink = RecordingSink(NullSink(RATE, 2, self.clock, sleep=self.clock.sleep), self.wav, "float")
        library = AudioLibrary(RATE, 2, declick=declick, stretch_cache=StretchCache(None), log=self.log)
        self.statuses: list[MediaStatus] = []
        self.player = AudioPlayer(library, self.sink, fade=fade, block=1024, clock=self.clock,
                                  on_status=self.statuses.append, media_dir=tmp, log=self.log)
        self.stop = threading.Event()

    def request(self, *texts: str) -> None:
        for text in texts:
            self.player.request(text)
        self.player.prepare_pending()

    def play(self, seconds: float) -> None:
        end = self.clock() + seconds
        while self.clock() < end:
            assert self.player.step(self.stop)

    @property
    def frames(self) -> int:
        return self.sink.frames_recorded

    def recording(self) -> np.ndarray:
        self.player.close()
        y, sr = sf.read(str(self.wav), always_2d=True, dtype="float32")
        assert sr == RATE
        return y

    def errors(self) -> list[MediaStatus]:
        return [s for s in self.statuses if s.state == State.ERROR]


# ----------------------------------------------------------------------------------------------
# Tempo of the built-in beat, measured on the recording
@pytest.mark.parametrize("bpm", [40.0, 110.0, 123.5, 135.0, 240.0])
def test_beat_plays_at_the_requested_tempo(tmp_path: Path, bpm: float) -> None:
    rig = Rig(tmp_path, fade=0.0)
    rig.request(f"beat:{bpm:g}")
    rig.play(40.0 if bpm < 60 else 20.0)  # several loops at the faster tempos
    y = rig.recording()
    sf.write(str(tmp_path / "beat.wav"), y, RATE)
    measured, residual = measure_tempo(tmp_path / "beat.wav")
    assert abs(measured - bpm) <= 0.5, f"beat:{bpm:g} measured {measured:.3f} BPM"
    assert residual < 0.002, f"onsets off a steady grid by {residual * 1000:.2f} ms RMS"
    status = rig.player.status()
    assert (status.source, status.kind, status.tempo, status.state) == (f"beat:{bpm:g}", "beat", bpm,
                                                                         State.PLAYING)


def test_beat_holds_its_tempo_across_a_swap_from_another_tempo(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    rig.request("beat:110")
    rig.play(5.0)
    rig.request("beat:130")
    swap = rig.frames
    rig.play(20.0)
    y = rig.recording()
    sf.write(str(tmp_path / "after.wav"), y[swap + 2 * RATE:], RATE)  # after the 1 s fade
    measured, _ = measure_tempo(tmp_path / "after.wav")
    assert abs(measured - 130.0) <= 0.5


# ----------------------------------------------------------------------------------------------
# Fades and loops
def _amplitude(y: np.ndarray, freq: float, start: int, length: int = 2205) -> float:
    """Amplitude of the ``freq`` sine in ``length`` frames from ``start`` (least squares)."""
    seg = y[start:start + length, 0].astype(float)
    t = np.arange(len(seg)) / RATE
    basis = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, seg, rcond=None)
    return float(np.hypot(*coef))


def _max_step_of_sines(freqs: tuple[float, ...], amp: float, fade: float) -> float:
    """The largest sample-to-sample change a fade between these sines can make (no click)."""
    slope = 2 * np.pi * max(freqs) * amp * np.sqrt(2) / RATE
    gain_slope = (np.pi / 2) / (fade * RATE) * amp * 2 if fade else 0.0
    return 1.05 * (slope + gain_slope)


def test_a_swap_cross_fades_without_a_step(tmp_path: Path) -> None:
    write_tone(tmp_path / "a.wav", 440.0, 1.2345)  # lengths of no whole number of periods
    write_tone(tmp_path / "b.wav", 660.0, 2.3456)  # no loop point inside the fade
    rig = Rig(tmp_path, fade=1.0)
    rig.request("a.wav")
    rig.play(3.0)
    rig.request("b.wav")
    swap = rig.frames
    rig.player.step(rig.stop)  # the request takes effect at the next block
    fading = rig.player.status()
    rig.play(3.0)
    y = rig.recording()

    assert fading.state == State.FADING and fading.source == "b.wav"
    assert fading.extra["fading_out"] == ["a.wav"]
    assert rig.player.status().state == State.PLAYING
    # The envelope: A falls and B rises over the 1 s fade, at constant power (equal-power fade).
    points = np.linspace(0, RATE - 2205, 9).astype(int)
    a = np.array([_amplitude(y, 440.0, swap + p) for p in points])
    b = np.array([_amplitude(y, 660.0, swap + p) for p in points])
    assert a[0] > 0.48 and b[0] < 0.03 and a[-1] < 0.03 and b[-1] > 0.48
    assert np.all(np.diff(a) < 0.005) and np.all(np.diff(b) > -0.005), (a, b)
    assert np.allclose(a**2 + b**2, 0.25, atol=0.02)
    mid = _amplitude(y, 440.0, swap + RATE // 2 - 1102)
    assert mid == pytest.approx(0.5 * np.cos(np.pi / 4), abs=0.03)
    # No click anywhere: at the swap, at every loop point of both files.
    steps = np.abs(np.diff(y[:, 0]))
    assert steps.max() <= _max_step_of_sines((440.0, 660.0), 0.5, 1.0), steps.argmax()


def test_a_loop_point_does_not_click_and_without_declick_it_would(tmp_path: Path) -> None:
    write_tone(tmp_path / "tone.wav", 440.0, 141.25 / 440.0)  # ends at a crest: a raw loop jumps
    bound = _max_step_of_sines((440.0,), 0.5, 0.0) + 0.5 * np.pi / (0.02 * RATE)
    rig = Rig(tmp_path, fade=0.0, declick=0.02)
    rig.request("tone.wav")
    rig.play(3.0)
    status = rig.player.status()
    y = rig.recording()
    assert status.loops >= 9
    assert np.abs(np.diff(y[:, 0])).max() <= bound

    raw = Rig(tmp_path, fade=0.0, declick=0.0, name="raw.wav")
    raw.request("tone.wav")
    raw.play(3.0)
    assert np.abs(np.diff(raw.recording()[:, 0])).max() > 5 * bound  # the click the declick removes


def test_track_read_wraps_and_declicks_only_at_the_loop_point() -> None:
    samples = np.ones((1000, 1), dtype=np.float32)
    track = Track(samples, 1000, "x", "file", declick=0.01)  # 10 frames of fade
    first = track.read(0, 1000)
    assert np.all(first[:990] == 1.0)  # the first pass starts at full level
    assert first[-1, 0] < 0.05 and np.all(np.diff(first[990:, 0]) < 0)
    second = track.read(1000, 20)
    assert second[0, 0] < 0.05 and np.all(np.diff(second[:10, 0]) > 0) and np.all(second[10:] == 1.0)
    assert np.array_equal(track.read(2500, 7), track.read(500, 7))


@pytest.mark.parametrize(("start", "count"), [(0, 7), (45, 10), (48, 130), (100, 1), (3, 50), (149, 2)])
def test_track_read_matches_the_sample_by_sample_definition(start: int, count: int) -> None:
    rng = np.random.default_rng(start)
    samples = rng.uniform(-1, 1, (50, 2)).astype(np.float32)
    track = Track(samples, 1000, "x", "file", declick=0.005)  # 5 frames of fade each side
    fade_in = 0.5 - 0.5 * np.cos(np.pi * (np.arange(5) + 0.5) / 5)
    expected = []
    for index in range(start, start + count):
        p = index % 50
        gain = 1.0
        if p >= 45:
            gain *= fade_in[49 - p]
        if p < 5 and index >= 50:
            gain *= fade_in[p]
        expected.append(samples[p] * gain)
    assert np.allclose(track.read(start, count), np.array(expected), atol=1e-6)


def test_stop_fades_to_silence(tmp_path: Path) -> None:
    rig = Rig(tmp_path, fade=0.5)
    rig.request("relaxing")
    rig.play(2.0)
    rig.request("stop")
    at = rig.frames
    rig.play(2.0)
    y = rig.recording()
    assert rig.player.status().state == State.STOPPED
    assert np.abs(y[at + int(0.6 * RATE):]).max() == 0.0
    assert np.abs(y[at:at + 1024]).max() > 0.0  # it fades, it does not cut


def test_mixer_reverses_a_fade_smoothly_when_a_request_arrives_mid_fade() -> None:
    a = Track(np.full((4410, 1), 0.5, dtype=np.float32), 44100, "a", "file")
    b = Track(np.full((4410, 1), -0.5, dtype=np.float32), 44100, "b", "file")
    mixer = Mixer(44100, 1, fade=0.1)
    mixer.start(a)
    out = [mixer.render(441) for _ in range(20)]
    mixer.start(b)
    out += [mixer.render(441) for _ in range(5)]
    mixer.start(a)  # back to a while b is fading in
    out += [mixer.render(441) for _ in range(30)]
    y = np.concatenate(out)[:, 0]
    assert np.abs(np.diff(y)).max() < 0.02  # levels move gradually: no jump
    assert y[-1] == pytest.approx(0.5) and mixer.state == State.PLAYING
    assert len(mixer.voices) == 1


# ----------------------------------------------------------------------------------------------
# Bad requests and bursts
def test_bad_requests_report_errors_and_the_track_goes_on(tmp_path: Path) -> None:
    (tmp_path / "broken.wav").write_text("not audio at all")
    (tmp_path / "empty.wav").write_bytes(b"")
    rig = Rig(tmp_path, fade=0.0)
    rig.request("beat:120")
    rig.play(4.0)
    bad = ["beat:0", "missing.wav", "broken.wav", "empty.wav", "midi:song", "file:song.wav@300", "beat:abc"]
    for text in bad:
        rig.request(text)
        rig.play(1.0)
    rig.play(4.0)
    y = rig.recording()

    errors = rig.errors()
    assert [e.request for e in errors] == bad
    assert all(e.error and e.source == "beat:120" for e in errors)
    assert len([m for m in rig.logs.messages(logging.ERROR)]) == len(bad)  # one line each
    status = rig.player.status()
    assert (status.source, status.state) == ("beat:120", State.PLAYING)
    assert status.requests.failed == len(bad) and status.requests.started == 1
    sf.write(str(tmp_path / "through.wav"), y, RATE)
    measured, residual = measure_tempo(tmp_path / "through.wav")
    assert abs(measured - 120.0) <= 0.5 and residual < 0.002  # uninterrupted beat


def test_preloaded_tracks_are_prepared_once_and_a_request_for_one_starts_at_the_next_block(
        tmp_path: Path) -> None:
    rig = Rig(tmp_path, fade=0.0)
    library = rig.player.library
    built: list[str] = []  # tracks built (a missing file fails in the build: not one)
    build = library._build

    def counted(request: Any) -> Any:
        track = build(request)
        built.append(request.text)
        return track

    library._build = counted  # type: ignore[method-assign]
    assert rig.player.preload(["beat:120", "relaxing", "missing.wav", "beat:0"]) == 2
    assert built == ["beat:120", "relaxing"]
    warnings = rig.logs.messages(logging.WARNING)
    assert len(warnings) == 2 and "missing.wav" in warnings[0] and "beat:0" in warnings[1]
    assert rig.player.status().requests.failed == 0  # nobody asked for them yet: no request failed
    rig.player.request("beat:120")
    rig.player.prepare_pending()
    assert built == ["beat:120", "relaxing"]  # from the library, not built again
    rig.play(0.05)
    assert (rig.player.status().source, rig.player.status().state) == ("beat:120", State.PLAYING)


def test_a_burst_plays_the_newest_playable_request_and_accounts_for_all(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    burst = [f"beat:{bpm}" for bpm in range(100, 140, 4)] + ["beat:999", "missing.wav"]
    rig.request(*burst)
    rig.play(1.5)
    status = rig.player.status()
    assert status.source == "beat:136"
    counts = status.requests
    assert counts.received == len(burst)
    assert (counts.started, counts.failed, counts.superseded) == (1, 2, 9)
    assert status.pending == ()


def test_requests_from_many_threads_are_all_accounted_for(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    rig.player.start_loader()

    def send(k: int) -> None:
        for i in range(25):
            rig.player.request(f"beat:{100 + (k * 25 + i) % 100}")

    threads = [threading.Thread(target=send, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for _ in range(2000):
        rig.player.step(rig.stop)
        counts = rig.player.status().requests
        if counts.started + counts.failed + counts.superseded == 100:
            break
    assert counts.received == 100 and counts.started + counts.superseded == 100 and counts.failed == 0
    assert rig.player.status().pending == ()
    rig.player.close()


def test_the_loader_waits_for_requests_and_close_ends_it_at_once(tmp_path: Path) -> None:
    """The loader thread sleeps until a request comes (no polling); close() wakes it, and the wake-up
    is no request: nothing fails, nothing is left pending."""
    rig = Rig(tmp_path)
    rig.player.start_loader()
    loader = rig.player._loader
    assert loader is not None
    rig.player.request("beat:120")
    for _ in range(2000):
        rig.player.step(rig.stop)
        if rig.player.status().requests.started == 1:
            break
    assert rig.player.status().requests.started == 1
    rig.player.close()
    loader.join(2.0)
    assert not loader.is_alive()
    counts = rig.player.status().requests
    assert (counts.received, counts.failed) == (1, 0) and rig.errors() == []


def test_status_is_published_on_every_change(tmp_path: Path) -> None:
    rig = Rig(tmp_path, fade=0.5)
    rig.player._emit_if_changed()
    rig.request("beat:120")
    rig.play(1.0)
    rig.request("relaxing")
    rig.play(1.0)
    states = [(s.state, s.source) for s in rig.statuses]
    assert (State.STOPPED, None) in states
    assert states.index((State.FADING, "beat:120")) < states.index((State.PLAYING, "beat:120"))
    assert states.index((State.PLAYING, "beat:120")) < states.index((State.FADING, "relaxing"))
    assert states[-1] == (State.PLAYING, "relaxing")
    data = rig.statuses[-1].as_dict()
    assert set(data) >= {"t", "state", "source", "kind", "position", "elapsed", "loops", "duration",
                         "requests", "pending", "sink", "fade"}
    assert "tempo" not in data  # the pad has none
    assert data["requests"] == {"received": 2, "started": 2, "failed": 0, "superseded": 0}

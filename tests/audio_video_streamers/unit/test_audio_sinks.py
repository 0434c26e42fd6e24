"""The audio sinks at their boundary: null sink pacing on a clock, the sound device (faked), the recorder."""

from __future__ import annotations

import logging
import threading
import types
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from audio_video_streamers.audio.sinks import (
    DeviceSink,
    NullSink,
    RecordingSink,
    SinkError,
    load_sounddevice,
    open_sink,
)
from audio_video_streamers.pacing import ClockTicks
from helpers.media import VirtualClock, capture_logger

RATE = 44100
BLOCK = np.zeros((1024, 2), dtype=np.float32)


class SimClockSteps(ClockTicks):
    """Sim time in 0.125-s steps: each wait for a tick is one /clock message arriving."""

    def __init__(self) -> None:
        super().__init__()
        self.t = 100.0
        self.waits = 0

    def __call__(self) -> float:
        return self.t

    def wait(self, seconds: float) -> bool:
        self.waits += 1
        self.t += 0.125
        self.tick()
        return True


def test_on_a_stepping_clock_the_null_sink_waits_for_each_step_not_in_short_polls() -> None:
    clock = SimClockSteps()
    polls: list[float] = []
    sink = NullSink(RATE, 2, clock, lead=0.0, ticks=clock,
                    sleep=lambda seconds, stop: polls.append(seconds) or False)
    stop = threading.Event()
    for _ in range(43):  # 43 blocks of 1024 frames: 0.9985 s of audio
        assert sink.write(BLOCK, stop)
    assert polls == []  # never a wall-time poll on a clock that moves only in steps
    assert clock.waits == 8 == clock.count  # one wait per step: 0.9985 s is due within 8 steps of 0.125 s
    assert sink.frames_played == 43 * 1024


def test_null_sink_consumes_samples_at_the_clock_rate() -> None:
    clock = VirtualClock(50.0)
    sink = NullSink(RATE, 2, clock, lead=0.1, sleep=clock.sleep)
    stop = threading.Event()
    start = clock()
    for _ in range(431):  # 10.0 s of audio
        assert sink.write(BLOCK, stop)
    played = 431 * 1024 / RATE
    # The last block is handed out ``lead`` s before it is due, once the one before has played.
    assert clock() - start == pytest.approx(played - 1024 / RATE - 0.1, abs=0.021)
    assert sink.frames_played == 431 * 1024 and sink.resyncs == 0


def test_null_sink_follows_a_faster_clock() -> None:
    """Sim time at 5x: the sink consumes 5 s of audio per wall second, i.e. per 5 s of its clock."""
    wall = VirtualClock(0.0)
    sim = lambda: 100.0 + 5 * wall()  # noqa: E731
    sink = NullSink(RATE, 2, sim, lead=0.1, sleep=wall.sleep)
    stop = threading.Event()
    for _ in range(431):
        sink.write(BLOCK, stop)
    assert sim() - 100.0 == pytest.approx(10.0 - 1024 / RATE - 0.1, abs=0.11)
    assert wall() == pytest.approx((sim() - 100.0) / 5, rel=1e-6)


def test_null_sink_waits_while_the_clock_stands_still_and_a_stop_ends_the_wait() -> None:
    """use_sim_time before the first /clock: the clock reads 0 and does not move."""
    stop = threading.Event()
    naps: list[float] = []

    def nap(seconds: float, stop_event: threading.Event) -> bool:
        naps.append(seconds)
        if len(naps) == 50:  # it is still waiting after 50 naps: stop it
            stop_event.set()
        return stop_event.is_set()

    sink = NullSink(RATE, 2, lambda: 0.0, lead=0.0, sleep=nap)
    assert sink.write(BLOCK, stop)  # the first block is due at once
    assert not sink.write(BLOCK, stop)  # the second waits for time that never comes, until the stop
    assert len(naps) == 50 and all(0 < s <= 0.02 for s in naps)
    assert sink.frames_played == 1024


def test_null_sink_restarts_when_the_clock_jumps() -> None:
    clock = VirtualClock(0.0)
    sink = NullSink(RATE, 2, clock, lead=0.1, sleep=clock.sleep)
    stop = threading.Event()
    for _ in range(10):
        sink.write(BLOCK, stop)
    clock.t = 1000.0  # /clock arrives: far ahead
    sink.write(BLOCK, stop)
    assert sink.resyncs == 1 and clock() == pytest.approx(1000.0)
    clock.t = 10.0  # a replay restarted: back in time
    for _ in range(5):
        sink.write(BLOCK, stop)
    assert clock() < 10.2  # consumed at the clock's rate from the new time, no catch-up wait


# ----------------------------------------------------------------------------------------------
# The sound device, through a fake sounddevice module
class FakeStream:
    def __init__(self, **kwargs: object) -> None:
        self.kwargs = kwargs
        self.blocks: list[np.ndarray] = []
        self.started = self.stopped = self.closed = False

    def start(self) -> None:
        self.started = True

    def write(self, block: np.ndarray) -> bool:
        self.blocks.append(block.copy())
        return len(self.blocks) == 2  # one underflow reported

    def stop(self) -> None:
        self.stopped = True

    def close(self) -> None:
        self.closed = True


def fake_sounddevice(has_output: bool = True) -> types.ModuleType:
    sd = types.ModuleType("sounddevice")

    class PortAudioError(Exception):
        pass

    streams: list[FakeStream] = []

    def query_devices(device: object = None, kind: str | None = None) -> dict:
        if not has_output:
            raise PortAudioError("Error querying device -1")
        return {"name": "Fake Speakers", "max_output_channels": 2}

    def check_output_settings(**kwargs: object) -> None:
        if kwargs.get("channels", 0) > 2:
            raise PortAudioError("Invalid number of channels")

    def output_stream(**kwargs: object) -> FakeStream:
        streams.append(FakeStream(**kwargs))
        return streams[-1]

    sd.PortAudioError = PortAudioError  # type: ignore[attr-defined]
    sd.query_devices = query_devices  # type: ignore[attr-defined]
    sd.check_output_settings = check_output_settings  # type: ignore[attr-defined]
    sd.OutputStream = output_stream  # type: ignore[attr-defined]
    sd.streams = streams  # type: ignore[attr-defined]
    return sd


def test_device_sink_plays_on_the_sound_device() -> None:
    sd = fake_sounddevice()
    log, logs = capture_logger("device")
    sink = open_sink("auto", RATE, 2, VirtualClock(), log, block=512, latency=0.05, backend_loader=lambda: sd)
    assert isinstance(sink, DeviceSink) and sink.kind == "device" and sink.name == "Fake Speakers"
    stream = sd.streams[0]
    assert stream.started
    assert stream.kwargs.items() >= {"samplerate": RATE, "channels": 2, "dtype": "float32", "blocksize": 512,
                                     "latency": 0.05}.items()
    stop = threading.Event()
    for i in range(3):
        assert sink.write(np.full((512, 2), i / 10, dtype=np.float32), stop)
    assert [b[0, 0] for b in stream.blocks] == pytest.approx([0.0, 0.1, 0.2])
    assert sink.underruns == 1 and sink.frames_played == 3 * 512
    sink.close()
    assert stream.stopped and stream.closed
    assert any("Fake Speakers" in m for m in logs.messages())


def test_no_portaudio_means_the_null_sink_with_one_info_line() -> None:
    def missing() -> types.ModuleType:
        raise OSError("PortAudio library not found")

    log, logs = capture_logger("noportaudio")
    sink = open_sink("auto", RATE, 2, VirtualClock(), log, backend_loader=missing)
    assert isinstance(sink, NullSink)
    assert len(logs.messages()) == 1 and logs.records[0].levelno == logging.INFO
    with pytest.raises(SinkError, match="sink device"):
        open_sink("device", RATE, 2, VirtualClock(), log, backend_loader=missing)


def test_no_output_device_means_the_null_sink_unless_the_device_is_required() -> None:
    sd = fake_sounddevice(has_output=False)
    log, logs = capture_logger("nodevice")
    assert isinstance(open_sink("auto", RATE, 2, VirtualClock(), log, backend_loader=lambda: sd), NullSink)
    assert len(logs.messages(logging.INFO)) == 1
    with pytest.raises(SinkError, match="audio device"):
        open_sink("device", RATE, 2, VirtualClock(), log, backend_loader=lambda: sd)


def test_this_machine_takes_the_real_path() -> None:
    """With the real sounddevice: PortAudio present -> the device (or null when none); absent -> null."""
    try:
        load_sounddevice()
        has_portaudio = True
    except OSError:
        has_portaudio = False
    log, logs = capture_logger("real")
    sink = open_sink("auto", RATE, 2, VirtualClock(), log)
    try:
        if not has_portaudio:
            assert isinstance(sink, NullSink) and "PortAudio" in logs.messages()[0]
        else:
            assert sink.kind in ("device", "null")
    finally:
        sink.close()


# ----------------------------------------------------------------------------------------------
# The recorder
def test_the_recording_is_exactly_what_was_played(tmp_path: Path) -> None:
    sd = fake_sounddevice()
    log, _ = capture_logger("rec")
    path = tmp_path / "played.wav"
    sink = open_sink("device", RATE, 2, VirtualClock(), log, record_wav=str(path), record_format="float",
                     backend_loader=lambda: sd)
    assert isinstance(sink, RecordingSink)
    rng = np.random.default_rng(1)
    blocks = [rng.uniform(-1, 1, (700, 2)).astype(np.float32) for _ in range(5)]
    stop = threading.Event()
    for b in blocks:
        sink.write(b, stop)
    sink.close()
    recorded, sr = sf.read(str(path), dtype="float32", always_2d=True)
    assert sr == RATE
    assert np.array_equal(recorded, np.concatenate(sd.streams[0].blocks))
    assert np.array_equal(recorded, np.concatenate(blocks))


def test_pcm16_recording_and_a_missing_directory(tmp_path: Path) -> None:
    clock = VirtualClock()
    sink = RecordingSink(NullSink(RATE, 1, clock, sleep=clock.sleep), tmp_path / "a.wav", "pcm16")
    sink.write(np.full((100, 1), 0.5, dtype=np.float32), threading.Event())
    sink.close()
    info = sf.info(str(tmp_path / "a.wav"))
    assert (info.subtype, info.frames, info.channels) == ("PCM_16", 100, 1)
    with pytest.raises(SinkError, match="does not exist"):
        RecordingSink(NullSink(RATE, 1, clock), tmp_path / "no" / "b.wav")

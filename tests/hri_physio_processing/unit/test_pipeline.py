"""neurokit_processor's loop without ROS: missing inputs, waiting idly, lost and returning streams.

A fake streamer stands in for LSL at the boundary (it raises what LslStreamer raises); the clock
and the sleeps are injected, so minutes of waiting take no time and are counted exactly.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import numpy as np
import pytest

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.streamers.base import (
    Streamer,
    StreamLostError,
    StreamNotFoundError,
    StreamSpec,
)
from hri_physio_bridge.streamers.csv_stream import CsvStreamer
from hri_physio_bridge.waiting import Backoff
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.pipeline import ProcessingPipeline
from hri_physio_processing.processor import FrameOutput, Output, StatusOutput

FS = 130


class FakeClock:
    """Time that moves only when the code under test sleeps."""

    def __init__(self, stop: threading.Event, stop_after: float = 600.0) -> None:
        self.t = 0.0
        self.sleeps: list[float] = []
        self.stop, self.stop_after = stop, stop_after

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> bool:
        self.sleeps.append(seconds)
        self.t += seconds
        if self.t >= self.stop_after:
            self.stop.set()
        return self.stop.is_set()


class FakeLsl(Streamer):
    """An LSL-like input: absent for ``absent_for`` attempts (each costs its timeout), then frames."""

    scheme = "lsl"

    def __init__(self, clock: FakeClock, frames: list[Frame], absent_for: int = 0,
                 lose_after: int | None = None) -> None:
        super().__init__("SIM/ECG")
        self.clock, self.frames = clock, list(frames)
        self.absent_for, self.lose_after = absent_for, lose_after
        self.opens = 0
        self.exhausted = False

    def open_input(self, expected=None, timeout=10.0, stop=None) -> StreamSpec:
        self.opens += 1
        if self.opens <= self.absent_for:
            self.clock.t += timeout  # a resolve that waited its whole timeout
            raise StreamNotFoundError(f"LSL stream name='SIM/ECG' did not appear within {timeout:g} s")
        self.spec = StreamSpec(name="SIM/ECG", nominal_rate=FS)
        return self.spec

    def receive(self, timeout: float = 0.1) -> Frame | None:
        if self.lose_after is not None and self.lose_after == 0:
            self.lose_after = None
            raise StreamLostError("LSL stream SIM/ECG was lost")
        if not self.frames:
            self.exhausted = True
            return None
        if self.lose_after is not None:
            self.lose_after -= 1
        return self.frames.pop(0)

    def open_output(self, spec: StreamSpec) -> None:
        raise NotImplementedError

    def publish(self, frame: Frame) -> None:
        raise NotImplementedError


class Recorder(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def at(self, level: int) -> list[str]:
        return [r.getMessage() for r in self.records if r.levelno == level]


@pytest.fixture
def log() -> tuple[logging.Logger, Recorder]:
    logger = logging.getLogger(f"test.pipeline.{id(object())}")
    logger.propagate = False
    logger.setLevel(logging.DEBUG)
    rec = Recorder()
    logger.handlers[:] = [rec]
    return logger, rec


def config(**values) -> ProcessorConfig:
    base = {"input": "lsl:SIM/ECG", "output_prefix": "/test/ecg", "window_seconds": 10, "hop_seconds": 5,
            "min_window_seconds": 5, "resolve_timeout": 2.0}
    return ProcessorConfig.from_mapping({**base, **values})


def ecg_frames(mitdb, seconds: int, chunk: int = FS) -> list[Frame]:
    n = seconds * FS
    t, x = 100.0 + mitdb.t[:n], mitdb.x[:n]
    return [Frame(t[a : a + chunk], x[a : a + chunk].reshape(-1, 1)) for a in range(0, n, chunk)]


def test_a_missing_csv_file_is_an_error_at_once(log, tmp_path: Path) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop)
    missing = tmp_path / "missing.csv"
    pipeline = ProcessingPipeline(config(input=f"csv:{missing}"), CsvStreamer(str(missing)), [].append,
                                  logger, clock=clock, sleep=clock.sleep)
    assert not pipeline.waits_for_input
    assert pipeline.run(stop) == 1
    assert pipeline.opener is not None and pipeline.opener.attempts == 1
    assert clock.sleeps == []  # no retry, no wait
    errors = rec.at(logging.ERROR)
    assert len(errors) == 1 and str(missing) in errors[0]
    assert rec.at(logging.WARNING) == []


def test_a_stream_that_never_appears_is_waited_for_idly_with_a_rate_limited_log(log) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop, stop_after=600.0)  # ten minutes of waiting, then Ctrl-C
    source = FakeLsl(clock, [], absent_for=10**9)
    pipeline = ProcessingPipeline(config(resolve_timeout=2.0), source, [].append, logger, clock=clock,
                                  sleep=clock.sleep, backoff=Backoff(0.5, 5.0, jitter=0.0))
    assert pipeline.waits_for_input
    assert pipeline.run(stop) == 0  # a stop while waiting is a clean exit
    attempts = source.opens
    assert 60 <= attempts <= 600 / 2.0  # an attempt every resolve_timeout + up to 5 s of backoff
    assert clock.sleeps[:4] == [0.5, 1.0, 2.0, 4.0] and max(clock.sleeps) == 5.0  # idle between attempts
    waiting = [m for m in rec.at(logging.WARNING) if "still waiting" in m]
    assert 1 <= len(waiting) <= 600 / 30 + 1  # at most one line per 30 s, not one per attempt
    assert "did not appear" in waiting[0] and "attempt(s)" in waiting[0]
    assert rec.at(logging.ERROR) == []
    assert any("stopped before the input" in m for m in rec.at(logging.INFO))


def test_a_stream_that_appears_later_is_processed(log, mitdb) -> None:
    logger, _ = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    source = FakeLsl(clock, ecg_frames(mitdb, 20), absent_for=3)
    pipeline = ProcessingPipeline(config(), source, out.append, logger, clock=clock, sleep=clock.sleep)
    assert pipeline.run(stop) == 0
    assert source.opens == 4 and pipeline.connected
    windows = [o.payload for o in out if isinstance(o, StatusOutput) and o.payload["event"] == "window"]
    assert [w["window"]["t_end"] for w in windows] == pytest.approx([100 + 10 - 1 / FS, 100 + 15 - 1 / FS,
                                                                     100 + 20 - 1 / FS])
    clean = np.concatenate([o.frame.timestamps for o in out if isinstance(o, FrameOutput)
                            and o.feature == "clean"])
    assert clean.shape[0] == 20 * FS  # every sample once


def test_a_lost_stream_closes_the_segment_and_is_waited_for_again(log, mitdb) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    source = FakeLsl(clock, ecg_frames(mitdb, 24), lose_after=12)
    pipeline = ProcessingPipeline(config(), source, out.append, logger, clock=clock, sleep=clock.sleep)
    assert pipeline.run(stop) == 0
    assert source.opens == 2  # reopened after the loss
    windows = [o.payload["window"] for o in out if isinstance(o, StatusOutput)
               and o.payload["event"] == "window"]
    assert any(w["final"] and w["t_end"] == pytest.approx(100 + 12 - 1 / FS) for w in windows)
    assert any("was lost" in m for m in rec.at(logging.WARNING))


def test_text_input_is_refused_in_one_line(log) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop)
    frame = Frame(np.array([1.0]), np.array([["beat"]], dtype=object))
    pipeline = ProcessingPipeline(config(), FakeLsl(clock, [frame]), [].append, logger, clock=clock,
                                  sleep=clock.sleep)
    assert pipeline.run(stop) == 1
    assert len(rec.at(logging.ERROR)) == 1 and "needs numbers" in rec.at(logging.ERROR)[0]


class QueuedInput(FakeLsl):
    """A ros:-like input whose frames are all queued already (the node was busy), some lost on the way."""

    def __init__(self, clock: FakeClock, frames: list[Frame], lost_at: dict[int, int]) -> None:
        super().__init__(clock, frames)
        self.lost_at = lost_at  # frames left in the queue -> lost_messages from then on
        self.taken = 0

    def backlog(self) -> int:
        return len(self.frames)

    def receive(self, timeout: float = 0.1) -> Frame | None:
        self.lost_messages = max([v for k, v in self.lost_at.items() if len(self.frames) <= k], default=0)
        frame = super().receive(timeout)
        self.taken += frame is not None
        return frame


def test_a_backlog_is_processed_in_batches_counted_and_reported(log, mitdb) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    frames = ecg_frames(mitdb, 30, chunk=3)  # 1300 frames, all queued at once
    source = QueuedInput(clock, frames, lost_at={600: 4, 200: 9})
    pipeline = ProcessingPipeline(config(), source, out.append, logger, clock=clock, sleep=clock.sleep)
    pushes: list[int] = []
    push = pipeline.push
    pipeline.push = lambda frame: (pushes.append(frame.num_samples), push(frame))[1]  # type: ignore[method-assign]
    assert pipeline.run(stop) == 0
    assert source.taken == 1300 and sum(pushes) == 30 * FS
    assert len(pushes) < 1300 / 100  # queued frames joined (up to 256 per step), not one push each
    status = [o.payload for o in out if isinstance(o, StatusOutput)]
    windows = [s for s in status if s["event"] == "window"]
    ends = [100 + k - 1 / FS for k in (10, 15, 20, 25, 30)]
    assert [w["window"]["t_end"] for w in windows] == pytest.approx(ends)
    assert all("input" in w and w["input"]["backlog"] >= 0 for w in windows)
    lost = [s for s in status if s["event"] == "input_lost"]
    assert lost and lost[0]["dropped_frames"] == 4 and not lost[0]["ok"]  # one event per report period
    stopped = status[-1]
    assert stopped["event"] == "stopped" and not stopped["ok"]
    assert stopped["input"] == {"samples_in": 30 * FS, "backlog": 0, "max_backlog": 1299, "dropped_frames": 9}
    behind = [m for m in rec.at(logging.WARNING) if "behind" in m]
    assert len(behind) == 1 and "1299 frame(s) queued" in behind[0]  # rate-limited


def test_a_clean_run_ends_with_an_ok_stopped_event(log, mitdb) -> None:
    logger, _ = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    pipeline = ProcessingPipeline(config(), FakeLsl(clock, ecg_frames(mitdb, 12)), out.append, logger,
                                  clock=clock, sleep=clock.sleep)
    assert pipeline.run(stop) == 0
    stopped = out[-1].payload
    assert stopped["event"] == "stopped" and stopped["ok"] and stopped["t"] == pytest.approx(112 - 1 / FS)
    assert stopped["input"]["samples_in"] == 12 * FS and stopped["input"]["dropped_frames"] == 0


class SlowQueuedInput(QueuedInput):
    """Queued frames taking ``cost`` s of the fake clock each to take off the input."""

    def __init__(self, clock: FakeClock, frames: list[Frame], cost: float) -> None:
        super().__init__(clock, frames, lost_at={})
        self.cost = cost

    def receive(self, timeout: float = 0.1) -> Frame | None:
        self.clock.t += self.cost
        return super().receive(timeout)


@pytest.mark.parametrize("cost,left", [(0.001, 0), (1.0, 200 - 17)])
def test_a_stop_processes_what_was_received_within_the_drain_timeout(log, mitdb, cost: float,
                                                                      left: int) -> None:
    logger, _ = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    frames = ecg_frames(mitdb, 20, chunk=13)  # 200 frames queued when the stop comes
    source = SlowQueuedInput(clock, frames, cost)
    cfg = ProcessorConfig.from_mapping({**config().as_dict(), "drain_timeout": 15.0, "drain_per_frame": 0.01})
    pipeline = ProcessingPipeline(cfg, source, out.append, logger, clock=clock, sleep=clock.sleep)
    assert pipeline.open(stop)
    # Deadline 15 s + 0.01 s x 200 = 17 s: at 1 s a frame, 17 frames fit.
    assert pipeline.drain() == left and pipeline.drained == 200 - left
    assert pipeline.processor.stats.samples_in == 13 * (200 - left)
    windows = [o.payload for o in out if isinstance(o, StatusOutput) and o.payload["event"] == "window"]
    assert len(windows) == (3 if left == 0 else 0)  # 20 s of ECG: windows ending at 10, 15, 20 s


def test_the_stopped_event_counts_what_was_drained_and_an_error_names_what_was_left(log, mitdb) -> None:
    logger, rec = log
    stop = threading.Event()
    clock = FakeClock(stop)
    out: list[Output] = []
    source = SlowQueuedInput(clock, ecg_frames(mitdb, 20, chunk=13), 1.0)
    cfg = ProcessorConfig.from_mapping({**config().as_dict(), "drain_timeout": 3.0, "drain_per_frame": 0.0})
    pipeline = ProcessingPipeline(cfg, source, out.append, logger, clock=clock, sleep=clock.sleep)
    # The loop takes nothing before the stop: the stop finds all 200 frames queued.
    pipeline.step = lambda stop_event, timeout=0.1: (stop.set(), True)[1]  # type: ignore[method-assign]
    assert pipeline.run(stop) == 0
    stopped = [o.payload for o in out if isinstance(o, StatusOutput)][-1]
    assert stopped["event"] == "stopped" and not stopped["ok"]
    assert (stopped["drained_frames"], stopped["input"]["backlog"]) == (3, 197)
    errors = rec.at(logging.ERROR)
    assert len(errors) == 1 and "stopped with 197 input frame(s) received but not processed" in errors[0]


LOADS_BEFORE_THE_FIRST_WINDOW = """
import logging, sys, threading
import numpy as np
from hri_physio_bridge.frames import Frame
from hri_physio_bridge.streamers.csv_stream import CsvStreamer
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.pipeline import ProcessingPipeline

path = sys.argv[1]
with open(path, "w") as fh:  # 2 s of samples: less than the shortest window, so no window runs
    fh.write("t,ecg\\n" + "".join(f"{i / 130},{np.sin(i / 10)}\\n" for i in range(260)))
cfg = ProcessorConfig.from_mapping({"input": f"csv:{path}?rate=0", "output_prefix": "/test/ecg",
                                    "window_seconds": 10, "hop_seconds": 5, "min_window_seconds": 5})
assert "neurokit2" not in sys.modules
out = []
pipeline = ProcessingPipeline(cfg, CsvStreamer(f"{path}?rate=0"), out.append, logging.getLogger("t"))
assert pipeline.run(threading.Event()) == 0
assert pipeline.processor.stats.windows == 0, pipeline.processor.stats
print("neurokit2" in sys.modules)
"""


def test_neurokit_is_loaded_before_the_input_is_opened_not_at_the_first_window(tmp_path: Path) -> None:
    """Its import costs seconds of CPU: at the first window it would make that window late."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", LOADS_BEFORE_THE_FIRST_WINDOW, str(tmp_path / "ecg.csv")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"

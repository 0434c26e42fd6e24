"""PhysioReceiver pipeline logic with in-memory streamers (no LSL, no ROS)."""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from helpers import wait_until
from hri_physio_bridge.frames import Frame
from hri_physio_bridge.receiver import ConfigError, PhysioReceiver, ReceiverConfig
from hri_physio_bridge.streamers import (
    Streamer,
    StreamerError,
    StreamLostError,
    StreamMismatchError,
    StreamNotFoundError,
    StreamSpec,
    factory,
)
from hri_physio_bridge.streamers.csv_stream import CsvStreamer


class MemorySource(Streamer):
    """Input fed by the test; can simulate a lost stream that comes back."""

    scheme = "mem"

    def __init__(self, spec: StreamSpec) -> None:
        super().__init__("source")
        self._spec = spec
        self.chunks: queue.Queue[Frame | Exception | None] = queue.Queue()
        self.available = threading.Event()
        self.available.set()
        self.opens = 0
        self.exhausted = False
        self.open_errors: list[Exception] = []  # raised by the next opens, in turn

    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        if not self.available.wait(timeout):
            raise StreamNotFoundError("memory source not available")
        if self.open_errors:
            raise self.open_errors.pop(0)
        self.opens += 1
        return self._spec

    def open_output(self, spec: StreamSpec) -> None:
        raise StreamerError("input only")

    def receive(self, timeout: float = 0.1) -> Frame | None:
        try:
            item = self.chunks.get(timeout=timeout)
        except queue.Empty:
            return None
        if item is None:
            self.exhausted = True
            return None
        if isinstance(item, Exception):
            raise item
        return item

    def publish(self, frame: Frame) -> None:
        raise StreamerError("input only")


class MemorySink(Streamer):
    scheme = "mem"

    def __init__(self, fail_first: int = 0, delay: float = 0.0, consumers: bool = True) -> None:
        super().__init__("sink")
        self.frames: list[Frame] = []
        self.fail_first = fail_first
        self.delay = delay  # seconds per publish: a slow consumer
        self.consumers = consumers
        self.closed = False

    def open_input(self, expected: StreamSpec | None = None, timeout: float = 10.0,
                   stop: threading.Event | None = None) -> StreamSpec:
        raise StreamerError("output only")

    def open_output(self, spec: StreamSpec) -> None:
        self.spec = spec

    def receive(self, timeout: float = 0.1) -> Frame | None:
        raise StreamerError("output only")

    def publish(self, frame: Frame) -> None:
        if self.fail_first > 0:
            self.fail_first -= 1
            raise StreamerError("sink hiccup")
        if self.delay:
            time.sleep(self.delay)
        self.frames.append(frame)

    def has_consumers(self) -> bool:
        return self.consumers

    def close(self) -> None:
        self.closed = True


class CountingSink(MemorySink):
    """An output that counts its listeners, as a ROS 2 publisher does."""

    counts_consumers = True

    def __init__(self) -> None:
        super().__init__()
        self.count = 0
        self.asked = 0  # how often the receiver asked how many listen

    def has_consumers(self) -> bool:
        return self.count > 0

    def consumer_count(self) -> int:
        self.asked += 1
        return self.count


def _memory_streamer(address: str, **_: object) -> Streamer:
    return MemorySink() if address == "sink" else MemorySource(StreamSpec(address))


@pytest.fixture(autouse=True)
def _memory_transport(monkeypatch: pytest.MonkeyPatch) -> None:
    """Addresses are checked against the known transports: make mem: one, for these tests only."""
    monkeypatch.setitem(factory._REGISTRY, "mem", _memory_streamer)


def chunk(start: int, n: int, rate: float = 100.0, channels: int = 1) -> Frame:
    idx = np.arange(start, start + n, dtype=float)
    return Frame(idx / rate, np.column_stack([idx] * channels))


def make(tmp_path: Path | None = None, monotonic: Callable[[], float] = time.monotonic,
         **overrides) -> tuple[PhysioReceiver, MemorySource, MemorySink]:
    opts = {"input": "mem:source", "output": "mem:sink", "sampling_rate": 100.0, "output_frame": 4,
            "buffer_length": 64}
    opts.update(overrides)
    cfg = ReceiverConfig.from_mapping(opts)
    src = MemorySource(StreamSpec("src", channel_count=cfg.num_channels, nominal_rate=cfg.sampling_rate))
    sink = MemorySink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"), monotonic=monotonic)
    return rx, src, sink


def log_lines(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


def run_to_end(rx: PhysioReceiver, src: MemorySource, chunks: list[Frame]) -> None:
    rx.start()
    for c in chunks:
        src.chunks.put(c)
    src.chunks.put(None)  # end of input
    assert rx.wait(5.0), "receiver did not finish"
    rx.stop()


def test_every_sample_forwarded_once_in_order_with_overlap_and_tail() -> None:
    rx, src, sink = make(output_frame=5, sample_overlap=2)
    told: list[int] = []
    rx.on_finished = lambda: told.append(rx.stats.published_samples)  # how the node waits for the end
    chunks = [chunk(i, 3) for i in range(0, 30, 3)]
    run_to_end(rx, src, chunks)
    assert told == [30]  # once, with the tail published
    firsts = [sink.frames[0].values[:, 0]] + [f.values[2:, 0] for f in sink.frames[1:-1]]
    # The tail frame (from drain) holds only unpublished samples.
    all_new = np.concatenate([*firsts, sink.frames[-1].values[:, 0]])
    np.testing.assert_array_equal(all_new, np.arange(30))
    for f in sink.frames[:-1]:
        np.testing.assert_array_equal(f.timestamps, f.values[:, 0] / 100.0)
    assert rx.stats.received_samples == 30 and rx.stats.published_samples == 30
    assert sink.closed


def test_csv_log_written_before_buffering(tmp_path: Path) -> None:
    log_path = tmp_path / "logs" / "ecg.csv"
    rx, src, _ = make(log_data=True, log_name=str(log_path), num_channels=2)
    rx.open()
    src.chunks.put(chunk(0, 3, channels=2))
    # Run only the producer step: the chunk must be in the log even before any frame exists.
    rx._accept(src.receive())
    rows = log_path.read_text().splitlines()
    assert rows[0] == "t,ch1,ch2" and len(rows) == 4
    rx.stop()
    back = CsvStreamer(f"{log_path}?rate=0")
    back.open_input()
    f = back.receive()
    np.testing.assert_array_equal(f.values, chunk(0, 3, channels=2).values)


def test_gap_in_timestamps_is_reported_with_first_and_last_missing() -> None:
    rx, src, _ = make()
    run_to_end(rx, src, [chunk(0, 10), chunk(25, 10)])
    assert len(rx.stats.gaps) == 1
    gap = rx.stats.gaps[0]
    assert gap.count == 15
    assert gap.first_t == pytest.approx(0.10) and gap.last_t == pytest.approx(0.24)
    assert rx.stats.published_samples == 20  # nothing received is lost


def test_lost_source_reconnects_and_keeps_data() -> None:
    rx, src, sink = make()
    rx.start()
    src.chunks.put(chunk(0, 8))
    src.available.clear()
    src.chunks.put(StreamLostError("memory stream lost"))
    threading.Timer(0.3, src.available.set).start()
    src.chunks.put(chunk(20, 8))
    src.chunks.put(None)
    assert rx.wait(5.0)
    rx.stop()
    assert src.opens == 2 and rx.stats.reconnects == 1
    got = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(got, np.r_[0:8, 20:28])
    assert [g.count for g in rx.stats.gaps] == [12]


def test_a_source_lost_again_while_reopening_is_waited_for() -> None:
    """LSL may still list an outlet that has just closed: opening it fails as lost, and the next try works."""
    rx, src, sink = make()
    rx.start()  # opens the source (it is there)
    assert src.opens == 1
    src.open_errors = [StreamLostError("could not open: the stream has been lost")] * 2
    src.chunks.put(chunk(0, 8))
    src.chunks.put(StreamLostError("memory stream lost"))
    src.chunks.put(chunk(20, 8))
    src.chunks.put(None)
    assert rx.wait(10.0)
    rx.stop()
    assert rx.fatal is None and rx.stats.reconnects == 1 and not src.open_errors
    got = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(got, np.r_[0:8, 20:28])


def test_lost_source_without_reconnect_is_fatal_but_flushes(caplog: pytest.LogCaptureFixture) -> None:
    rx, src, sink = make(reconnect=False)
    told = threading.Event()
    rx.on_finished = told.set
    with caplog.at_level(logging.INFO, logger="test"):
        rx.start()
        src.chunks.put(chunk(0, 6))
        src.chunks.put(StreamLostError("gone"))
        assert rx.wait(5.0)
        assert told.is_set()
        rx.stop()
    assert isinstance(rx.fatal, StreamLostError) and src.opens == 1
    assert sum(f.num_samples for f in sink.frames) == 6
    # It says what it does, not that it waits for the input to come back.
    assert log_lines(caplog, "input lost; reconnect is off: publishing what is buffered and exiting")
    assert not log_lines(caplog, "waiting for it to come back")


def test_wrong_channel_count_chunk_is_rejected_and_counted() -> None:
    rx, src, _ = make()
    run_to_end(rx, src, [chunk(0, 4), chunk(4, 4, channels=3), chunk(8, 4)])
    assert rx.stats.rejected_chunks == 1
    assert rx.stats.published_samples == 8


def test_rejected_chunks_are_all_counted_but_logged_at_most_every_5_s(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    rx, _, _ = make(num_channels=2, monotonic=lambda: now[0])
    rx.open()
    with caplog.at_level(logging.ERROR, logger="test"):
        for t in (0.0, 1.0, 4.9, 5.5, 6.0):
            now[0] = t
            rx._accept(chunk(0, 4, channels=3))
    rx.stop()
    assert rx.stats.rejected_chunks == 5 and rx.stats.received_samples == 0
    assert log_lines(caplog, "rejected") == [
        "mem:source: chunk with 3 channel(s) rejected, num_channels is 2 "
        "(1 chunk(s) rejected so far; repeats are summarised at most every 5 s)",
        "mem:source: chunk with 3 channel(s) rejected, num_channels is 2 "
        "(3 chunk(s) rejected since the last report, 4 so far)",
    ]


def test_nonfinite_samples_are_counted_and_forwarded(caplog: pytest.LogCaptureFixture) -> None:
    rx, src, sink = make()
    bad = chunk(0, 4)
    bad.values[1, 0] = np.nan
    bad.values[2, 0] = np.inf
    with caplog.at_level(logging.WARNING, logger="test"):
        run_to_end(rx, src, [bad])
    assert rx.stats.nonfinite_samples == 2
    assert "2 sample(s) with NaN/inf" in caplog.text
    assert np.isnan(sink.frames[0].values[1, 0])


def test_samples_with_a_nan_or_infinite_timestamp_are_dropped_and_the_rest_goes_on(
        caplog: pytest.LogCaptureFixture) -> None:
    """Such a sample has no place in time (and stopped the receiver, and a processor downstream): it is
    dropped, counted and said; the chunk's other samples and the chunks after it are published."""
    rx, src, sink = make()
    bad = chunk(4, 4)
    bad.timestamps[1] = np.inf
    bad.timestamps[2] = np.nan
    all_bad = chunk(8, 4)
    all_bad.timestamps[:] = -np.inf
    with caplog.at_level(logging.ERROR, logger="test"):
        run_to_end(rx, src, [chunk(0, 4), bad, all_bad, chunk(12, 8)])
    assert rx.fatal is None
    assert rx.stats.bad_timestamp_samples == 6 and rx.stats.as_dict()["bad_timestamp_samples"] == 6
    published = np.concatenate([f.timestamps for f in sink.frames])
    expected = np.array([0, 1, 2, 3, 4, 7, 12, 13, 14, 15, 16, 17, 18, 19]) / 100.0
    assert np.isfinite(published).all() and np.allclose(published[:len(expected)], expected)
    assert rx.stats.published_samples == 14
    assert "2 sample(s) with a NaN or infinite timestamp dropped (in a chunk from t=0.0400)" in caplog.text


def test_publish_errors_are_counted_not_fatal() -> None:
    rx, src, _ = make()
    rx.sink = sink = MemorySink(fail_first=1)
    run_to_end(rx, src, [chunk(0, 8)])
    assert rx.stats.publish_errors == 1 and rx.fatal is None
    assert len(sink.frames) == 1


def test_pause_holds_output_resume_releases_it() -> None:
    rx, src, sink = make()
    rx.start()
    rx.pause()
    src.chunks.put(chunk(0, 8))
    threading.Event().wait(0.3)
    assert sink.frames == [] and rx.stats.received_samples == 8
    rx.resume()
    src.chunks.put(None)
    assert rx.wait(5.0)
    rx.stop()
    assert sum(f.num_samples for f in sink.frames) == 8


def test_stop_mid_stream_publishes_what_was_buffered() -> None:
    rx, src, sink = make(output_frame=50)
    rx.start()
    src.chunks.put(chunk(0, 7))
    deadline = threading.Event()
    while rx.stats.received_samples < 7 and not deadline.wait(0.01):
        pass
    rx.stop()
    assert sum(f.num_samples for f in sink.frames) == 7


def test_drop_oldest_overflow_reported_as_gap() -> None:
    rx, src, sink = make(overflow_policy="drop_oldest", buffer_length=8, output_frame=8)
    rx.open()
    rx._accept(chunk(0, 8))
    rx._accept(chunk(8, 4))  # buffer full: 0..3 dropped
    rx.start()
    src.chunks.put(None)
    assert rx.wait(5.0)
    rx.stop()
    assert [(g.count, g.reason.startswith("buffer overflow")) for g in rx.stats.gaps] == [(4, True)]
    np.testing.assert_array_equal(sink.frames[0].values[:, 0], np.arange(4, 12))


def test_drop_oldest_overflow_is_logged_with_the_count_since_the_last_line(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    rx, _, sink = make(overflow_policy="drop_oldest", buffer_length=8, output_frame=8,
                         monotonic=lambda: now[0])
    rx.open()
    with caplog.at_level(logging.WARNING, logger="test"):
        rx._accept(chunk(0, 8))
        rx._accept(chunk(8, 4))  # full: 0..3 dropped, logged at once
        now[0] = 2.0
        rx._accept(chunk(12, 2))  # 4..5 dropped within 5 s: counted, not logged
        now[0] = 6.0
        rx._accept(chunk(14, 3))  # 6..8 dropped: logged with everything since the last line
        rx.stop()
    assert log_lines(caplog, "buffer overflow") == [
        "buffer overflow: dropped 4 oldest sample(s) t=0.0000..0.0300 "
        "(4 sample(s) dropped so far; repeats are summarised at most every 5 s)",
        "buffer overflow: dropped 3 oldest sample(s) t=0.0600..0.0800 "
        "(5 sample(s) dropped since the last report, 9 so far)",
    ]
    # Every drop is still a gap in the stats, and the survivors are forwarded.
    assert [(g.first_t, g.last_t, g.count) for g in rx.stats.gaps] == [
        (0.0, 0.03, 4), (0.04, 0.05, 2), (0.06, 0.08, 3)
    ]
    np.testing.assert_array_equal(np.concatenate([f.values[:, 0] for f in sink.frames]), np.arange(9, 17))


def test_block_policy_with_a_slow_consumer_loses_nothing_and_says_so_once(
        caplog: pytest.LogCaptureFixture) -> None:
    rx, src, _ = make(overflow_policy="block", buffer_length=8, output_frame=4, monotonic=lambda: 0.0)
    rx.sink = sink = MemorySink(delay=0.005)
    with caplog.at_level(logging.WARNING, logger="test"):
        run_to_end(rx, src, [chunk(i, 5) for i in range(0, 200, 5)])
    values = np.concatenate([f.values[:, 0] for f in sink.frames])
    stamps = np.concatenate([f.timestamps for f in sink.frames])
    np.testing.assert_array_equal(values, np.arange(200))  # every sample once, in order
    np.testing.assert_array_equal(stamps, np.arange(200) / 100.0)
    assert rx.stats.gaps == [] and rx.buffer.dropped_samples == 0
    assert rx.buffer.overflow_events > 1  # the producer did wait for the consumer, many times
    assert log_lines(caplog, "buffer full") == [
        "buffer full: producer waits for the consumer (raise buffer_length?) "
        "(1 wait(s) so far; repeats are summarised at most every 5 s)"
    ]


def test_request_stop_ends_the_wait_for_a_consumer(caplog: pytest.LogCaptureFixture) -> None:
    rx, src, sink = make(wait_for_consumers=30.0)
    rx.sink = sink = MemorySink(consumers=False)
    rx.open()
    threading.Timer(0.2, rx.request_stop).start()
    start = time.monotonic()
    with caplog.at_level(logging.INFO, logger="test"):
        rx.start()
    assert time.monotonic() - start < 2.0
    src.chunks.put(chunk(0, 4))
    assert rx._threads == [] and rx.stats.received_samples == 0  # stopped before reading: no threads
    rx.stop()
    assert sink.closed
    assert log_lines(caplog, "stopped while waiting for a consumer on mem:sink")


@pytest.mark.parametrize(
    "overrides,option",
    [
        ({"output_frame": 0}, "output_frame"),
        ({"sample_overlap": 4}, "sample_overlap"),
        ({"buffer_length": 2}, "buffer_length"),
        ({"dtype": "complex128"}, "dtype"),
        ({"sampling_rate": -5}, "sampling_rate"),
        ({"sampling_rate": "fast"}, "sampling_rate"),
        ({"overflow_policy": "panic"}, "overflow_policy"),
        ({"log_data": "perhaps"}, "log_data"),
        ({"num_channels": 2.5}, "num_channels"),
        ({"colour": "red"}, "colour"),
        ({"input": ""}, "input"),
        ({"input": "udp:1234"}, "udp"),
        ({"output": "/no/scheme"}, "output"),
        ({"channel_names": ["a", "b"]}, "channel_names"),
        ({"min_consumers": 0}, "min_consumers"),
        ({"min_consumers": 2}, "min_consumers"),
    ],
)
def test_bad_configuration_is_named(overrides: dict, option: str) -> None:
    opts = {"output_frame": 4}
    opts.update(overrides)
    with pytest.raises(ConfigError) as err:
        ReceiverConfig.from_mapping(opts)
    assert option in str(err.value) and "\n" not in str(err.value)


def test_waits_for_min_consumers_before_reading(caplog: pytest.LogCaptureFixture) -> None:
    """A processor and a recorder must both see the first sample: with min_consumers 2 the
    receiver reads nothing while only one listens, and starts once the second one does."""
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "output_frame": 4,
                                       "wait_for_consumers": 30.0, "min_consumers": 2, "sampling_rate": 100})
    src = MemorySource(StreamSpec("src", channel_count=1, nominal_rate=100.0))
    sink = CountingSink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"))
    rx.open()
    sink.count = 1
    src.chunks.put(chunk(0, 8))  # waits in the open input meanwhile
    started = threading.Event()
    with caplog.at_level(logging.INFO, logger="test"):
        t = threading.Thread(target=lambda: (rx.start(), started.set()))
        t.start()
        # Asked again and again while one listens: it is waiting, and reads nothing meanwhile.
        wait_until(lambda: sink.asked >= 3, 10, "the receiver to ask for its listeners three times")
        assert not started.is_set() and rx.stats.received_samples == 0 and rx._threads == []
        sink.count = 2
        assert started.wait(2.0)
        t.join()
    src.chunks.put(None)
    assert rx.wait(5.0)
    rx.stop()
    np.testing.assert_array_equal(np.concatenate([f.values[:, 0] for f in sink.frames]), np.arange(8))
    assert log_lines(caplog, "waiting up to 30 s for 2 consumers on mem:sink")
    assert log_lines(caplog, "mem:sink has 2 consumers")


def test_min_consumers_times_out_with_the_count_named(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "output_frame": 4,
                                       "wait_for_consumers": 5.0, "min_consumers": 3, "sampling_rate": 100})
    sink = CountingSink()
    sink.count = 1
    rx = PhysioReceiver(cfg, MemorySource(StreamSpec("src", nominal_rate=100.0)), sink,
                        log=logging.getLogger("test"), monotonic=lambda: now[0])
    rx.open()
    threading.Timer(0.1, lambda: now.__setitem__(0, 6.0)).start()
    with caplog.at_level(logging.INFO, logger="test"):
        rx.start()  # gives up after the (fake) 5 s and starts anyway
    rx.request_stop()
    rx.stop()
    assert log_lines(caplog, "only 1 of 3 consumers on mem:sink after 5 s; starting anyway")


def test_min_consumers_needs_an_output_that_counts() -> None:
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "output_frame": 4,
                                       "wait_for_consumers": 5.0, "min_consumers": 2})
    with pytest.raises(ConfigError, match="output mem:sink cannot count its listeners"):
        PhysioReceiver(cfg, MemorySource(StreamSpec("src")), MemorySink())


# -- what the input declares, and what its timestamps say ----------------------------------------


def test_a_stream_declaring_another_rate_is_refused_at_open() -> None:
    """A 500 Hz stream read with the default 130 Hz used to be 'connected ... @ 130 Hz' without a word."""
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink"})  # 130 Hz
    src = MemorySource(StreamSpec("src", nominal_rate=500.0))
    sink = MemorySink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"))
    with pytest.raises(StreamMismatchError) as err:
        rx.open()
    message = str(err.value)
    assert "500 Hz" in message and "130 Hz" in message and "sampling_rate" in message and "\n" not in message
    assert rx.buffer is None and sink.spec is None  # nothing was opened downstream


def test_a_stream_declaring_no_rate_is_taken_with_a_warning(caplog: pytest.LogCaptureFixture) -> None:
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "sampling_rate": 100})
    src = MemorySource(StreamSpec("src", nominal_rate=0.0))
    rx = PhysioReceiver(cfg, src, MemorySink(), log=logging.getLogger("test"))
    with caplog.at_level(logging.WARNING, logger="test"):
        run_to_end(rx, src, [chunk(0, 10)])
    assert rx.stats.published_samples == 10
    assert log_lines(caplog, "declares no nominal rate")


@pytest.mark.parametrize("changed", [{"nominal_rate": 500.0}, {"channel_count": 2}])
def test_a_stream_that_comes_back_as_another_stream_is_an_error(changed: dict) -> None:
    """After a reconnect, another rate (or channel count) must not be mixed into the same output."""
    rx, src, sink = make()
    rx.start()
    src.chunks.put(chunk(0, 8))
    src.available.clear()
    src.chunks.put(StreamLostError("memory stream lost"))
    spec = {"name": "src", "channel_count": 1, "nominal_rate": 100.0, **changed}
    src._spec = StreamSpec(**spec)  # the source that comes back is another stream
    threading.Timer(0.2, src.available.set).start()
    src.chunks.put(chunk(8, 8))
    assert rx.wait(10.0)
    rx.stop()
    assert isinstance(rx.fatal, StreamMismatchError) and "came back as another stream" in str(rx.fatal)
    assert rx.stats.reconnects == 0 and src.opens == 2
    np.testing.assert_array_equal(np.concatenate([f.values[:, 0] for f in sink.frames]), np.arange(8))


def stamped(stamps: np.ndarray, first_value: int = 0) -> Frame:
    return Frame(np.asarray(stamps, dtype=float), np.arange(first_value, first_value + len(stamps),
                                                             dtype=float).reshape(-1, 1))


def test_a_backward_clock_jump_and_its_return_are_jumps_not_gaps(caplog: pytest.LogCaptureFixture) -> None:
    """5 s back, then forward again onto the earlier timeline: nothing is missing. (Before: the
    return counted as a gap of 650 'missing' samples, the jumps were not counted at all.)"""
    rate = 130.0
    k = np.arange(130 * 30)
    t = k / rate
    t[130 * 10:130 * 20] -= 5.0  # the sender's clock runs 5 s behind for 10 s, then comes back
    rx, src, sink = make(sampling_rate=rate, output_frame=13)
    with caplog.at_level(logging.WARNING, logger="test"):
        run_to_end(rx, src, [stamped(t[i:i + 13], i) for i in range(0, len(t), 13)])
    status = rx.status()
    assert (status["gaps"], status["missing_samples"], status["clock_jumps"]) == (0, 0, 2)
    assert [j.kind for j in rx.stats.clock_jumps] == ["backward", "returned"]
    values = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(values, k)  # every sample forwarded, once, in order
    np.testing.assert_array_equal(np.concatenate([f.timestamps for f in sink.frames]), t)  # unchanged
    assert len(log_lines(caplog, "clock jump")) == 1  # the second within 5 s is counted, not logged
    assert not log_lines(caplog, "gap of")


def test_samples_missing_after_a_returning_clock_are_a_gap_of_the_right_size() -> None:
    rate = 100.0
    t = np.r_[np.arange(0, 500), np.arange(500, 700) - 300, np.arange(750, 800)] / rate  # 3 s back, then
    rx, src, _ = make(sampling_rate=rate)  # forward onto the earlier timeline 50 samples late
    run_to_end(rx, src, [stamped(t[i:i + 10], i) for i in range(0, len(t), 10)])
    assert [j.kind for j in rx.stats.clock_jumps] == ["backward", "returned"]
    assert [g.count for g in rx.stats.gaps] == [50]
    assert rx.stats.gaps[0].first_t == pytest.approx(7.0) and rx.stats.gaps[0].last_t == pytest.approx(7.49)


def test_repeated_timestamps_are_flagged_counted_and_logged_at_most_every_5_s(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    rx, _, _ = make(sampling_rate=10, buffer_length=200, monotonic=lambda: now[0])
    rx.open()
    with caplog.at_level(logging.WARNING, logger="test"):
        for i in range(40):  # a 10 Hz sender that stamps two samples alike, ten times a second
            now[0] = i * 0.1
            rx._accept(stamped([i * 0.1, i * 0.1]))
    rx.stop()
    assert rx.status()["clock_jumps"] == 40 and rx.status()["gaps"] == 0
    lines = log_lines(caplog, "clock jump")
    assert len(lines) == 1, lines  # 4 s of repeats: the first line only; before, ~10 lines a second


def test_measured_rate_off_by_more_than_5_percent_is_warned_and_reported(
        caplog: pytest.LogCaptureFixture) -> None:
    """Declared 100 Hz, sent at 110 Hz: measured_rate in the status, a warning (rate-limited)."""
    now = [0.0]
    rx, _, _ = make(buffer_length=5000, monotonic=lambda: now[0])
    rx.open()
    with caplog.at_level(logging.WARNING, logger="test"):
        for i in range(0, 110 * 20, 11):  # 20 s of stream, one chunk each 0.1 s
            now[0] = i / 110
            rx._accept(stamped(np.arange(i, i + 11) / 110.0, i))
    rx.stop()
    assert rx.status()["measured_rate"] == pytest.approx(110.0)
    assert len(log_lines(caplog, "measured rate 110 Hz is +10% off sampling_rate 100 Hz")) == 1


def test_measured_rate_ignores_gaps_and_needs_a_few_seconds() -> None:
    now = [0.0]
    rx, _, _ = make(buffer_length=5000, monotonic=lambda: now[0])
    rx.open()
    rx._accept(stamped(np.arange(0, 200) / 100.0))
    now[0] = 2.0
    rx._accept(stamped(np.arange(200, 300) / 100.0))  # 3 s of timestamps: not enough yet
    assert rx.status()["measured_rate"] is None
    now[0] = 10.0
    rx._accept(stamped(np.arange(400, 900) / 100.0))  # after a gap of 100 samples
    rx.stop()
    assert rx.status()["measured_rate"] == pytest.approx(100.0) and rx.status()["gaps"] == 1


def test_csv_input_that_is_not_utf8_is_one_error_naming_file_and_line(tmp_path: Path) -> None:
    """No UnicodeDecodeError traceback; every row before the bad line is forwarded."""
    path = tmp_path / "session.csv"
    rows = b"".join(f"{i / 100},{i}\n".encode() for i in range(50))
    path.write_bytes(b"t,a\n" + rows + b"0.5,\xff\n0.51,51\n")
    cfg = ReceiverConfig.from_mapping({"input": f"csv:{path}?rate=0", "output": "mem:sink",
                                       "sampling_rate": 0, "input_frame": 32})
    sink = MemorySink()
    rx = PhysioReceiver(cfg, CsvStreamer(f"{path}?rate=0", max_chunk=32), sink, log=logging.getLogger("test"))
    rx.start()
    assert rx.wait(5.0)
    rx.stop()
    assert isinstance(rx.fatal, StreamMismatchError)
    assert str(rx.fatal).startswith(f"{path}:52: not UTF-8 text"), rx.fatal
    np.testing.assert_array_equal(np.concatenate([f.values[:, 0] for f in sink.frames]), np.arange(50))


class LateSource(MemorySource):
    """An input whose samples arrive just as the stop comes: a receive call that started before
    ``arrived`` was set waits its whole timeout and returns nothing, as an LSL inlet whose data
    landed after the pull began."""

    def __init__(self, spec: StreamSpec) -> None:
        super().__init__(spec)
        self.arrived = threading.Event()
        self.calls = threading.Event()

    def receive(self, timeout: float = 0.1) -> Frame | None:
        self.calls.set()
        if not self.arrived.is_set():
            time.sleep(timeout)
            return None
        return super().receive(0.0)


def test_samples_that_arrived_before_the_stop_are_forwarded() -> None:
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "sampling_rate": 100,
                                       "output_frame": 4})
    src = LateSource(StreamSpec("src", nominal_rate=100.0))
    sink = MemorySink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"))
    rx.start()
    assert src.calls.wait(5.0)
    for i in range(0, 30, 10):
        src.chunks.put(chunk(i, 10))
    src.arrived.set()
    rx.stop()  # before: the producer saw the stop and left these 30 samples in the input
    np.testing.assert_array_equal(np.concatenate([f.values[:, 0] for f in sink.frames]), np.arange(30))


class EndlessSource(MemorySource):
    """An input that never runs dry once the stop comes: every receive gives another chunk, and each
    takes 0.1 s of the receiver's (fake) clock."""

    def __init__(self, spec: StreamSpec, now: list[float]) -> None:
        super().__init__(spec)
        self.now = now
        self.next = 0
        self.stopping = threading.Event()

    def receive(self, timeout: float = 0.1) -> Frame | None:
        if not self.stopping.is_set():
            time.sleep(min(timeout, 0.01))
            return None
        self.now[0] += 0.1
        frame = chunk(self.next, 10)
        self.next += 10
        return frame


def test_an_input_that_keeps_delivering_at_the_stop_is_cut_with_an_error_line(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "sampling_rate": 100,
                                       "output_frame": 10})
    src = EndlessSource(StreamSpec("src", nominal_rate=100.0), now)
    sink = MemorySink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"), monotonic=lambda: now[0])
    rx.start()
    src.stopping.set()
    with caplog.at_level(logging.INFO, logger="test"):
        rx.stop()
    errors = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert len(errors) == 1 and "still delivered after 5 s" in errors[0] and "left unread" in errors[0]
    published = np.concatenate([f.values[:, 0] for f in sink.frames])
    # What was taken (at least the 5 s of the fake clock the drain lasted, 10 samples per 0.1 s) is
    # published whole, in order.
    np.testing.assert_array_equal(published, np.arange(len(published)))
    assert len(published) >= 490


class BackloggedSource(EndlessSource):
    """An input holding ``held`` chunks at the stop; taking each costs 0.02 s of the (fake) clock, so
    taking them all lasts longer than drain_timeout alone."""

    def __init__(self, spec: StreamSpec, now: list[float], held: int) -> None:
        super().__init__(spec, now)
        self.held = held

    def backlog(self) -> int:
        return self.held if self.stopping.is_set() else 0

    def receive(self, timeout: float = 0.1) -> Frame | None:
        if self.stopping.is_set() and self.held == 0:
            return None
        frame = super().receive(timeout)
        if frame is not None:
            self.now[0] += 0.01
            self.held -= 1
        return frame


@pytest.mark.parametrize("per_chunk, all_taken", [(0.2, True), (0.0, False)])
def test_the_stops_drain_time_scales_with_what_the_input_holds(
        per_chunk: float, all_taken: bool, caplog: pytest.LogCaptureFixture) -> None:
    """500 chunks at 0.11 s each: 55 s, far past drain_timeout (5 s). With drain_per_chunk the stop
    allows for them and forwards every sample, without an error; without it, the rest is an error
    naming what was left, and counted in the status."""
    now = [0.0]
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "sampling_rate": 100,
                                       "output_frame": 10, "drain_per_chunk": per_chunk})
    src = BackloggedSource(StreamSpec("src", nominal_rate=100.0), now, held=500)
    sink = MemorySink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"), monotonic=lambda: now[0])
    rx.start()
    src.stopping.set()
    with caplog.at_level(logging.INFO, logger="test"):
        rx.stop()
    errors = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    published = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(published, np.arange(len(published)))
    if all_taken:
        assert errors == [] and len(published) == 5000 and rx.status()["unread_at_stop"] == 0
    else:
        assert len(errors) == 1 and "chunk(s) left unread" in errors[0], errors
        assert len(published) < 5000 and rx.status()["unread_at_stop"] == src.held > 0


def test_a_backlog_the_stop_cannot_wait_for_goes_out_whole_and_in_order() -> None:
    """A slow output (10 ms a frame) and 1500 buffered frames at the stop, with no time allowed for
    them: the consumer leaves after its current frame and the stop publishes the rest as one frame.
    Every sample is published once, in order (the rest used to go out beside a consumer still at work,
    reordering them)."""
    rx, src, sink = make(sampling_rate=100, output_frame=1, drain_timeout=0, drain_per_chunk=0,
                         buffer_length=5000)
    sink.delay = 0.01
    for i in range(0, 1500, 100):
        src.chunks.put(chunk(i, 100))
    rx.start()
    wait_until(lambda: rx.status()["received_samples"] == 1500, 10, "the producer to take the input")
    rx.stop(timeout=0.05)
    published = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(published, np.arange(1500))
    assert rx.status()["unpublished_at_stop"] == 0 and len(sink.frames) < 1500  # the rest went as one


class StuckSink(MemorySink):
    """An output whose 10th publish does not return until ``release`` is set."""

    def __init__(self) -> None:
        super().__init__()
        self.stuck, self.release = threading.Event(), threading.Event()

    def publish(self, frame: Frame) -> None:
        if len(self.frames) == 10 and not self.release.is_set():
            self.stuck.set()
            self.release.wait(30)
        super().publish(frame)


def test_a_stop_never_publishes_beside_a_consumer_stuck_in_the_output(
        caplog: pytest.LogCaptureFixture) -> None:
    """The consumer is stuck inside its 11th publish when the stop comes. The stop must not publish the
    rest meanwhile (that frame would land after the rest: samples out of order); it says how many
    samples it left, as an error, and what was published is in order."""
    cfg = ReceiverConfig.from_mapping({"input": "mem:source", "output": "mem:sink", "sampling_rate": 100,
                                       "output_frame": 1, "drain_timeout": 0, "drain_per_chunk": 0,
                                       "buffer_length": 5000})
    src = MemorySource(StreamSpec("src", nominal_rate=100.0))
    sink = StuckSink()
    rx = PhysioReceiver(cfg, src, sink, log=logging.getLogger("test"))
    for i in range(0, 500, 100):
        src.chunks.put(chunk(i, 100))
    rx.start()
    assert sink.stuck.wait(10)
    wait_until(lambda: rx.status()["received_samples"] == 500, 10, "the producer to take the input")
    with caplog.at_level(logging.ERROR, logger="test"):
        rx.stop(timeout=0.05)
    sink.release.set()
    consumer = next(t for t in rx._threads if t.name == "receiver-consumer")
    consumer.join(10)
    assert not consumer.is_alive()  # it left after the frame it was stuck in
    published = np.concatenate([f.values[:, 0] for f in sink.frames])
    np.testing.assert_array_equal(published, np.arange(len(published)))  # in order, none twice
    left = rx.status()["unpublished_at_stop"]
    assert len(published) + left == 500 and left > 0
    assert [m for m in log_lines(caplog, "the output is stuck") if f"{left} buffered sample(s)" in m]

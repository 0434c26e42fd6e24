"""Ring buffer: overlap semantics at every boundary, wrap-around, overflow policies, threads."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from hri_physio_bridge.ring_buffer import BufferClosed, Gap, OverflowPolicy, RingBuffer


def counter(start: int, n: int, channels: int = 1) -> tuple[np.ndarray, np.ndarray]:
    idx = np.arange(start, start + n, dtype=np.float64)
    values = np.column_stack([idx * (c + 1) for c in range(channels)])
    return idx / 100.0, values


def frames_of(buf: RingBuffer, n: int, k: int) -> list[np.ndarray]:
    out = []
    while (f := buf.dequeue_frame(n, k, timeout=0)) is not None:
        out.append(f.values[:, 0].copy())
    return out


@pytest.mark.parametrize("n,k", [(1, 0), (4, 0), (4, 1), (4, 3), (5, 2), (7, 6)])
@pytest.mark.parametrize("capacity", [7, 8, 13, 64])
@pytest.mark.parametrize("chunk", [1, 3, 5, 11])
def test_sliding_windows_match_reference(n: int, k: int, capacity: int, chunk: int) -> None:
    """Frames equal x[i*(n-k) : i*(n-k)+n] for any chunking and any wrap-around."""
    if n > capacity:
        pytest.skip("frame larger than buffer is rejected (tested separately)")
    total = 60
    buf = RingBuffer(capacity, 1)
    got: list[np.ndarray] = []
    t_all, v_all = counter(0, total)
    pos = 0
    while pos < total:
        # Feed what fits (consume as we go so the buffer wraps many times).
        take = min(chunk, total - pos, buf.capacity - len(buf))
        if take:
            buf.enqueue(t_all[pos : pos + take], v_all[pos : pos + take])
            pos += take
        got.extend(frames_of(buf, n, k))
    step = n - k
    expected = [np.arange(i, i + n, dtype=float) for i in range(0, total - n + 1, step)]
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_array_equal(g, e)


def test_timestamps_travel_with_samples_across_wrap() -> None:
    buf = RingBuffer(5, 2)
    t, v = counter(0, 4, channels=2)
    buf.enqueue(t, v)
    f1 = buf.dequeue_frame(3, 1, timeout=0)
    t2, v2 = counter(4, 3, channels=2)
    buf.enqueue(t2, v2)  # wraps
    f2 = buf.dequeue_frame(3, 1, timeout=0)
    np.testing.assert_array_equal(f1.timestamps, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(f2.timestamps, [0.02, 0.03, 0.04])
    np.testing.assert_array_equal(f2.values[:, 1], [4.0, 6.0, 8.0])
    assert f1.fresh == 3 and f2.fresh == 2


def test_first_frame_needs_n_new_samples_and_drain_returns_rest() -> None:
    buf = RingBuffer(10, 1)
    buf.enqueue(*counter(0, 4))
    assert buf.dequeue_frame(5, 2, timeout=0) is None
    buf.enqueue(*counter(4, 1))
    f = buf.dequeue_frame(5, 2, timeout=0)
    np.testing.assert_array_equal(f.values[:, 0], [0, 1, 2, 3, 4])
    buf.enqueue(*counter(5, 2))
    assert buf.dequeue_frame(5, 2, timeout=0) is None  # only 2 new + 2 overlap
    rest = buf.drain()
    np.testing.assert_array_equal(rest.values[:, 0], [5, 6])  # unpublished samples only
    assert rest.fresh == 2
    assert buf.drain() is None


def test_changing_overlap_down_discards_only_already_published() -> None:
    buf = RingBuffer(10, 1)
    buf.enqueue(*counter(0, 8))
    buf.dequeue_frame(4, 3, timeout=0)  # keeps 1,2,3
    f = buf.dequeue_frame(4, 0, timeout=0)  # no overlap wanted now: 4 new samples
    np.testing.assert_array_equal(f.values[:, 0], [4, 5, 6, 7])


@pytest.mark.parametrize(
    "n,k,msg",
    [(0, 0, "frame size"), (4, 4, "overlap"), (4, -1, "overlap"), (11, 0, "exceeds buffer capacity")],
)
def test_invalid_frame_requests(n: int, k: int, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        RingBuffer(10, 1).dequeue_frame(n, k, timeout=0)


def test_invalid_construction_and_chunks() -> None:
    with pytest.raises(ValueError, match="capacity"):
        RingBuffer(0, 1)
    with pytest.raises(ValueError, match="num_channels"):
        RingBuffer(4, 0)
    with pytest.raises(ValueError, match="unknown overflow policy 'explode'"):
        RingBuffer(4, 1, overflow="explode")
    with pytest.raises(ValueError, match="does not match"):
        RingBuffer(4, 2).enqueue(np.zeros(3), np.zeros((3, 3)))


def test_drop_oldest_counts_reports_and_marks_gap() -> None:
    seen: list[Gap] = []
    buf = RingBuffer(5, 1, overflow=OverflowPolicy.DROP_OLDEST, on_overflow=seen.append)
    buf.enqueue(*counter(0, 5))
    buf.enqueue(*counter(5, 3))  # drops 0,1,2
    assert buf.dropped_samples == 3 and buf.overflow_events == 1
    assert seen and seen[0].count == 3
    assert (seen[0].first_t, seen[0].last_t) == (0.0, 0.02)
    f = buf.dequeue_frame(5, 0, timeout=0)
    np.testing.assert_array_equal(f.values[:, 0], [3, 4, 5, 6, 7])
    assert f.gaps == seen  # the gap marker travels with the next frame
    buf.enqueue(*counter(8, 1))
    assert buf.drain().gaps == []


def test_drop_oldest_uses_published_overlap_first() -> None:
    buf = RingBuffer(5, 1, overflow="drop_oldest")
    buf.enqueue(*counter(0, 5))
    buf.dequeue_frame(3, 2, timeout=0)  # 0,1,2 published; 1,2 kept as overlap; 3,4 unread
    buf.enqueue(*counter(5, 2))  # needs a slot: overlap sample 1 goes, nothing unread is lost
    assert buf.dropped_samples == 0
    frames = frames_of(buf, 3, 2)
    np.testing.assert_array_equal(frames, [[2, 3, 4], [3, 4, 5], [4, 5, 6]])


def test_chunk_larger_than_capacity_with_drop_oldest_keeps_newest() -> None:
    buf = RingBuffer(4, 1, overflow="drop_oldest")
    buf.enqueue(*counter(0, 10))
    assert buf.dropped_samples == 6
    np.testing.assert_array_equal(buf.drain().values[:, 0], [6, 7, 8, 9])


def test_block_policy_waits_for_consumer_and_loses_nothing() -> None:
    events: list[Gap] = []
    buf = RingBuffer(8, 1, overflow="block", on_overflow=events.append)
    total = 500
    got: list[float] = []

    def consume() -> None:
        while True:
            f = buf.dequeue_frame(5, 0, timeout=1.0)
            if f is None:
                rest = buf.drain()
                if rest is not None:
                    got.extend(rest.values[:, 0])
                return
            got.extend(f.values[:, 0])
            time.sleep(0.0005)

    th = threading.Thread(target=consume)
    th.start()
    t, v = counter(0, total)
    for i in range(0, total, 7):
        buf.enqueue(t[i : i + 7], v[i : i + 7])
    buf.close()
    th.join(5)
    np.testing.assert_array_equal(got, np.arange(total, dtype=float))
    assert buf.dropped_samples == 0
    assert buf.overflow_events >= 1 and events, "blocking on a full buffer must be reported"
    assert buf.blocked_seconds > 0


def test_block_policy_timeout_and_close_release_the_producer() -> None:
    buf = RingBuffer(3, 1)
    buf.enqueue(*counter(0, 3))
    with pytest.raises(TimeoutError, match="still full"):
        buf.enqueue(*counter(3, 1), timeout=0.05)
    threading.Timer(0.05, buf.close).start()
    with pytest.raises(BufferClosed):
        buf.enqueue(*counter(3, 1))
    with pytest.raises(BufferClosed):
        buf.enqueue(*counter(3, 1))


def test_dequeue_wakes_on_enqueue_from_another_thread() -> None:
    buf = RingBuffer(16, 1)
    threading.Timer(0.05, lambda: buf.enqueue(*counter(0, 4))).start()
    f = buf.dequeue_frame(4, 0, timeout=2.0)
    assert f is not None and f.num_samples == 4


def test_closed_buffer_returns_none_when_not_enough_for_a_frame() -> None:
    buf = RingBuffer(16, 1)
    buf.enqueue(*counter(0, 3))
    buf.close()
    assert buf.dequeue_frame(4, 0, timeout=1.0) is None
    assert buf.drain().num_samples == 3


def test_string_samples() -> None:
    buf = RingBuffer(4, 1, dtype=object)
    buf.enqueue(np.array([1.0, 2.0]), np.array([["start"], ["stop"]], dtype=object))
    f = buf.dequeue_frame(2, 0, timeout=0)
    assert list(f.values[:, 0]) == ["start", "stop"]


def test_concurrent_producer_consumer_with_overlap_is_exact() -> None:
    """Random chunk sizes from one thread, frames with overlap on another: reference equality."""
    rng = np.random.default_rng(3)
    buf = RingBuffer(32, 2)
    total, n, k = 3000, 10, 4
    frames: list[np.ndarray] = []

    def consume() -> None:
        while (f := buf.dequeue_frame(n, k, timeout=1.0)) is not None:
            frames.append(f.values.copy())

    th = threading.Thread(target=consume)
    th.start()
    t, v = counter(0, total, channels=2)
    i = 0
    while i < total:
        m = int(rng.integers(1, 40))
        buf.enqueue(t[i : i + m], v[i : i + m])
        i += m
    buf.close()
    th.join(5)
    starts = range(0, total - n + 1, n - k)
    assert len(frames) == len(starts)
    for f, s in zip(frames, starts, strict=True):
        np.testing.assert_array_equal(f[:, 0], np.arange(s, s + n))
        np.testing.assert_array_equal(f[:, 1], 2 * np.arange(s, s + n))

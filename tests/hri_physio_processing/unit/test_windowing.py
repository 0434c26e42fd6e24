"""Window accumulator: chunking-independent windows, hop/overlap, gaps, flush."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.processing import random_chunks
from hri_physio_bridge.ring_buffer import Gap
from hri_physio_processing.windowing import ClockJump, Discarded, Window, WindowAccumulator

FS = 10.0


def run(acc: WindowAccumulator, t: np.ndarray, v: np.ndarray, chunks, flush: bool = True) -> list:
    events: list = []
    for a, b in chunks:
        events.extend(acc.push(t[a:b], v[a:b]))
    if flush:
        events.extend(acc.flush())
    return events


def signature(events: list) -> list:
    out = []
    for e in events:
        if isinstance(e, Window):
            out.append(("W", e.index, e.segment, e.first_in_segment, e.final, e.next_start,
                        e.timestamps.tobytes(), e.values.tobytes()))
        else:
            out.append((type(e).__name__, repr(e)))
    return out


@pytest.mark.parametrize("window,hop", [(20, 5), (20, 20), (7, 3), (1, 1)])
def test_windows_do_not_depend_on_chunking(window: int, hop: int) -> None:
    n = 137
    t = 100 + np.arange(n) / FS
    v = np.column_stack([np.arange(n), -np.arange(n)]).astype(float)
    ref = signature(run(WindowAccumulator(window, hop, FS), t, v, [(0, n)]))
    for seed in range(4):
        chunks = random_chunks(n, np.random.default_rng(seed), 1, 30)
        assert signature(run(WindowAccumulator(window, hop, FS), t, v, chunks)) == ref
    single = [(i, i + 1) for i in range(n)]
    assert signature(run(WindowAccumulator(window, hop, FS), t, v, single)) == ref


def test_hop_overlap_timestamps_and_final_window() -> None:
    n = 53
    t = 5 + np.arange(n) / FS
    v = np.arange(n, dtype=float)
    events = run(WindowAccumulator(20, 5, FS), t, v, [(0, n)])
    wins = [e for e in events if isinstance(e, Window)]
    # full windows start at 0, 5, ..., 30; the last 3 samples (50..52) get a final window.
    assert [int(w.values[0, 0]) for w in wins] == [0, 5, 10, 15, 20, 25, 30, 33]
    assert all(w.num_samples == 20 for w in wins)
    for w in wins:
        np.testing.assert_array_equal(w.timestamps, t[w.values[:, 0].astype(int)])  # source stamps kept
    assert [w.final for w in wins] == [False] * 7 + [True]
    assert wins[0].first_in_segment and not any(w.first_in_segment for w in wins[1:])
    assert all(w.next_start == 5 for w in wins[:-1]) and wins[-1].next_start == 20


def test_no_final_window_when_everything_was_covered() -> None:
    t = np.arange(40) / FS
    events = run(WindowAccumulator(20, 10, FS), t, np.zeros(40), [(0, 40)])
    assert [e.final for e in events] == [False, False, False]


def test_gap_cuts_the_stream_into_segments() -> None:
    t = np.concatenate([np.arange(33), np.arange(38, 80)]) / FS  # 5 samples missing after t=3.2
    v = np.arange(t.shape[0], dtype=float)
    chunks = random_chunks(t.shape[0], np.random.default_rng(1), 1, 9)
    events = run(WindowAccumulator(20, 10, FS), t, v, chunks)
    kinds = [type(e).__name__ for e in events]
    gap_at = kinds.index("Gap")
    gap = events[gap_at]
    assert gap.t_before == pytest.approx(3.2) and gap.t_after == pytest.approx(3.8)
    assert gap.count == 5  # the bridge's one Gap type: the missing samples and their estimated times
    assert gap.first_t == pytest.approx(3.3) and gap.last_t == pytest.approx(3.7)
    before = [e for e in events[:gap_at] if isinstance(e, Window)]
    after = [e for e in events[gap_at:] if isinstance(e, Window)]
    assert all(w.t_end <= 3.2 + 1e-9 for w in before)
    assert all(w.t_start >= 3.8 - 1e-9 for w in after)
    # windows [0, 20), [10, 30), then a final one so samples 30..32 are covered too
    assert [(w.values[0, 0], w.values[-1, 0], w.final) for w in before] == [(0, 19, False), (10, 29, False),
                                                                            (13, 32, True)]
    assert after[0].first_in_segment and after[0].segment == before[0].segment + 1
    for w in before + after:  # no window spans the cut: evenly spaced inside
        np.testing.assert_allclose(np.diff(w.timestamps), 1 / FS)


def test_backward_and_duplicate_timestamps_cut_too_as_clock_jumps_not_gaps() -> None:
    t = np.array([0.0, 0.1, 0.2, 0.2, 0.3, 0.1, 0.2])
    events = WindowAccumulator(2, 1, FS).push(t, np.zeros(7))
    assert not [e for e in events if isinstance(e, Gap)]  # nothing is missing
    assert [e for e in events if isinstance(e, ClockJump)] == [ClockJump(0.2, 0.2), ClockJump(0.3, 0.1)]


def test_short_segments_are_discarded_and_reported() -> None:
    t = np.concatenate([np.arange(5), np.arange(100, 130)]) / FS
    acc = WindowAccumulator(20, 10, FS, min_samples=10)
    events = run(acc, t, np.zeros(t.shape[0]), [(0, t.shape[0])])
    assert isinstance(events[0], Discarded) and events[0].samples == 5
    assert isinstance(events[1], Gap)
    assert [e.num_samples for e in events[2:]] == [20, 20]


def test_gap_across_chunk_boundary_and_flush_twice() -> None:
    acc = WindowAccumulator(3, 3, FS)
    assert acc.push(np.array([0.0, 0.1]), np.zeros(2)) == []
    events = acc.push(np.array([0.5, 0.6, 0.7]), np.zeros(3))
    assert isinstance(events[0], Window) and events[0].final and events[0].num_samples == 2
    assert isinstance(events[1], Gap) and events[1].t_before == 0.0 + 0.1
    assert isinstance(events[2], Window) and not events[2].final
    assert acc.flush() == [] and acc.flush() == []


@pytest.mark.parametrize("kwargs,match", [
    ({"window": 0, "hop": 1, "sampling_rate": FS}, "window"),
    ({"window": 5, "hop": 6, "sampling_rate": FS}, "hop"),
    ({"window": 5, "hop": 0, "sampling_rate": FS}, "hop"),
    ({"window": 5, "hop": 1, "sampling_rate": 0.0}, "sampling rate"),
    ({"window": 5, "hop": 1, "sampling_rate": FS, "gap_factor": 1.0}, "gap_factor"),
])
def test_invalid_configuration(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        WindowAccumulator(**kwargs)


def test_shape_errors() -> None:
    acc = WindowAccumulator(4, 2, FS)
    acc.push(np.array([0.0]), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="channel"):
        acc.push(np.array([0.1]), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="timestamps"):
        acc.push(np.array([0.1, 0.2]), np.zeros((3, 2)))


def test_context_carries_preceding_samples_of_the_same_segment() -> None:
    t = np.concatenate([np.arange(47), np.arange(60, 123)]) / FS  # gap after sample 46
    v = np.arange(t.shape[0], dtype=float)
    for seed in range(3):
        chunks = random_chunks(t.shape[0], np.random.default_rng(seed), 1, 13)
        events = run(WindowAccumulator(10, 10, FS, context=4), t, v, chunks)
        wins = [e for e in events if isinstance(e, Window)]
        for w in wins:
            first = int(w.values[0, 0])
            expect = [i for i in range(first - 4, first) if i >= 0 and (first < 47 or i >= 47)]
            assert w.pre_values[:, 0].tolist() == expect  # never across the gap
            np.testing.assert_array_equal(w.pre_timestamps, t[expect])
        final = [w for w in wins if w.final]
        assert [int(w.values[0, 0]) for w in final] == [37, 100]  # final windows get their lead-in too
        assert all(w.pre_values.shape[0] == 4 for w in final)

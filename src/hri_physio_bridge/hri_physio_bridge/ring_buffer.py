"""Fixed-capacity, thread-safe ring buffer of timestamped multi-channel samples.

The producer enqueues chunks of any size; the consumer dequeues frames of N
samples and keeps the last K of them for the next frame (sliding window with
overlap). Overflow is never silent: it is counted, reported through
``on_overflow``, and handled by the configured policy:

* ``block`` - the producer waits until the consumer makes room (nothing lost);
* ``drop_oldest`` - the oldest unread samples are discarded and a :class:`Gap`
  marker describing them is attached to the next dequeued frame.
"""

from __future__ import annotations

import enum
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hri_physio_bridge.frames import Frame, default_channel_names


class OverflowPolicy(enum.Enum):
    BLOCK = "block"
    DROP_OLDEST = "drop_oldest"

    @classmethod
    def parse(cls, value: str | OverflowPolicy) -> OverflowPolicy:
        if isinstance(value, OverflowPolicy):
            return value
        try:
            return cls(str(value).lower())
        except ValueError:
            names = ", ".join(p.value for p in cls)
            raise ValueError(f"unknown overflow policy {value!r}; choose one of: {names}") from None


@dataclass(frozen=True)
class Gap:
    """Samples that are missing from the stream (dropped or never received).

    ``first_t``/``last_t``: the first and last missing sample (estimated when never received);
    ``t_before``/``t_after``: the received samples either side of the hole when known (the
    processor cuts its windows there), None otherwise.
    """

    first_t: float
    last_t: float
    count: int
    reason: str
    t_before: float | None = None
    t_after: float | None = None


@dataclass
class BufferedFrame(Frame):
    """A dequeued frame, how many of its samples are new, and the gaps before them."""

    gaps: list[Gap] = field(default_factory=list)
    fresh: int = 0


class BufferClosed(Exception):
    """The buffer was closed while a producer was waiting for room."""


class RingBuffer:
    def __init__(
        self,
        capacity: int,
        num_channels: int,
        dtype: np.dtype | type | str = np.float64,
        overflow: OverflowPolicy | str = OverflowPolicy.BLOCK,
        channels: tuple[str, ...] = (),
        on_overflow: Callable[[Gap], None] | None = None,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"buffer capacity must be >= 1 sample, got {capacity}")
        if num_channels < 1:
            raise ValueError(f"num_channels must be >= 1, got {num_channels}")
        self.capacity = int(capacity)
        self.num_channels = int(num_channels)
        self.policy = OverflowPolicy.parse(overflow)
        self.channels = tuple(channels) or default_channel_names(num_channels)
        self._t = np.zeros(self.capacity, dtype=np.float64)
        self._v = np.zeros((self.capacity, self.num_channels), dtype=np.dtype(dtype))
        self._head = 0  # index of the oldest stored sample
        self._size = 0  # stored samples, including overlap kept from the last frame
        self._retained = 0  # leading stored samples already published as overlap
        self._cond = threading.Condition()
        self._closed = False
        self._pending_gaps: list[Gap] = []
        self._on_overflow = on_overflow
        self.overflow_events = 0
        self.dropped_samples = 0
        self.blocked_seconds = 0.0
        self.enqueued_samples = 0
        self._blocking = False

    # -- state ---------------------------------------------------------------
    def __len__(self) -> int:
        with self._cond:
            return self._size

    @property
    def unread(self) -> int:
        """Samples not yet published in any frame."""
        with self._cond:
            return self._size - self._retained

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Wake every waiter; enqueue fails afterwards, dequeue drains what is left."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    # -- producer ------------------------------------------------------------
    def enqueue(self, timestamps: np.ndarray, values: np.ndarray, timeout: float | None = None) -> int:
        """Append samples; returns how many were stored.

        With the ``block`` policy a full buffer makes the caller wait for room;
        if ``timeout`` expires or the buffer is closed, :class:`BufferClosed` or
        :class:`TimeoutError` is raised after storing what fitted (the return
        value of a partial call is never lost: the exception says how many).
        """
        timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        values = np.asarray(values)
        if values.ndim == 1:
            values = values.reshape(-1, 1) if self.num_channels == 1 else values.reshape(1, -1)
        if values.shape != (timestamps.shape[0], self.num_channels):
            raise ValueError(
                f"chunk of shape {values.shape} does not match {timestamps.shape[0]} timestamps "
                f"x {self.num_channels} channels"
            )
        n = timestamps.shape[0]
        stored = 0
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            if self._closed:
                raise BufferClosed("buffer is closed")
            while stored < n:
                free = self.capacity - self._size
                if free == 0:
                    if self.policy is OverflowPolicy.DROP_OLDEST:
                        self._drop_oldest(min(n - stored, self.capacity))
                        free = self.capacity - self._size
                    else:
                        self._wait_for_room(deadline, stored)
                        continue
                take = min(free, n - stored)
                self._write(timestamps[stored : stored + take], values[stored : stored + take])
                stored += take
                self._cond.notify_all()
        self.enqueued_samples += stored
        return stored

    def _wait_for_room(self, deadline: float | None, stored: int) -> None:
        if not self._blocking:
            # Report each full-buffer episode once, not every wake-up.
            self._blocking = True
            self.overflow_events += 1
            if self._on_overflow is not None:
                t = float(self._t[(self._head + self._size - 1) % self.capacity])
                self._on_overflow(Gap(t, t, 0, "buffer full: producer blocked until the consumer catches up"))
        start = time.monotonic()
        remaining = None if deadline is None else max(0.0, deadline - start)
        self._cond.wait(timeout=remaining)
        self.blocked_seconds += time.monotonic() - start
        if self._closed:
            raise BufferClosed(f"buffer closed while the producer waited ({stored} samples stored)")
        if deadline is not None and time.monotonic() >= deadline and self._size == self.capacity:
            raise TimeoutError(f"buffer still full after waiting ({stored} samples stored)")

    def _write(self, t: np.ndarray, v: np.ndarray) -> None:
        k = t.shape[0]
        start = (self._head + self._size) % self.capacity
        first = min(k, self.capacity - start)
        self._t[start : start + first] = t[:first]
        self._v[start : start + first] = v[:first]
        if first < k:
            self._t[: k - first] = t[first:]
            self._v[: k - first] = v[first:]
        self._size += k
        self._blocking = False

    def _drop_oldest(self, k: int) -> None:
        """Discard k samples (retained overlap first, then the oldest unread)."""
        k = min(k, self._size)
        from_retained = min(k, self._retained)
        unread_dropped = k - from_retained
        if unread_dropped:
            first = self._head + from_retained
            t_first = float(self._t[first % self.capacity])
            t_last = float(self._t[(first + unread_dropped - 1) % self.capacity])
            gap = Gap(t_first, t_last, unread_dropped, "buffer overflow: oldest samples dropped")
            self._pending_gaps.append(gap)
            self.overflow_events += 1
            self.dropped_samples += unread_dropped
            if self._on_overflow is not None:
                self._on_overflow(gap)
        self._retained -= from_retained
        self._head = (self._head + k) % self.capacity
        self._size -= k

    # -- consumer ------------------------------------------------------------
    def dequeue_frame(self, n: int, overlap: int = 0, timeout: float | None = None) -> BufferedFrame | None:
        """Wait for a frame of ``n`` samples; keep its last ``overlap`` for the next frame.

        The first frame has n new samples; every later frame starts with the
        last ``overlap`` samples of the previous one followed by n - overlap new
        samples. Returns None on timeout, or when the buffer is closed and
        fewer than a frame's worth of new samples remain (see :meth:`drain`).
        """
        if n < 1:
            raise ValueError(f"frame size must be >= 1, got {n}")
        if not 0 <= overlap < n:
            raise ValueError(f"overlap must satisfy 0 <= overlap < frame size ({n}), got {overlap}")
        if n > self.capacity:
            raise ValueError(f"frame size {n} exceeds buffer capacity {self.capacity}")
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while True:
                # Retained overlap from the previous frame counts towards this one,
                # but only as much of it as the caller asked to keep.
                usable_retained = min(self._retained, overlap)
                if self._size - self._retained + usable_retained >= n:
                    break
                if self._closed:
                    return None
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cond.wait(timeout=remaining)
            skip = self._retained - usable_retained
            self._head = (self._head + skip) % self.capacity
            self._size -= skip
            self._retained = usable_retained
            frame = self._read(n)
            frame.fresh = n - usable_retained
            consumed = n - overlap
            self._head = (self._head + consumed) % self.capacity
            self._size -= consumed
            self._retained = overlap
            frame.gaps, self._pending_gaps = self._pending_gaps, []
            self._cond.notify_all()
            return frame

    def drain(self) -> BufferedFrame | None:
        """Everything not yet published, as one (possibly short) frame, or None."""
        with self._cond:
            skip = self._retained
            self._head = (self._head + skip) % self.capacity
            self._size -= skip
            self._retained = 0
            if self._size == 0 and not self._pending_gaps:
                return None
            frame = self._read(self._size)
            frame.fresh = frame.num_samples
            self._head = (self._head + self._size) % self.capacity
            self._size = 0
            frame.gaps, self._pending_gaps = self._pending_gaps, []
            self._cond.notify_all()
            return frame

    def _read(self, n: int) -> BufferedFrame:
        idx = (self._head + np.arange(n)) % self.capacity
        return BufferedFrame(self._t[idx].copy(), self._v[idx].copy(), self.channels)

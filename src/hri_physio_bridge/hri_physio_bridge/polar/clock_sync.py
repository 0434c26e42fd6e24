"""Device time -> host (LSL) time: an online offset + drift estimate, applied without steps.

The sensor's clock is not wall time (an H10 restarts at 2019-01-01 after power-off) and its
crystal drifts (up to +-20 ppm, ~72 ms/h). Each PMD frame gives one observation: the device time
``T`` of its last sample and the host time ``r`` the notification arrived. BLE delivery only adds
delay, so ``r - T`` lies ABOVE the true offset line ``c + b * T``; the estimate is the lower
envelope of those points:

- the points are kept in buckets (``bucket_ns`` of device time, the lowest point of each) over a
  sliding ``window_ns``;
- the line is the lower convex hull edge above the points' mean device time (the line under all
  points that is closest to them on average); its slope (the drift) is clamped to
  ``+-max_drift`` and held at 0 until the points span ``min_span_ns``.

The estimate moves as points arrive; stepping the mapping would make LSL timestamps jump (or run
backwards). So the APPLIED mapping is a continuous piecewise-linear function of device time: at
every observation a new segment starts where the last one ends, with the estimated drift plus a
correction ``error / tau`` limited to ``+-max_slew`` (like an NTP clock slewing). Every device
time mapped so far keeps its host time; the map stays strictly increasing.

The minimum BLE latency itself cannot be observed: mapped times are late by it (a constant of
a few ms; ``latency_ns`` subtracts a known value).
"""

from __future__ import annotations

import bisect
import itertools
from dataclasses import dataclass

NS = 1_000_000_000


@dataclass(frozen=True)
class ClockEstimate:
    offset_ns: int  # host - device at the reference device time
    drift: float  # d(host - device) / d(device): -20e-6 = device 20 ppm fast
    points: int
    span_ns: int


def _cross(o: tuple[int, int], a: tuple[int, int], b: tuple[int, int]) -> int:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def lower_hull(points: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Lower convex hull of points sorted by x (Andrew's monotone chain), exact integer arithmetic."""
    hull: list[tuple[int, int]] = []
    for p in points:
        while len(hull) >= 2 and _cross(hull[-2], hull[-1], p) <= 0:
            hull.pop()
        hull.append(p)
    return hull


class DeviceClockMapper:
    """Maps one device's clock (ns since 2000-01-01) onto the host clock (ns), shared by its streams."""

    def __init__(
        self,
        *,
        bucket_ns: int = 2 * NS,
        window_ns: int = 600 * NS,
        min_span_ns: int = 60 * NS,
        max_drift: float = 500e-6,
        max_slew: float = 2000e-6,
        tau_ns: int = 5 * NS,
        latency_ns: int = 0,
        keep_segments_ns: int = 120 * NS,
    ) -> None:
        self.bucket_ns, self.window_ns, self.min_span_ns = bucket_ns, window_ns, min_span_ns
        self.max_drift, self.max_slew, self.tau_ns = max_drift, max_slew, tau_ns
        self.latency_ns, self.keep_segments_ns = latency_ns, keep_segments_ns
        # Points are (x, y) = (device time - x0, arrival - device time - y0): small exact ints.
        self._x0: int | None = None
        self._y0 = 0
        self._buckets: dict[int, tuple[int, int]] = {}  # bucket -> the point with the lowest y
        self._keys: list[int] = []
        self._estimate: tuple[float, float] | None = None  # (intercept at x = 0 relative to y0, slope)
        # Applied mapping: segments starting at device time T_a with offset (host - device, ns) and rate.
        self._seg_t: list[int] = []
        self._seg: list[tuple[int, float]] = []
        self.observations = 0

    # -- estimate -------------------------------------------------------------------------------
    def observe(self, device_ns: int, arrival_ns: int) -> None:
        """One frame: its last sample's device time and the host time its notification arrived."""
        if self._x0 is None:
            self._x0 = device_ns
            self._y0 = arrival_ns - self.latency_ns - device_ns
        x = device_ns - self._x0
        y = arrival_ns - self.latency_ns - device_ns - self._y0
        self.observations += 1
        key = x // self.bucket_ns
        old = self._buckets.get(key)
        changed = old is None or y < old[1]
        if old is None:
            bisect.insort(self._keys, key)
        if changed:
            self._buckets[key] = (x, y)
        newest = self._keys[-1]
        limit = newest - self.window_ns // self.bucket_ns
        while self._keys and self._keys[0] < limit:
            del self._buckets[self._keys.pop(0)]
            changed = True
        if changed or self._estimate is None:
            self._estimate = self._fit()
        self._slew(device_ns)

    def _fit(self) -> tuple[float, float]:
        points = [self._buckets[k] for k in self._keys]
        span = points[-1][0] - points[0][0]
        slope = 0.0
        if len(points) >= 2 and span >= self.min_span_ns:
            hull = lower_hull(points)
            mean_x = sum(p[0] for p in points) / len(points)
            slope = (hull[-1][1] - hull[0][1]) / max(1, hull[-1][0] - hull[0][0])
            for a, b in itertools.pairwise(hull):
                if a[0] <= mean_x <= b[0]:
                    slope = (b[1] - a[1]) / (b[0] - a[0])
                    break
            slope = max(-self.max_drift, min(self.max_drift, slope))
        intercept = min(y - slope * x for x, y in points)
        return intercept, slope

    def estimate(self) -> ClockEstimate | None:
        if self._estimate is None or self._x0 is None:
            return None
        c, b = self._estimate
        points = [self._buckets[k] for k in self._keys]
        return ClockEstimate(self._y0 + round(c), b, len(points), points[-1][0] - points[0][0])

    def _target(self, device_ns: int) -> int:
        """The estimated offset (host - device, ns) at ``device_ns``."""
        assert self._estimate is not None and self._x0 is not None
        c, b = self._estimate
        return self._y0 + round(c + b * (device_ns - self._x0))

    # -- applied mapping --------------------------------------------------------------------------
    def _slew(self, device_ns: int) -> None:
        target = self._target(device_ns)
        if not self._seg_t:
            self._seg_t.append(device_ns)
            self._seg.append((target, self._estimate[1] if self._estimate else 0.0))
            return
        if device_ns <= self._seg_t[-1]:
            return  # an older frame of another stream: times up to the newest anchor are fixed
        current = self._offset(device_ns)
        error = target - current
        correction = max(-self.max_slew, min(self.max_slew, error / self.tau_ns))
        assert self._estimate is not None
        rate = self._estimate[1] + correction
        self._seg_t.append(device_ns)
        self._seg.append((current, rate))
        while len(self._seg_t) > 2 and self._seg_t[1] < device_ns - self.keep_segments_ns:
            self._seg_t.pop(0)
            self._seg.pop(0)

    def _offset(self, device_ns: int) -> int:
        i = max(0, bisect.bisect_right(self._seg_t, device_ns) - 1)
        start = self._seg_t[i]
        offset, rate = self._seg[i]
        return offset + round(rate * (device_ns - start))

    @property
    def ready(self) -> bool:
        return bool(self._seg_t)

    def to_host(self, device_ns: int) -> int:
        """Host time (ns) of a device time, on the applied (continuous, increasing) mapping."""
        if not self._seg_t:
            raise RuntimeError("no observation yet: call observe() first")
        return device_ns + self._offset(device_ns)

    def to_host_many(self, device_ns: list[int]) -> list[int]:
        return [self.to_host(t) for t in device_ns]

    @property
    def drift_estimated(self) -> bool:
        """Whether the points span enough device time for a drift estimate (before: drift held at 0)."""
        if len(self._keys) < 2:
            return False
        return self._buckets[self._keys[-1]][0] - self._buckets[self._keys[0]][0] >= self.min_span_ns

    @property
    def drift_ppm(self) -> float:
        return (self._estimate[1] if self._estimate else 0.0) * 1e6

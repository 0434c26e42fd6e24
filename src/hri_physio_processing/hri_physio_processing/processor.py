"""The NeuroKit2 processor's logic: frames in, feature frames and status out (no rclpy, no clock).

Per window (see :mod:`windowing`) it publishes

* one-sample frames ``[t_end, value]`` for every scalar feature, stamped with the window's
  last sample time, NaN when invalid;
* the cleaned signal and the peak mask for the window's *new part* only, so that the frames
  of successive windows join into one continuous stream with every beat exactly once;
* per-beat rate (ECG/PPG) at each newly published beat;
* a status dict (``t`` = window end) with the window's extent, flags and NaN reasons.

The part a window publishes ends ``edge_guard_seconds`` before its end (filters and peak
detection are least reliable at the edges; the next window sees that stretch in its
interior), moved to the middle of the RR interval it falls in, so that a peak found one
sample earlier or later by the next window cannot cross the boundary. Peaks within
``dedup_seconds`` of the last published one are dropped as duplicates. When windows overlap
by less than two guards (down to windows that just meet, hop = window), the cleaned signal
and peaks are taken from a second NeuroKit2 pass over the window plus a lead-in of two guards
of preceding samples, so the held-back stretch is in the interior of the next window's pass;
the scalar features are always computed on the window alone.

Frequency-domain HRV (LF, HF, LF/HF) needs 1 to 5 min of beats, longer than the default 60 s
window. With ``hrv_window_seconds`` > 0 it is computed from the beats already published (each
beat once, by source time; after each window's artefact step, so corrected beats are corrected
once) over the last ``hrv_window_seconds`` of clean signal ending at the window's published end,
and stamped with that end: no second peak detection or correction. The beat series restarts at a
gap, a clock jump, a flagged window (no beats are trusted there) or a window whose beats are unfit
for HRV (a beat-free stretch, too many artefacts), so HF appears 1 min, LF 2 min and LF/HF 5 min
after the last restart.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hri_physio_bridge.frames import Frame
from hri_physio_processing import hrv
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import (
    FREQUENCY_SCALARS,
    PEAKS_FEATURE,
    SCALARS,
    SIGNAL_FEATURES,
    WindowResult,
    detect,
    extract,
    hrv_frequency_of_beats,
)
from hri_physio_processing.windowing import ClockJump, Discarded, Gap, Window, WindowAccumulator


@dataclass(frozen=True)
class FrameOutput:
    """A frame for ``<output_prefix>/<feature>``."""

    feature: str
    frame: Frame


@dataclass(frozen=True)
class StatusOutput:
    """A JSON-able status object for ``<output_prefix>/status`` (always has ``t``)."""

    payload: dict[str, Any]


Output = FrameOutput | StatusOutput


@dataclass(frozen=True)
class _View:
    """What a window publishes from: timestamps, cleaned signal and peaks; ``offset`` samples of
    lead-in (before the window proper) come first."""

    t: np.ndarray
    clean: np.ndarray
    peaks: np.ndarray
    offset: int


@dataclass
class ProcessorStats:
    windows: int = 0
    flagged_windows: int = 0
    inverted_windows: int = 0  # ECG/PPG windows turned over before peak detection (polarity)
    published_peaks: int = 0
    duplicate_peaks: int = 0
    gaps: int = 0
    missing_samples: int = 0  # estimated, in the gaps
    clock_jumps: int = 0  # duplicate or backward time steps
    discarded_samples: int = 0
    bad_timestamp_samples: int = 0  # dropped: their timestamp was NaN or infinite
    samples_in: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class _Pending:
    """Discontinuities not yet reported (reported at most once per hop): the totals at the last
    report, and when the first and last unreported ones happened."""

    reported: ProcessorStats
    t_first: float = math.nan
    t_last: float = math.nan
    examples: list[str] = field(default_factory=list)


class NeurokitProcessor:
    """Windows a stream and turns each window into feature outputs."""

    def __init__(self, cfg: ProcessorConfig) -> None:
        self.cfg = cfg
        self.fs = float(cfg.sampling_rate)
        self.settings = cfg.features
        overlap = cfg.window_samples - cfg.hop_samples
        guard = round(cfg.edge_guard_seconds * self.fs)
        # Windows that overlap by less than two guards get a lead-in of two guards for peak
        # detection, so the stretch each window holds back is inside the next one's view.
        self.context = 2 * guard if overlap < 2 * guard else 0
        self.guard = min(guard, (overlap + self.context) // 2)
        self.acc = WindowAccumulator(
            cfg.window_samples, cfg.hop_samples, self.fs, cfg.gap_factor,
            min_samples=max(2, round(cfg.min_window_seconds * self.fs)), context=self.context,
        )
        self.dedup = cfg.mode_default("dedup_seconds")
        self.peaks_feature = PEAKS_FEATURE[cfg.mode]
        self.stats = ProcessorStats()
        self._boundary: float | None = None  # last published sample time (this segment)
        self._last_peak: float | None = None  # last published peak time (this segment)
        self._pending = _Pending(replace(self.stats))
        self._last_event_t: float | None = None
        # The last window of the segment if it kept an unpublished tail (it was not final).
        self._open: _View | None = None
        # Long-window HRV: published beat times since the clean beat series (re)started.
        self.hrv_window = float(cfg.hrv_window_seconds) if "lf" in SCALARS[cfg.mode] else 0.0
        self._beats: list[float] = []
        self._clean_since: float | None = None

    # -- public API ------------------------------------------------------------
    def push(self, frame: Frame) -> list[Output]:
        """Take the next chunk of the input stream."""
        if frame.num_samples == 0:
            return []
        if frame.num_channels <= self.cfg.channel:
            raise ValueError(
                f"input frame has {frame.num_channels} channel(s); channel {self.cfg.channel} was asked for"
            )
        self.stats.samples_in += frame.num_samples
        t = frame.timestamps
        values = np.asarray(frame.values[:, self.cfg.channel], dtype=np.float64)
        finite = np.isfinite(t)
        if finite.all():
            return self._handle(self.acc.push(t, values))
        out = self._drop_bad_timestamps(t, finite)
        return out + self._handle(self.acc.push(t[finite], values[finite]))

    def finish(self) -> list[Output]:
        """The input ended: process what is left and report anything pending."""
        out = self._handle(self.acc.flush())
        out.extend(self._close_segment())
        out.extend(self._report_pending())
        return out

    # -- events ----------------------------------------------------------------
    def _handle(self, events: list) -> list[Output]:
        out: list[Output] = []
        for ev in events:
            if isinstance(ev, Window):
                out.extend(self._report_pending())
                out.extend(self._window(ev))
            elif isinstance(ev, Gap | ClockJump):
                out.extend(self._cut(ev))
            elif isinstance(ev, Discarded):
                self.stats.discarded_samples += ev.samples
                self._note(self._pending, ev.t_start, ev.t_end,
                           f"{ev.samples} sample(s) {ev.t_start:.6f}..{ev.t_end:.6f}")
                out.extend(self._maybe_report(ev.t_end))
        return out

    def _cut(self, ev: Gap | ClockJump) -> list[Output]:
        """The stream is cut at a gap or a clock jump: close the segment, note it for the report."""
        out = self._close_segment()
        p = self._pending
        t_before, t_after = float(ev.t_before), float(ev.t_after)
        if isinstance(ev, Gap):
            self.stats.gaps += 1
            self.stats.missing_samples += ev.count
            kind = "gap"
        else:
            self.stats.clock_jumps += 1
            kind = "backward"
        self._note(p, t_before, t_after,
                   f"{kind} {t_before:.6f} -> {t_after:.6f} ({t_after - t_before:+.4g} s)")
        self._boundary = self._last_peak = None  # a new segment starts
        self._restart_beats()
        out.extend(self._maybe_report(t_after))
        return out

    def _drop_bad_timestamps(self, t: np.ndarray, finite: np.ndarray) -> list[Output]:
        """Samples whose timestamp is NaN or infinite have no place in a window: dropped, counted, and
        reported with the discontinuities (at the nearest good time; before any, only counted)."""
        bad = int((~finite).sum())
        self.stats.bad_timestamp_samples += bad
        good = t[finite]
        near = float(good[0]) if good.size else self.acc.last_timestamp
        if near is None:
            return []
        self._note(self._pending, near, near,
                   f"{bad} sample(s) with a NaN or infinite timestamp near {near:.6f}")
        return self._maybe_report(near)

    @staticmethod
    def _note(p: _Pending, t0: float, t1: float, example: str) -> None:
        if math.isnan(p.t_first):
            p.t_first = t0
        p.t_last = t1
        if len(p.examples) < 3:
            p.examples.append(example)

    def _maybe_report(self, t: float) -> list[Output]:
        """Report gaps/discards now unless one was reported less than a hop ago (source time)."""
        if self._last_event_t is not None and t - self._last_event_t < self.cfg.hop_seconds:
            return []
        return self._report_pending()

    def _report_pending(self) -> list[Output]:
        p, now = self._pending, self.stats
        gaps, missing = now.gaps - p.reported.gaps, now.missing_samples - p.reported.missing_samples
        backward = now.clock_jumps - p.reported.clock_jumps
        discarded = now.discarded_samples - p.reported.discarded_samples
        bad_times = now.bad_timestamp_samples - p.reported.bad_timestamp_samples
        if not (gaps or backward or discarded or bad_times) or math.isnan(p.t_last):
            return []
        self._last_event_t = p.t_last
        reasons = []
        cuts = gaps + backward
        if cuts:
            reasons.append(
                f"{cuts} timestamp discontinuit{'y' if cuts == 1 else 'ies'} "
                f"({gaps} gap(s), about {missing} missing sample(s); {backward} "
                "duplicate or backward step(s)); windows restart after each"
            )
        if discarded:
            reasons.append(
                f"{discarded} sample(s) not processed: their stretch between discontinuities is shorter "
                f"than min_window_seconds ({self.cfg.min_window_seconds:g} s)"
            )
        if bad_times:
            reasons.append(f"{bad_times} sample(s) dropped: their timestamp is NaN or infinite")
        # Since the start, as one report (a hop's worth) may hold only a few of a stream's cuts.
        if now.gaps + now.clock_jumps >= 10 and discarded:
            if now.clock_jumps and now.missing_samples <= 3 * now.gaps:  # small steps both ways: jitter
                reasons.append("timestamps step a few samples forward and back: does the source stamp "
                               "each chunk when it arrives? The receiver can smooth them (its input "
                               "lsl:<stream>?dejitter=1)")
            else:
                reasons.append("timestamps keep jumping: is sampling_rate "
                               f"({self.fs:g} Hz) right for this stream?")
        payload = {
            "t": p.t_last, "event": "discontinuity", "mode": self.cfg.mode, "ok": False,
            "gaps": gaps, "missing_samples": missing, "backward_steps": backward,
            "discarded_samples": discarded, "bad_timestamp_samples": bad_times,
            "t_first": p.t_first, "t_last": p.t_last,
            "examples": p.examples, "reason": "; ".join(reasons),
        }
        self._pending = _Pending(replace(now))
        return [StatusOutput(payload)]

    # -- one window ------------------------------------------------------------
    def _window(self, w: Window) -> list[Output]:
        res = extract(w.timestamps, w.values[:, 0], self.settings)
        self.stats.windows += 1
        self.stats.flagged_windows += not res.ok
        self.stats.inverted_windows += res.inverted
        if res.polarity_clear and res.inverted != self.settings.ecg_inverted_when_unclear:
            # A strap keeps its polarity: a window that cannot tell (noise) takes the last clear one.
            self.settings = replace(self.settings, ecg_inverted_when_unclear=res.inverted)
        view = self._view(w, res)
        start = self._region_start(view)
        end = self._region_end(w, view, start)
        out, peaks, dups = self._publish_region(view, start, end)
        self._open = None if w.final or end == view.t.shape[0] else view
        t_end = w.t_end
        hrv = self._long_window_hrv(view, start, end, res) if self.hrv_window > 0 else None
        for name in SCALARS[self.cfg.mode]:
            value = res.scalars[name]
            stamp = hrv["t_end"] if hrv is not None and name in FREQUENCY_SCALARS else t_end
            out.append(FrameOutput(name, Frame(np.array([stamp]), np.array([[value]]), (name,))))
        status = self._status(w, res, view, start, end, peaks, dups)
        if hrv is not None:
            status["hrv_window"] = hrv
        out.append(StatusOutput(status))
        return out

    # -- long-window frequency-domain HRV ----------------------------------------
    def _restart_beats(self) -> None:
        self._beats.clear()
        self._clean_since = None

    def _long_window_hrv(self, view: _View, start: int, end: int,
                         res: WindowResult) -> dict[str, Any] | None:
        """Track the published beats; LF, HF, LF/HF of the last ``hrv_window`` s of them into ``res``.

        Returns the long window's extent (None when nothing has been published in this segment).
        """
        if end > start:
            if res.ok and res.hrv_reason is None:
                if self._clean_since is None:
                    self._clean_since = float(view.t[start])
                self._beats.extend(self._nn_times(view, res, start, end))
            else:  # a flagged stretch, or beats unfit for HRV: the series restarts after it
                self._restart_beats()
        if self._boundary is None:
            return None
        t_end = self._boundary
        if self._clean_since is None:
            return {"t_start": None, "t_end": t_end, "seconds": 0.0, "beats": 0}
        seconds = min(self.hrv_window, t_end - self._clean_since)
        t_start = t_end - seconds
        first = bisect.bisect_left(self._beats, t_start)
        del self._beats[:first]  # older beats never fall inside a later long window
        beats = np.asarray(self._beats)
        if res.ok:
            values, reasons = hrv_frequency_of_beats(beats, seconds, self.settings.max_beat_gap_seconds,
                                                     cleaned=True, spectrum=self.settings.hrv_spectrum)
            for key in FREQUENCY_SCALARS:
                res.scalars[key] = values[key]
                if key in reasons:
                    res.nan_reasons[key] = reasons[key]
                else:
                    res.nan_reasons.pop(key, None)
        return {"t_start": t_start, "t_end": t_end, "seconds": seconds, "beats": int(beats.shape[0])}

    def _nn_times(self, view: _View, res: WindowResult, start: int, end: int) -> list[float]:
        """Source times of the window's artefact-corrected beats in the published part [start, end) of
        the view (each beat once: the published parts tile the stream)."""
        if res.nn_beats is None or not res.nn_beats.shape[0]:
            return []
        pos = res.nn_beats + view.offset  # window samples -> view samples
        pos = pos[(pos >= start - 0.5) & (pos < end - 0.5)]
        times = np.interp(pos, np.arange(view.t.shape[0]), view.t)
        out: list[float] = []
        last = self._beats[-1] if self._beats else -math.inf
        for t in times:
            if t - last >= self.dedup:
                out.append(float(t))
                last = t
        return out

    def _view(self, w: Window, res: WindowResult) -> _View:
        """Signal and peaks to publish from: the window itself, or the window plus its lead-in."""
        lead = w.pre_timestamps.shape[0]
        if not (self.context and lead and res.ok):
            return _View(w.timestamps, res.clean, res.peaks, 0)
        x = np.concatenate([w.pre_values[:, 0], w.values[:, 0]])
        try:
            clean, peaks = detect(x, self.settings, inverted=res.inverted)
        except Exception:  # the window itself was fine; keep its own result
            return _View(w.timestamps, res.clean, res.peaks, 0)
        return _View(np.concatenate([w.pre_timestamps, w.timestamps]), clean, peaks, lead)

    def _close_segment(self) -> list[Output]:
        """The segment ended after a non-final window: publish that window's held-back tail."""
        if self._open is None:
            return []
        view = self._open
        self._open = None
        out, _, _ = self._publish_region(view, self._region_start(view), view.t.shape[0])
        return out

    def _region_start(self, view: _View) -> int:
        if self._boundary is None:
            return view.offset
        return int(np.searchsorted(view.t, self._boundary, side="right"))

    def _publish_region(self, view: _View, start: int, end: int) -> tuple[list[Output], np.ndarray, int]:
        """Signal, peak mask and per-beat rate for samples [start, end) of the view."""
        t = view.t
        peaks, dups = self._new_peaks(t, view.peaks, start, end)
        out: list[Output] = []
        if end > start:
            ts = t[start:end]
            out.append(FrameOutput("clean", Frame(ts, view.clean[start:end].reshape(-1, 1), ("clean",))))
            mask = np.zeros(end - start)
            mask[peaks - start] = 1.0
            out.append(FrameOutput(self.peaks_feature, Frame(ts, mask.reshape(-1, 1), (self.peaks_feature,))))
            self._boundary = float(t[end - 1])
        if "beat_hr" in SIGNAL_FEATURES[self.cfg.mode] and peaks.shape[0]:
            beat_t, beat_hr = self._beat_rates(t, view.peaks, peaks)
            if beat_t.shape[0]:
                out.append(FrameOutput("beat_hr", Frame(beat_t, beat_hr.reshape(-1, 1), ("beat_hr",))))
        if peaks.shape[0]:
            self._last_peak = float(t[peaks[-1]])
        self.stats.published_peaks += int(peaks.shape[0])
        self.stats.duplicate_peaks += dups
        return out, peaks, dups

    def _region_end(self, w: Window, view: _View, start: int) -> int:
        """Exclusive end (view index) of the part to publish now (see the module docstring)."""
        n = view.t.shape[0]
        if w.final:
            return n
        # The next window (with its lead-in) starts here: the boundary must not fall before it.
        first_next = view.offset + w.next_start - self.context
        nominal = n - self.guard
        end = nominal
        peaks = view.peaks
        i = int(np.searchsorted(peaks, nominal))
        if 0 < i < peaks.shape[0]:
            mid = int((peaks[i - 1] + peaks[i]) // 2) + 1
            if first_next <= mid <= n:
                end = mid
        return max(end, start, min(first_next, n))

    def _new_peaks(self, t: np.ndarray, peaks: np.ndarray, start: int, end: int) -> tuple[np.ndarray, int]:
        p = peaks[(peaks >= start) & (peaks < end)]
        if not p.shape[0]:
            return p, 0
        keep = np.ones(p.shape[0], dtype=bool)
        last = self._last_peak
        for k, idx in enumerate(p):
            if last is not None and t[idx] - last < self.dedup:
                keep[k] = False
            else:
                last = float(t[idx])
        return p[keep], int((~keep).sum())

    def _beat_rates(
        self, t: np.ndarray, all_peaks: np.ndarray, new: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rate at each new beat from the interval to the previous beat found in this window."""
        pos = np.searchsorted(all_peaks, new)
        has_prev = pos > 0
        cur = new[has_prev]
        prev = all_peaks[pos[has_prev] - 1]
        return t[cur], 60.0 * self.fs / (cur - prev).astype(np.float64)

    def _status(self, w: Window, res: WindowResult, view: _View, start: int, end: int, peaks: np.ndarray,
                dups: int) -> dict[str, Any]:
        t = view.t
        status: dict[str, Any] = {
            "t": w.t_end,
            "event": "window",
            "mode": self.cfg.mode,
            "ok": res.ok,
            "window": {
                "index": w.index, "segment": w.segment, "t_start": w.t_start, "t_end": w.t_end,
                "samples": w.num_samples, "seconds": w.num_samples / self.fs, "final": w.final,
            },
            "flags": [{"code": f.code, "reason": f.reason} for f in res.flags],
            "nan": dict(res.nan_reasons),
            "features": {k: (v if math.isfinite(v) else None) for k, v in res.scalars.items()},
            "peaks_in_window": int(res.peaks.shape[0]),
            "beats": dict(res.beats),
            **({"inverted": res.inverted} if self.cfg.mode in ("ecg", "ppg") else {}),
            **({"hrv_method": hrv.METHODS[self.settings.hrv_spectrum]} if "lf" in SCALARS[self.cfg.mode]
               else {}),
            "peaks_published": int(peaks.shape[0]),
            "duplicates_dropped": dups,
            "lead_in_samples": view.offset,
        }
        if end > start:
            status["published"] = {"t_start": float(t[start]), "t_end": float(t[end - 1]),
                                   "samples": end - start}
        return status

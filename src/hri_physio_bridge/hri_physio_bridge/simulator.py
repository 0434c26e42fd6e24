"""Simulated physiological signals (NeuroKit2) as exactly-timed sample sources.

Plain logic, no rclpy and no pylsl; time comes in as an argument or an injected clock.

* A :class:`SampleSource` hands out consecutive blocks of one stream; sample ``i`` is
  stamped ``t0 + i / rate`` exactly. It is finite (``seconds``) or continuous
  (``seconds == 0``: runs until the caller stops asking).
* Continuous NeuroKit2 signals are generated in segments (``segment_seconds`` each,
  seed ``seed + k`` for segment ``k``). Each new segment is spliced onto the previous one
  where the two match best (a window of about one beat / breath is compared), then
  cross-faded over that window, so the rhythm and the level carry on without a step.
  Remaining joint artefact: EDA's tonic level and drift restart each segment (the
  cross-fade turns that into a slope over a few seconds), and SCR / EMG burst counts
  apply per segment.
* The HR stream (1 Hz) reports what a Polar strap would: the mean heart rate of the
  simulated ECG over the last few seconds (R-peaks found with NeuroKit2), in whole bpm;
  the configured bpm until enough beats exist.
* :class:`Pacer` decides which chunks are due at a given time and :func:`run_paced`
  streams them in real time on an injected clock and sleep.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
from pydantic import field_validator, model_validator

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_bridge.streamers.base import StreamSpec

SIGNALS = ("ecg", "ppg", "eda", "emg", "rsp", "ramp", "hr")
DEFAULT_SIGNALS = ("ecg", "hr")
NEUROKIT_SIGNALS = frozenset({"ecg", "ppg", "eda", "emg", "rsp", "hr"})  # hr is derived from ECG
HR_RATE = 1.0
#: Finite runs up to this long are generated in one piece (no joints), like the seed did.
SINGLE_SEGMENT_MAX_SECONDS = 600.0
MIN_NEUROKIT_RATE = 20.0
#: Shorter runs are cut from a simulation this long (NeuroKit2's events need room).
MIN_SIMULATION_SECONDS = 10
MAX_RATE = 5000.0


@dataclass(frozen=True)
class StreamLayout:
    """How one signal appears on LSL: ``<family>/<device-id>/<kind>``."""

    family: str
    kind: str
    unit: str


#: Names follow DESIGN.md so the rest of the system cannot tell the simulator from a Polar
#: strap. ECG is float64 in millivolts (NeuroKit2's unit; a real H10 sends integer microvolts).
STREAMS: dict[str, StreamLayout] = {
    "ecg": StreamLayout("PolarH10", "ECG", "mV"),
    "hr": StreamLayout("PolarH10", "HR", "bpm"),
    "ppg": StreamLayout("PolarOH1", "PPG", "a.u."),
    "eda": StreamLayout("NeuroKitSim", "EDA", "uS"),
    "emg": StreamLayout("NeuroKitSim", "EMG", "mV"),
    "rsp": StreamLayout("NeuroKitSim", "RSP", "a.u."),
    "ramp": StreamLayout("NeuroKitSim", "RAMP", "sample index"),
}


class SimulatorConfig(NodeConfig):
    """Every option of the simulator, declared once: the seed simulator's flags plus streaming options.

    ``seconds 0`` and ``continuous`` say the same thing (stream until stopped); each sets the other.
    """

    SEED_KEYS: ClassVar[tuple[str, ...]] = (
        "seconds", "rate", "noise", "bpm", "scr", "drift", "bnum", "bdur", "resp", "seed",
    )

    seconds: float = option(60.0, "length of the simulated session (0 = until stopped)", unit="s", ge=0)
    continuous: bool = option(False, "stream until stopped (the same as seconds 0)", switch=True)
    rate: float = option(130.0, "sampling rate of every stream but HR (1 Hz); 130 Hz is the Polar H10 "
                         "ECG rate", unit="Hz", gt=0, le=MAX_RATE)
    noise: float = option(0.01, "noise amplitude", ge=0)
    bpm: float = option(70.0, "heart rate of the ECG, HR and PPG", unit="bpm", ge=20, le=250)
    scr: int = option(3, "skin conductance responses per simulated segment (EDA)", ge=0)
    drift: float = option(-0.01, "EDA linear drift", unit="per s")
    bnum: int = option(3, "EMG bursts per simulated segment", ge=0)
    bdur: float = option(1.0, "EMG burst duration", unit="s", gt=0)
    resp: float = option(15.0, "breathing rate (RSP)", unit="breaths/min", ge=1, le=60)
    seed: int = option(42, "random seed (segment k of a continuous run uses seed + k)", ge=0)
    segment_seconds: float = option(60.0, "continuous or long runs: length of each generated segment",
                                    unit="s", ge=20)
    signals: list[str] = option(list(DEFAULT_SIGNALS),
                                f"streams to send, a comma list from {','.join(SIGNALS)}")
    device_id: str = option("SIM0001", "device id in the stream names (a word without '/')")
    name_prefix: str = option("", "prefix for every stream name, e.g. for test isolation")
    chunk: int = option(0, "samples per push (0 = about 0.1 s, 13 at 130 Hz); HR sends one at a time",
                        unit="samples", ge=0)
    wait_for_consumers: float = option(0.0, "wait up to this long for an inlet on every stream before "
                                       "streaming (0 = no wait)", unit="s", ge=0)

    @field_validator("signals")
    @classmethod
    def _signals(cls, value: list[str]) -> list[str]:
        return list(parse_signals(value))

    @field_validator("device_id")
    @classmethod
    def _device_id(cls, value: str) -> str:
        value = value.strip()
        if not value or "/" in value or any(c.isspace() for c in value):
            raise ValueError("expected a non-empty word without '/' or spaces")
        return value

    @field_validator("name_prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        return value.strip().strip("/")

    @model_validator(mode="after")
    def _consistent(self) -> SimulatorConfig:
        if self.continuous or self.seconds == 0:  # frozen: keep the two spellings in step
            object.__setattr__(self, "continuous", True)
            object.__setattr__(self, "seconds", 0.0)
        if self.rate < MIN_NEUROKIT_RATE and NEUROKIT_SIGNALS.intersection(self.signals):
            raise ValueError(f"rate: must be >= {MIN_NEUROKIT_RATE:g} Hz for NeuroKit2 signals "
                             f"({', '.join(sorted(NEUROKIT_SIGNALS.intersection(self.signals)))}), "
                             f"got {self.rate:g}")
        if "emg" in self.signals and self.bnum * self.bdur >= self.generated_seconds:
            raise ValueError(f"bnum, bdur: {self.bnum} EMG bursts of {self.bdur:g} s do not fit in "
                             f"{self.generated_seconds:g} s of simulated EMG")
        return self

    @property
    def generated_seconds(self) -> float:
        """Length of one NeuroKit2 simulation (a finite run, or one continuous segment)."""
        if self.continuous or self.seconds > SINGLE_SEGMENT_MAX_SECONDS:
            return self.segment_seconds
        return max(math.ceil(self.seconds), MIN_SIMULATION_SECONDS)

    @property
    def fs(self) -> int:
        """NeuroKit2 generates at a whole rate; timestamps still use ``rate`` exactly."""
        return max(1, round(self.rate))

    @property
    def chunk_samples(self) -> int:
        return self.chunk or max(1, round(self.rate * 0.1))


def parse_signals(value: Any) -> tuple[str, ...]:
    """``"ecg,hr"`` or ``["ecg", "hr"]`` -> ``("ecg", "hr")``; unknown names are an error."""
    items = value.split(",") if isinstance(value, str) else value
    if not isinstance(items, Sequence):
        raise ValueError(f"signals must be a comma list, got {value!r}")
    names = [str(s).strip().lower() for s in items if str(s).strip()]
    bad = [s for s in names if s not in SIGNALS]
    if bad:
        raise ValueError(f"unknown signal(s) {', '.join(bad)}; choose from {', '.join(SIGNALS)}")
    if not names:
        raise ValueError(f"no signal chosen; choose from {', '.join(SIGNALS)}")
    return tuple(dict.fromkeys(names))  # keep order, drop repeats


def stream_rate(signal: str, cfg: SimulatorConfig) -> float:
    return HR_RATE if signal == "hr" else cfg.rate


def stream_name(signal: str, device_id: str, prefix: str = "") -> str:
    layout = STREAMS[signal]
    prefix = prefix.strip("/")
    return f"{prefix + '/' if prefix else ''}{layout.family}/{device_id}/{layout.kind}"


def stream_spec(signal: str, cfg: SimulatorConfig, device_id: str, prefix: str = "") -> StreamSpec:
    """What the simulator declares for ``signal``: one float64 channel labelled by kind."""
    layout = STREAMS[signal]
    return StreamSpec(
        name=stream_name(signal, device_id, prefix),
        type=layout.kind,
        channel_count=1,
        nominal_rate=stream_rate(signal, cfg),
        dtype="float64",
        source_id=f"{device_id}-{layout.kind}",
        channels=(layout.kind,),
    )


# -- signal generation ------------------------------------------------------------------


def _neurokit() -> Any:
    """NeuroKit2, imported on first use: it takes ~2 s, and --help or a bad flag should not wait."""
    import neurokit2

    return neurokit2


def neurokit_segment(signal: str, cfg: SimulatorConfig, n: int, seed: int) -> np.ndarray:
    """``n`` samples of one NeuroKit2 signal at ``cfg.fs`` Hz."""
    nk = _neurokit()
    fs = cfg.fs
    duration = max(math.ceil(n / fs), MIN_SIMULATION_SECONDS)  # NeuroKit2 wants whole seconds
    if signal == "emg" and cfg.bnum * cfg.bdur >= duration:
        raise ValueError(f"{cfg.bnum} EMG bursts of {cfg.bdur:g} s do not fit in {duration} s")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # NeuroKit2 warns about low rates / short signals
        if signal in ("ecg", "hr"):
            x = nk.ecg_simulate(duration=duration, sampling_rate=fs, noise=cfg.noise,
                                heart_rate=cfg.bpm, method="ecgsyn", random_state=seed)
        elif signal == "ppg":
            x = nk.ppg_simulate(duration=duration, sampling_rate=fs, heart_rate=cfg.bpm,
                                motion_amplitude=cfg.noise, random_state=seed)
        elif signal == "eda":
            x = nk.eda_simulate(duration=duration, sampling_rate=fs, noise=cfg.noise,
                                scr_number=cfg.scr, drift=cfg.drift, random_state=seed)
        elif signal == "emg":
            x = nk.emg_simulate(duration=duration, sampling_rate=fs, noise=cfg.noise,
                                burst_number=cfg.bnum, burst_duration=cfg.bdur, random_state=seed)
        elif signal == "rsp":
            x = nk.rsp_simulate(duration=duration, sampling_rate=fs, noise=cfg.noise,
                                respiratory_rate=cfg.resp, random_state=seed)
        else:
            raise ValueError(f"{signal!r} is not a NeuroKit2 signal")
    x = np.asarray(x, dtype=np.float64)
    if len(x) < n:  # NeuroKit2 rounds lengths; never observed to fall short by more than a sample
        x = np.concatenate([x, np.full(n - len(x), x[-1])])
    return x[:n]


def _cycle_seconds(signal: str, cfg: SimulatorConfig) -> float:
    """Rough length of one cycle: the window the splice matches so the rhythm carries on."""
    if signal in ("ecg", "hr", "ppg"):
        return 60.0 / cfg.bpm
    if signal == "rsp":
        return 60.0 / cfg.resp
    if signal == "eda":
        return 4.0  # slow: a longer fade hides the restart of the tonic level
    return 0.5


def best_splice(tail: np.ndarray, head: np.ndarray, half: int, max_points: int = 400) -> int:
    """Index ``j`` in ``head`` whose neighbourhood ``head[j-half:j+half]`` best matches the
    last ``2*half`` samples of ``tail`` (least squares), with ``half <= j <= len(head)-half``.

    Long windows are compared on every ``k``-th sample so the search stays cheap at high rates.
    """
    a = tail[-2 * half:]
    k = max(1, math.ceil(2 * half / max_points))
    a_d = a[::k]
    span = len(a_d)
    starts = np.arange(0, len(head) - 2 * half + 1, k)  # window start = j - half
    if len(starts) == 0:
        raise ValueError("head is shorter than the match window")
    idx = starts[:, None] + np.arange(span)[None, :] * k
    cost = np.sum((head[idx] - a_d[None, :]) ** 2, axis=1)
    return int(starts[int(np.argmin(cost))] + half)


class ValueGenerator(Protocol):
    """Sample values by global index; indices below ``discard_before`` may be forgotten."""

    def values(self, start: int, stop: int) -> np.ndarray: ...

    def discard_before(self, index: int) -> None: ...


class RampValues:
    """Value = sample index, exactly: lets a test spot any lost, repeated or reordered sample."""

    def values(self, start: int, stop: int) -> np.ndarray:
        return np.arange(start, stop, dtype=np.float64)

    def discard_before(self, index: int) -> None:
        pass


class NeuroKitValues:
    """One NeuroKit2 signal, generated a segment at a time and spliced (see module doc)."""

    def __init__(self, signal: str, cfg: SimulatorConfig, total: int | None) -> None:
        self.signal = signal
        self.cfg = cfg
        self.total = total
        fs = cfg.fs
        self.half = max(2, round(_cycle_seconds(signal, cfg) * fs))
        # The new segment's lead-in: room for the match window plus two cycles to search in.
        self.lead = 2 * self.half + 2 * self.half
        if total is not None and total <= SINGLE_SEGMENT_MAX_SECONDS * cfg.rate:
            self.segment = total
        else:
            self.segment = round(cfg.segment_seconds * fs)
        self.joints: list[int] = []  # global index where each later segment takes over
        self._buf = np.empty(0)
        self._start = 0  # global index of _buf[0]
        self._next_seed = cfg.seed

    @property
    def generated(self) -> int:
        """Global index one past the last sample generated so far."""
        return self._start + len(self._buf)

    def _append_segment(self) -> None:
        seed = self._next_seed
        self._next_seed += 1
        if len(self._buf) == 0 and self._start == 0:
            self._buf = neurokit_segment(self.signal, self.cfg, self.segment, seed)
            return
        head = neurokit_segment(self.signal, self.cfg, self.segment + self.lead, seed)
        h = self.half
        j = best_splice(self._buf, head[: self.lead], h)
        cut = len(self._buf) - h  # keep the tail up to the middle of the matched window
        fade = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, h))
        blended = (1 - fade) * self._buf[cut - h: cut] + fade * head[j - h: j]
        self.joints.append(self._start + cut)
        self._buf = np.concatenate([self._buf[: cut - h], blended, head[j:]])

    def values(self, start: int, stop: int) -> np.ndarray:
        if start < self._start:
            raise IndexError(f"samples before {self._start} were discarded (asked for {start})")
        # Keep 2*half unsent samples beyond `stop`: a splice rewrites only that tail.
        need = stop + 2 * self.half
        if self.total is not None:
            need = min(need, self.total)
        while self.generated < need:
            self._append_segment()
        return self._buf[start - self._start: stop - self._start].copy()

    def discard_before(self, index: int) -> None:
        drop = min(index - self._start, len(self._buf) - 2 * self.half)
        if drop > 0:
            self._buf = self._buf[drop:]
            self._start += drop


class HeartRateValues:
    """What a Polar strap's HR notification reports, from the simulated ECG (1 Hz).

    HR sample ``k`` is at time ``k`` s, the same instant as ECG sample ``k * rate``. Its value
    is 60 / mean RR of the R-peaks in the preceding ``window`` seconds of that ECG, in whole
    bpm (as the strap sends), or the configured bpm while fewer than three beats are in view.
    The ECG is the same one the ECG stream sends (same seed and splices), generated again.
    """

    def __init__(self, cfg: SimulatorConfig, window: float = 5.0) -> None:
        self.cfg = cfg
        # Exactly the ECG stream's length, so NeuroKit2 draws exactly the same ECG.
        self.ecg_total = None if cfg.continuous else round(cfg.seconds * cfg.rate)
        self.ecg = NeuroKitValues("ecg", cfg, self.ecg_total)
        self.window = round(window * cfg.rate)

    def _ecg_end(self, k: int) -> int:
        """One past the last ECG sample at or before time ``k`` s."""
        end = math.floor(k * self.cfg.rate + 1e-9) + 1
        return end if self.ecg_total is None else min(end, self.ecg_total)

    def value_at(self, k: int) -> float:
        end = self._ecg_end(k)
        start = max(0, end - self.window)
        if end - start < self.cfg.rate * 2:
            return float(round(self.cfg.bpm))
        ecg = self.ecg.values(start, end)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, info = _neurokit().ecg_peaks(ecg, sampling_rate=self.cfg.fs)
        rr = np.diff(np.asarray(info["ECG_R_Peaks"], dtype=np.float64)) / self.cfg.fs
        rr = rr[(rr > 0.2) & (rr < 3.0)]  # drop detector glitches
        if len(rr) < 2:
            return float(round(self.cfg.bpm))
        return float(round(60.0 / float(np.mean(rr))))

    def values(self, start: int, stop: int) -> np.ndarray:
        out = np.array([self.value_at(k) for k in range(start, stop)], dtype=np.float64)
        return out

    def discard_before(self, index: int) -> None:
        self.ecg.discard_before(self._ecg_end(index) - self.window)


# -- sources and pacing -----------------------------------------------------------------


@dataclass(frozen=True)
class Block:
    """Consecutive samples ``first .. first+len-1`` of one stream."""

    first: int
    timestamps: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamps)


class SampleSource:
    """Consecutive blocks of one stream; sample ``i`` is stamped ``t0 + i / rate``."""

    def __init__(self, signal: str, rate: float, values: ValueGenerator,
                 total: int | None, t0: float = 0.0) -> None:
        self.signal = signal
        self.rate = rate
        self.t0 = t0
        self.total = total  # None = continuous
        self.sent = 0
        self._values = values

    @property
    def done(self) -> bool:
        return self.total is not None and self.sent >= self.total

    def remaining(self) -> int | None:
        return None if self.total is None else self.total - self.sent

    def timestamp(self, index: int) -> float:
        return self.t0 + index / self.rate

    def take(self, n: int) -> Block:
        """The next ``n`` samples (fewer at the end of a finite source)."""
        if self.total is not None:
            n = min(n, self.total - self.sent)
        n = max(0, n)
        first = self.sent
        values = self._values.values(first, first + n)
        idx = np.arange(first, first + n, dtype=np.float64)
        self.sent += n
        self._values.discard_before(self.sent)
        return Block(first, self.t0 + idx / self.rate, values)

    def prefetch(self) -> None:
        """Generate the first segment now, before streaming starts, not in the first chunk."""
        if not self.done:
            self._values.values(self.sent, self.sent + 1)


def make_source(signal: str, cfg: SimulatorConfig, t0: float = 0.0) -> SampleSource:
    if signal not in SIGNALS:
        raise ValueError(f"unknown signal {signal!r}; choose from {', '.join(SIGNALS)}")
    rate = stream_rate(signal, cfg)
    total = None if cfg.continuous else round(cfg.seconds * rate)
    values: ValueGenerator
    if signal == "ramp":
        values = RampValues()
    elif signal == "hr":
        values = HeartRateValues(cfg)
    else:
        values = NeuroKitValues(signal, cfg, total)
    return SampleSource(signal, rate, values, total, t0)


class Pacer:
    """Which chunks of which stream are due at clock time ``now``.

    A chunk goes out once its last sample's time (``start + index / rate``) has come, as a
    strap sends a notification once it has measured it; a finite stream's last chunk may
    be shorter. HR goes out one value at a time, like the strap's 1 Hz notification.
    """

    def __init__(self, sources: Mapping[str, SampleSource], chunk: int, start: float) -> None:
        if chunk < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk}")
        self.sources = dict(sources)
        self.chunks = {k: 1 if k == "hr" else chunk for k in self.sources}
        self.start = start

    def _next_chunk(self, key: str) -> tuple[int, float] | None:
        src = self.sources[key]
        n = self.chunks[key]
        left = src.remaining()
        if left is not None:
            if left <= 0:
                return None
            n = min(n, left)
        return n, self.start + (src.sent + n - 1) / src.rate

    def next_due(self) -> float | None:
        """Clock time the next chunk is due, or None when every finite stream is done."""
        times = [nc[1] for k in self.sources if (nc := self._next_chunk(k)) is not None]
        return min(times) if times else None

    @property
    def done(self) -> bool:
        return self.next_due() is None

    def due(self, now: float) -> list[tuple[str, Block]]:
        """Every chunk due by ``now``, in time order within each stream (catches up after a stall)."""
        out: list[tuple[str, Block]] = []
        for key, src in self.sources.items():
            while (nc := self._next_chunk(key)) is not None and nc[1] <= now + 1e-9:
                out.append((key, src.take(nc[0])))
        return out


def run_paced(pacer: Pacer, clock: Callable[[], float], sleep: Callable[[float], Any],
              emit: Callable[[str, Block], None], should_stop: Callable[[], bool],
              on_tick: Callable[[float], None] | None = None, max_sleep: float = 0.25) -> bool:
    """Stream in real time until every finite stream is done or ``should_stop()``.

    ``sleep`` may return early (e.g. ``threading.Event.wait``); it never sleeps longer than
    ``max_sleep`` so a stop request and ``on_tick`` (progress) are seen promptly.
    Returns True when the streams finished, False when stopped.
    """
    while not should_stop():
        now = clock()
        for key, block in pacer.due(now):
            emit(key, block)
        if on_tick is not None:
            on_tick(now)
        nxt = pacer.next_due()
        if nxt is None:
            return True
        wait = nxt - clock()
        if wait > 0:
            sleep(min(wait, max_sleep))
    return False

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
from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np

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


@dataclass(frozen=True)
class SimulatorConfig:
    """Signal options; names match the seed simulator's flags."""

    seconds: float = 60.0  # 0 = continuous
    rate: float = 130.0  # Hz, the Polar H10 ECG rate
    noise: float = 0.01
    bpm: float = 70.0
    scr: int = 3
    drift: float = -0.01
    bnum: int = 3
    bdur: float = 1.0
    resp: float = 15.0
    seed: int = 42
    segment_seconds: float = 60.0

    def __post_init__(self) -> None:
        problems = []
        if not (math.isfinite(self.seconds) and self.seconds >= 0):
            problems.append(f"seconds must be >= 0 (0 = until stopped), got {self.seconds:g}")
        if not (math.isfinite(self.rate) and 0 < self.rate <= MAX_RATE):
            problems.append(f"rate must be > 0 and <= {MAX_RATE:g} Hz, got {self.rate:g}")
        if not (math.isfinite(self.noise) and self.noise >= 0):
            problems.append(f"noise must be >= 0, got {self.noise:g}")
        if not 20 <= self.bpm <= 250:
            problems.append(f"bpm must be between 20 and 250, got {self.bpm:g}")
        if self.scr < 0:
            problems.append(f"scr must be >= 0, got {self.scr}")
        if not math.isfinite(self.drift):
            problems.append(f"drift must be a finite number, got {self.drift}")
        if self.bnum < 0:
            problems.append(f"bnum must be >= 0, got {self.bnum}")
        if not (math.isfinite(self.bdur) and self.bdur > 0):
            problems.append(f"bdur must be > 0 s, got {self.bdur:g}")
        if not 1 <= self.resp <= 60:
            problems.append(f"resp must be between 1 and 60 breaths/min, got {self.resp:g}")
        if not (math.isfinite(self.segment_seconds) and self.segment_seconds >= 20):
            problems.append(f"segment_seconds must be >= 20, got {self.segment_seconds:g}")
        if problems:
            raise ValueError("; ".join(problems))

    @property
    def continuous(self) -> bool:
        return self.seconds == 0

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


# -- options (CLI / YAML) ---------------------------------------------------------------


@dataclass(frozen=True)
class RunOptions:
    """Everything the node needs, validated."""

    sim: SimulatorConfig = field(default_factory=SimulatorConfig)
    signals: tuple[str, ...] = DEFAULT_SIGNALS
    device_id: str = "SIM0001"
    name_prefix: str = ""
    chunk: int = 0  # 0 = about 0.1 s of samples
    wait_for_consumers: float = 0.0

    @property
    def chunk_samples(self) -> int:
        return self.chunk or max(1, round(self.sim.rate * 0.1))


_SIM_KEYS = {f.name: f.type for f in fields(SimulatorConfig)}
_RUN_KEYS = {"signals", "device_id", "name_prefix", "chunk", "wait_for_consumers", "continuous"}
OPTION_KEYS = frozenset(_SIM_KEYS) | _RUN_KEYS


def _number(key: str, value: Any, integer: bool = False) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f"option {key!r} must be a number, got {value!r}")
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"option {key!r} must be a number, got {value!r}") from None
    if integer:
        if not number.is_integer():
            raise ValueError(f"option {key!r} must be a whole number, got {value!r}")
        return int(number)
    return number


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


def options_from_mapping(values: Mapping[str, Any]) -> RunOptions:
    """Validate options from YAML and/or the command line (keys use ``_`` or ``-``)."""
    opts = {str(k).replace("-", "_"): v for k, v in values.items()}
    unknown = sorted(set(opts) - OPTION_KEYS)
    if unknown:
        raise ValueError(f"unknown option(s) {', '.join(unknown)}; known: {', '.join(sorted(OPTION_KEYS))}")
    sim = {k: _number(k, v, integer=_SIM_KEYS[k] == "int") for k, v in opts.items() if k in _SIM_KEYS}
    continuous = opts.get("continuous", False)
    if not isinstance(continuous, bool):
        raise ValueError(f"option 'continuous' must be true or false, got {continuous!r}")
    if continuous:
        sim["seconds"] = 0.0
    cfg = SimulatorConfig(**sim)
    signals = parse_signals(opts.get("signals", DEFAULT_SIGNALS))
    if cfg.rate < MIN_NEUROKIT_RATE and NEUROKIT_SIGNALS.intersection(signals):
        raise ValueError(f"rate must be >= {MIN_NEUROKIT_RATE:g} Hz for NeuroKit2 signals, got {cfg.rate:g}")
    if "emg" in signals and cfg.bnum * cfg.bdur >= cfg.generated_seconds:
        raise ValueError(f"{cfg.bnum} EMG bursts of {cfg.bdur:g} s do not fit in "
                         f"{cfg.generated_seconds:g} s of simulated EMG")
    device_id = str(opts.get("device_id", "SIM0001")).strip()
    if not device_id or "/" in device_id or any(c.isspace() for c in device_id):
        raise ValueError(f"device_id must be a non-empty word without '/', got {device_id!r}")
    chunk = _number("chunk", opts.get("chunk", 0), integer=True)
    if chunk < 0:
        raise ValueError(f"chunk must be >= 1 sample (0 = about 0.1 s), got {chunk}")
    wait = _number("wait_for_consumers", opts.get("wait_for_consumers", 0.0))
    if not (math.isfinite(wait) and wait >= 0):
        raise ValueError(f"wait_for_consumers must be >= 0 s, got {wait:g}")
    prefix = opts.get("name_prefix") or ""
    return RunOptions(cfg, signals, device_id, str(prefix).strip("/"), int(chunk), float(wait))


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

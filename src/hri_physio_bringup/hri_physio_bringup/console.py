"""A calm console for a session (no rclpy): one live display, the nodes' warnings above it, the rest in files.

Every node's full output goes to its log file (``launcher.ProcessGroup``); the console gets

* :class:`LiveConsole` on a terminal: one rich live display (phase and activity, elapsed and
  remaining session time, HR and the zone, tempo and gesture speed, adaptations, the sim-time
  factor), with every warning or error line of a node printed above it, labelled with the node;
* :class:`PlainConsole` when stdout is not a terminal (CI, a pipe, a file): the same warnings and
  one plain progress line per ``every`` seconds of session;
* :class:`VerboseConsole` (``--verbose``): every line of every node, interleaved and labelled,
  with the plain progress lines.

Which node lines are warnings is read from the lines themselves (:class:`LineClassifier`):
rclpy's ``[WARN]``/``[ERROR]``/``[FATAL]`` prefixes, ``<prog>: error:`` lines and the last line
of a Python traceback.
"""

from __future__ import annotations

import re
import threading
from collections import Counter
from dataclasses import dataclass
from typing import Any, Protocol, TextIO

from hri_physio_bringup.view import SessionView

WARNING, ERROR = "WARN", "ERROR"
_ROS_LINE = re.compile(r"^\[(WARN|WARNING|ERROR|FATAL)\]\s*(?:\[[\d.]+\]\s*)?(?:\[[^\]]*\]:?\s*)?(.*)$")
_PROG_LINE = re.compile(r"^[\w./-]+: (error|warning): (.*)$")
_TRACEBACK = "Traceback (most recent call last):"
#: A warning whose text (digits aside) a node already said this often is not echoed again.
MAX_REPEATS = 3
#: Lines of one node echoed at most: a node in trouble says so, its log file says the rest.
MAX_PER_NODE = 10


class LineClassifier:
    """Which lines of one node's output the console shows: (level, text) or None. Keeps traceback state."""

    def __init__(self) -> None:
        self._in_traceback = False

    def __call__(self, line: str) -> tuple[str, str] | None:
        text = line.rstrip()
        if self._in_traceback:
            if not text or text[0].isspace() or text.startswith(("Traceback", "During handling",
                                                                 "The above exception")):
                return None
            self._in_traceback = False
            if text == "KeyboardInterrupt":
                # Only the launcher's own SIGINT, come before the node had its handler (still starting,
                # being stopped): no crash to report. A node past its start handles SIGINT itself.
                return None
            return ERROR, f"crashed: {text}"
        if text.startswith(_TRACEBACK):
            self._in_traceback = True
            return None
        m = _ROS_LINE.match(text)
        if m:
            level = WARNING if m.group(1).startswith("WARN") else ERROR
            return level, m.group(2)
        m = _PROG_LINE.match(text)
        if m:
            return (ERROR if m.group(1) == "error" else WARNING), m.group(2)
        return None


class EchoFilter:
    """Node warnings for the console: each kind (node + text with digits masked) at most ``max_repeats``
    times, at most ``max_per_node`` lines of one node; the rest stays in the node's log file."""

    def __init__(self, max_repeats: int = MAX_REPEATS, max_per_node: int = MAX_PER_NODE) -> None:
        self.max_repeats = max_repeats
        self.max_per_node = max_per_node
        self._echoed: Counter[str] = Counter()
        self._classifiers: dict[str, LineClassifier] = {}
        self.seen: Counter[tuple[str, str]] = Counter()  # (node, level) -> lines
        self._kinds: Counter[tuple[str, str]] = Counter()
        self._lock = threading.Lock()

    def __call__(self, node: str, line: str) -> str | None:
        """The console line for ``line`` of ``node`` (None: it stays in the log file only)."""
        with self._lock:
            found = self._classifiers.setdefault(node, LineClassifier())(line)
            if found is None:
                return None
            level, text = found
            self.seen[(node, level)] += 1
            kind = (node, re.sub(r"\d+(\.\d+)?", "#", text))
            self._kinds[kind] += 1
            n = self._kinds[kind]
            if n > self.max_repeats + 1 or self._echoed[node] >= self.max_per_node:
                return None
            self._echoed[node] += 1
            last = self._echoed[node] == self.max_per_node
        if last:
            return f"[{node}] {level}: {text} (further warnings of {node} only in logs/{node}.log)"
        if n == self.max_repeats + 1:
            return f"[{node}] {level}: {text} (repeated; further repeats only in logs/{node}.log)"
        return f"[{node}] {level}: {text}"


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Progress:
    """What the console shows of a running session."""

    elapsed: float | None  # session seconds since the coach's start (None: not started)
    duration: float  # of the routine
    phase: str | None
    activity: str | None
    hr: float
    zone: tuple[float, float] | None
    speed: float | None  # gesture speed
    tempo: float | None  # music tempo
    adaptations: int
    robot_actions: int
    factor: float | None  # measured sim seconds per wall second
    ended: bool

    @classmethod
    def of(cls, view: SessionView, now: float, duration: float, factor: float | None) -> Progress:
        t0 = view.started_at
        end = view.ended_at if view.ended_at is not None else now
        state = view.state
        return cls(
            elapsed=None if t0 is None else max(0.0, end - t0),
            duration=view.duration if view.duration is not None else duration,
            phase=state.get("phase"), activity=state.get("activity"), hr=view.hr, zone=view.zone,
            speed=_number(state.get("ladder_speed")), tempo=_number(state.get("ladder_tempo")),
            adaptations=view.adaptations, robot_actions=view.robot_actions, factor=factor,
            ended=view.ended_at is not None,
        )

    @property
    def remaining(self) -> float | None:
        return None if self.elapsed is None else max(0.0, self.duration - self.elapsed)

    @property
    def zone_state(self) -> str:
        if self.zone is None:
            return "zone not set yet"
        if self.hr != self.hr:  # NaN
            return f"zone {self.zone[0]:.0f}-{self.zone[1]:.0f}"
        where = "below" if self.hr < self.zone[0] else "above" if self.hr > self.zone[1] else "in"
        return f"{where} zone {self.zone[0]:.0f}-{self.zone[1]:.0f}"

    @property
    def where(self) -> str:
        if self.ended:
            return "ended"
        if self.elapsed is None:
            return "waiting for the start"
        return f"{self.phase or '-'} / {self.activity or '-'}"

    @property
    def pace(self) -> str:
        if self.speed is None:
            return "pace -"
        tempo = "-" if self.tempo is None else f"{self.tempo:.0f}"
        return f"tempo {tempo} BPM, gesture speed {self.speed:.2f}"

    def line(self) -> str:
        """One plain progress line."""
        hr = "  -  " if self.hr != self.hr else f"{self.hr:5.1f}"
        factor = "" if self.factor is None else f"  {self.factor:.0f}x"
        return (f"[session] {clock_text(self.elapsed)}/{clock_text(self.duration)} {self.where:30s} "
                f"HR {hr} bpm ({self.zone_state})  {self.pace}  adaptations {self.adaptations}{factor}")


def _number(value: Any) -> float | None:
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def clock_text(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    s = int(seconds)
    return f"{s // 60:02d}:{s % 60:02d}"


# ----------------------------------------------------------------------------------------------
class SessionConsole(Protocol):
    def say(self, text: str) -> None:
        """A line of the launcher's own (start-up, the summary)."""

    def node_line(self, node: str, line: str) -> None:
        """A line of a node's output (from the process group's reader threads)."""

    def progress(self, progress: Progress) -> None:
        """The session as it is now (called often; the console decides what to show)."""

    def close(self) -> None:
        """End the live part: what is said after stays below it."""


class PlainConsole:
    """Plain lines: the nodes' warnings and one progress line per ``every`` session seconds."""

    def __init__(self, out: TextIO, every: float = 60.0, echo: EchoFilter | None = None) -> None:
        self.out = out
        self.every = every
        self.echo = echo if echo is not None else EchoFilter()
        self._next = 0.0
        self._ended = False
        self._lock = threading.Lock()

    def say(self, text: str) -> None:
        with self._lock:
            print(text, file=self.out, flush=True)

    def node_line(self, node: str, line: str) -> None:
        shown = self.echo(node, line)
        if shown is not None:
            self.say(shown)

    def progress(self, progress: Progress) -> None:
        if progress.elapsed is None or self._ended or (progress.phase is None and not progress.ended):
            return  # not started, or the coach's first state is still on its way
        if progress.ended:
            self._ended = True
            self.say(progress.line())
            return
        if progress.remaining == 0.0:
            return  # the routine's end: the line of its end comes with the coach's session_end
        if progress.elapsed >= self._next:
            while self._next <= progress.elapsed:
                self._next += self.every
            self.say(progress.line())

    def close(self) -> None:
        """Nothing is live: plain lines stay where they are."""


class VerboseConsole(PlainConsole):
    """Every node line, labelled, interleaved (the old console), plus the plain progress lines."""

    def node_line(self, node: str, line: str) -> None:
        self.echo(node, line)  # counted all the same
        self.say(f"[{node}] {line}")


class LiveConsole:
    """One rich live display on a terminal; node warnings and the launcher's lines print above it."""

    def __init__(self, title: str, echo: EchoFilter | None = None, console: Any = None) -> None:
        from rich.console import Console
        from rich.live import Live

        self.console = console if console is not None else Console()
        self.echo = echo if echo is not None else EchoFilter()
        self.title = title
        self._live = Live(self._render(None), console=self.console, refresh_per_second=4, transient=False)
        self._live.start()
        self._closed = False

    def say(self, text: str) -> None:
        self.console.print(text, markup=False, highlight=False, soft_wrap=True)

    def node_line(self, node: str, line: str) -> None:
        shown = self.echo(node, line)
        if shown is not None:
            style = "bold red" if f"] {ERROR}:" in shown else "yellow"
            self.console.print(shown, style=style, markup=False, highlight=False, soft_wrap=True)

    def progress(self, progress: Progress) -> None:
        if not self._closed:
            self._live.update(self._render(progress))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._live.stop()

    def _render(self, p: Progress | None) -> Any:
        from rich.panel import Panel
        from rich.progress_bar import ProgressBar
        from rich.table import Table

        grid = Table.grid(padding=(0, 2))
        grid.add_column(style="bold", no_wrap=True)
        grid.add_column()
        if p is None:
            grid.add_row("starting", "waiting for the nodes and the first heart rate ...")
            return Panel(grid, title=self.title, expand=False)
        elapsed = p.elapsed or 0.0
        bar = Table.grid(padding=(0, 1))
        bar.add_row(ProgressBar(total=max(p.duration, 1.0), completed=min(elapsed, p.duration), width=32),
                    f"{clock_text(p.elapsed)} / {clock_text(p.duration)}  ({clock_text(p.remaining)} left)")
        hr = "-" if p.hr != p.hr else f"{p.hr:.0f} bpm"
        grid.add_row("phase", p.where)
        grid.add_row("time", bar)
        grid.add_row("heart rate", f"{hr}  ({p.zone_state})")
        grid.add_row("pace", p.pace)
        factor = "-" if p.factor is None else f"{p.factor:.1f}x real time"
        grid.add_row("adaptations", f"{p.adaptations}   robot actions {p.robot_actions}   sim time {factor}")
        return Panel(grid, title=self.title, expand=False)

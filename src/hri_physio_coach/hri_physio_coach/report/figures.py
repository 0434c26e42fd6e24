"""The report's figures (matplotlib, no pyplot: each figure is its own Agg canvas, no global state).

* :func:`hr_session_figure` - thesis Fig. 4.12: heart rate over the session, the zone, phases,
  activities, rule updates and the pace (music tempo, gesture speed);
* :func:`fuzzy_probability_figure` - Fig. 4.13: the fuzzy rule's p(HR) for this participant's zone;
* :func:`fuzzy_overlay_figure` - Fig. 4.14: p(HR) along the heart-rate trace and at each rule update;
* :func:`hrv_figure` - LF, HF and LF/HF of the processor over the session.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MultipleLocator

from hri_physio_coach.report.bagdata import BagTables
from hri_physio_coach.report.metrics import HeartRate, feature_times, hrv_method, hrv_method_text, hrv_series
from hri_physio_coach.report.timeline import EXERCISE_KINDS, RuleOutcome, SessionClock, Span, Timeline
from hri_physio_coach.zones import HeartRateZone, fuzzy_probability

DPI = 150
#: Opaque (tests look for it in the PNG): the target zone band.
ZONE_COLOR = "#d5ecd0"
ZONE_EDGE = "#5a9e4f"
HR_COLOR = "#1b3a6b"
PHASE_COLORS = {"calibration": "#7f8fa6", "warm_up": "#e0a030", "conditioning": "#c8473d",
                "cool_down": "#3f7fbf"}
OUTCOME_STYLE = {
    RuleOutcome.SPEED_UP: {"marker": "^", "color": "#2a9d3c", "size": 46},
    RuleOutcome.SLOW_DOWN: {"marker": "v", "color": "#d1342f", "size": 46},
    RuleOutcome.NO_CHANGE: {"marker": "o", "color": "#8a8a8a", "size": 22},
    RuleOutcome.NO_UPDATE: {"marker": "X", "color": "#444444", "size": 30},
}
#: Colours of the timeline's other marks: music tempo, gesture speed, heart rate lost, node restarts
#: and a node lost.
COLORS = {"tempo": "#7b4fa0", "speed": "#b0642a", "lost": "#f3c9c6", "restart": "#8a5a00", "died": "#b00020"}


def _pretty(name: str) -> str:
    return name.replace("_", "-" if name in EXERCISE_KINDS else " ").capitalize()


def _minutes(t: np.ndarray | float, t0: float) -> np.ndarray | float:
    return (np.asarray(t, dtype=np.float64) - t0) / 60.0 if isinstance(t, np.ndarray) else (t - t0) / 60.0


def _broken_line(t: np.ndarray, y: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaN where consecutive samples are further apart than ``max_gap`` (no line across gaps)."""
    if t.size < 2:
        return t, y
    breaks = np.flatnonzero(np.diff(t) > max_gap) + 1
    return np.insert(t, breaks, np.nan), np.insert(y, breaks, np.nan)


def _strip(ax, spans: Sequence[Span], t0: float, colors: Sequence[str], text_color: str, size: float,
           chars_per_min: float, bold: bool) -> None:
    for i, span in enumerate(spans):
        a, b = _minutes(span.start, t0), _minutes(span.end, t0)
        ax.axvspan(a, b, color=colors[i % len(colors)], lw=0)
        if b > a:
            ax.axvline(a, color="white", lw=1.2)
            width = b - a
            label = span.label if not bold else _pretty(span.name)
            if bold:
                label = f"{label} ({width:.0f} min)" if width >= 2.5 else label
            fits = max(3, int(chars_per_min * width))
            text = "\n".join(textwrap.wrap(label, fits, break_long_words=False)) or label
            longest = max(len(line) for line in text.splitlines())
            ax.text((a + b) / 2, 0.5, text, ha="center", va="center", color=text_color,
                    fontsize=size * min(1.0, fits / longest),
                    fontweight="bold" if bold else "normal", linespacing=0.95, clip_on=True)
    ax.set_ylim(0, 1)
    ax.set_yticks([])
    for side in ("top", "right", "left", "bottom"):
        ax.spines[side].set_visible(False)
    ax.tick_params(axis="x", which="both", bottom=False, labelbottom=False)


def _session_marks(ax, timeline: Timeline, t0: float) -> list:
    """The launcher's events: a node down until its restart (a band, named), a node lost (a line)."""
    handles: list = []
    restarts = [e for e in timeline.session_events if e.get("event") == "node_restarted"]
    for ev in restarts:
        t = float(ev["t"])
        down = float(ev.get("down_s") or 0.0)
        ax.axvspan(_minutes(t - down, t0), _minutes(t, t0), color=COLORS["restart"], alpha=0.35, lw=0,
                   zorder=0.6)
        ax.axvline(_minutes(t, t0), color=COLORS["restart"], lw=0.9, ls="-.", zorder=2)
        ax.annotate(str(ev.get("node")), (_minutes(t, t0), 0.01), xycoords=("data", "axes fraction"),
                    rotation=90, va="bottom", ha="right", fontsize=6.5, color=COLORS["restart"])
    if restarts:
        handles.append(Line2D([], [], color=COLORS["restart"], ls="-.",
                              label=f"Node restarted ({len(restarts)})"))
    lost = [e for e in timeline.session_events if e.get("event") == "node_died"]
    for ev in lost:
        ax.axvline(_minutes(float(ev["t"]), t0), color=COLORS["died"], lw=1.4, zorder=2)
    if lost:
        names = ", ".join(str(e.get("node")) for e in lost)
        handles.append(Line2D([], [], color=COLORS["died"], lw=1.4, label=f"Session ended: {names} died"))
    return handles


def hr_session_figure(path: Path, timeline: Timeline, hr: HeartRate | None, title: str) -> Path:
    """Thesis Fig. 4.12 for this session."""
    t0 = timeline.t0
    end_min = max(_minutes(timeline.end, t0), 1e-3)
    fig = Figure(figsize=(12, 7.2), dpi=DPI, layout="constrained")
    grid = fig.add_gridspec(4, 1, height_ratios=[0.34, 0.46, 3.7, 1.35])
    ax_phase = fig.add_subplot(grid[0])
    ax_act = fig.add_subplot(grid[1], sharex=ax_phase)
    ax = fig.add_subplot(grid[2], sharex=ax_phase)
    ax_pace = fig.add_subplot(grid[3], sharex=ax_phase)

    # Characters of a label that fit in one minute of the x axis (about 0.9 of the figure's width).
    per_min = 0.9 * 12 * 72 / end_min
    _strip(ax_phase, timeline.phases, t0, [PHASE_COLORS.get(p.kind, "#999999") for p in timeline.phases],
           "white", 9, per_min / (9 * 0.56), True)
    _strip(ax_act, timeline.activities, t0, ["#e9e9e9", "#d4d4d4"], "#222222", 7, per_min / (7 * 0.6), False)

    zone = timeline.zone
    handles: list = []
    if zone is not None:
        ax.axhspan(zone.low, zone.high, color=ZONE_COLOR, lw=0, zorder=0)
        for y in (zone.low, zone.high):
            ax.axhline(y, color=ZONE_EDGE, lw=0.8, ls="--", zorder=1)
        ax.axhline(zone.hr_rest, color="#777777", lw=0.8, ls=":", zorder=1)
        low_pct, high_pct = zone.low_fraction * 100, zone.high_fraction * 100
        handles.append(Patch(facecolor=ZONE_COLOR, edgecolor=ZONE_EDGE, ls="--",
                             label=f"Target zone HRR{low_pct:.0f}–{high_pct:.0f} "
                                   f"({zone.low:.1f}–{zone.high:.1f} bpm)"))
        handles.append(Line2D([], [], color="#777777", ls=":", label=f"HR$_{{rest}}$ {zone.hr_rest:.1f} bpm"))
    for gap in timeline.hr_gaps:
        stop = gap["resumed"] if gap["resumed"] is not None else timeline.end
        ax.axvspan(_minutes(gap["silent_since"], t0), _minutes(stop, t0), color=COLORS["lost"], lw=0,
                   zorder=0.5)
    if timeline.hr_gaps:
        handles.append(Patch(facecolor=COLORS["lost"], label="No HR at the coach"))
    handles += _session_marks(ax, timeline, t0)

    y_values: list[float] = []
    if hr is not None:
        sel = hr.valid & (hr.t >= t0 - 5) & (hr.t <= timeline.end + 5)
        t, y = _broken_line(hr.t[sel], hr.bpm[sel], 3 * (hr.period if math.isfinite(hr.period) else 1.0))
        ax.plot(_minutes(t, t0), y, color=HR_COLOR, lw=1.0, zorder=3)
        handles.insert(0, Line2D([], [], color=HR_COLOR, lw=1.2, label="Heart rate (coach's input)"))
        y_values += list(hr.bpm[sel])

    for outcome, style in OUTCOME_STYLE.items():
        ups = [u for u in timeline.rule_updates if u.outcome == outcome]
        if not ups:
            continue
        xs = [_minutes(u.t, t0) for u in ups]
        if outcome == RuleOutcome.NO_UPDATE:
            ys = [u.hr for u in ups]
            base = min(y_values) - 4 if y_values else (zone.low - 10 if zone else 60)
            ys = [base if v is None else v for v in ys]
        else:
            ys = [u.hr for u in ups]
        ax.scatter(xs, ys, marker=style["marker"], s=style["size"], color=style["color"],
                   edgecolors="black", linewidths=0.5, zorder=5)
        handles.append(Line2D([], [], ls="", marker=style["marker"], color=style["color"],
                              markeredgecolor="black", markeredgewidth=0.5,
                              markersize=7 if outcome != RuleOutcome.NO_CHANGE else 5,
                              label=f"Rule update: {outcome} ({len(ups)})"))
        y_values += [v for v in ys if v is not None]

    bounds = [*y_values]
    if zone is not None:
        bounds += [zone.hr_rest - 8, zone.high + 10]
    if bounds:
        lo, hi = min(bounds), max(bounds)
        ax.set_ylim(5 * math.floor((lo - 4) / 5), 5 * math.ceil((hi + 6) / 5))
    ax.set_ylabel("Heart rate (bpm)")
    ax.grid(axis="y", color="#e6e6e6", lw=0.6, zorder=-1)
    ax.tick_params(axis="x", labelbottom=False)
    if handles:
        ax.legend(handles=handles, loc="upper left", fontsize=7.5, ncol=2, framealpha=0.92, borderaxespad=0.4)

    _pace_axes(ax_pace, timeline, t0, end_min)
    for a in (ax, ax_pace, ax_act):
        for p in timeline.phases[1:]:
            a.axvline(_minutes(p.start, t0), color="#9a9a9a", lw=0.8, zorder=2)
    ax_phase.set_xlim(0, end_min)
    ax_pace.xaxis.set_major_locator(MultipleLocator(2 if end_min > 12 else 1))
    ax_pace.xaxis.set_minor_locator(MultipleLocator(1 if end_min > 12 else 0.5))
    ax_pace.set_xlabel("Session time (min)")
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=DPI)
    return path


def _pace_axes(ax, timeline: Timeline, t0: float, end_min: float) -> None:
    exercise = [p.start for p in timeline.phases if p.kind in EXERCISE_KINDS]
    start = exercise[0] if exercise else t0
    steps = timeline.pace
    ax.set_ylabel("Tempo (bpm)", color=COLORS["tempo"], fontsize=9)
    ax.tick_params(axis="y", colors=COLORS["tempo"], labelsize=8)
    twin = ax.twinx()
    twin.set_ylabel("Gesture speed (×)", color=COLORS["speed"], fontsize=9)
    twin.tick_params(axis="y", colors=COLORS["speed"], labelsize=8)
    if not steps:
        ax.text(0.5, 0.5, "no pace recorded", transform=ax.transAxes, ha="center", va="center",
                color="#777777")
        return
    before = [s for s in steps if s[0] <= start]
    shown = ([(start, *before[-1][1:])] if before else []) + [s for s in steps if s[0] > start]
    if not shown:
        shown = [steps[0]]
    xs = [_minutes(s[0], t0) for s in shown] + [end_min]
    speed = [s[1] for s in shown] + [shown[-1][1]]
    tempo = [s[2] for s in shown] + [shown[-1][2]]
    ax.step(xs, tempo, where="post", color=COLORS["tempo"], lw=1.6)
    twin.step(xs, speed, where="post", color=COLORS["speed"], lw=1.3, ls="--")
    # Tempo in the upper half, gesture speed in the lower half: they step together and would hide
    # each other on a shared scale.
    for axis, values, pad, upper in ((ax, tempo, 2.0, True), (twin, speed, 0.02, False)):
        lo, hi = min(values), max(values)
        span = max(hi - lo, 4 * pad)
        if upper:
            axis.set_ylim(lo - pad - 1.15 * span, hi + pad)
        else:
            axis.set_ylim(lo - pad, hi + pad + 1.15 * span)
    ax.legend(handles=[Line2D([], [], color=COLORS["tempo"], lw=1.6, label="Music tempo"),
                       Line2D([], [], color=COLORS["speed"], lw=1.3, ls="--", label="Gesture speed")],
              loc="best", fontsize=7.5, ncol=2, framealpha=0.92)
    ax.grid(axis="x", color="#eeeeee", lw=0.5)


def _zone_model(timeline: Timeline) -> HeartRateZone:
    zone = timeline.zone
    assert zone is not None
    return HeartRateZone(zone.hr_rest, zone.hr_max, zone.low_fraction, zone.high_fraction)


def fuzzy_probability_figure(path: Path, timeline: Timeline, title: str) -> Path:
    """Thesis Fig. 4.13: p(HR) = |HR − target| / (target − HRR40), clipped to [0, 1]."""
    model = _zone_model(timeline)
    fig = Figure(figsize=(7.5, 4.4), dpi=DPI, layout="constrained")
    ax = fig.add_subplot()
    hrs = [u.hr for u in timeline.rule_updates if u.hr is not None]
    lo = min([model.hr_rest - 5, *hrs])
    hi = max([model.hr_max, *hrs])
    x = np.linspace(lo, hi, 600)
    ax.axvspan(model.low, model.high, color=ZONE_COLOR, lw=0, zorder=0)
    ax.plot(x, [fuzzy_probability(v, model) for v in x], color="black", lw=1.6, zorder=3, label="p(HR)")
    for value, name in ((model.low, f"HRR{model.low_fraction * 100:.0f}"), (model.target, "target"),
                        (model.high, f"HRR{model.high_fraction * 100:.0f}")):
        ax.axvline(value, color=ZONE_EDGE, lw=0.8, ls="--")
        ax.text(value, 1.07, f"{name}\n{value:.1f}", ha="center", va="bottom", fontsize=8, color="#2f6a27")
    ups = [u for u in timeline.rule_updates if u.hr is not None and u.p is not None]
    if ups:
        hit = [u for u in ups if u.draw is not None and u.draw < u.p]
        changed = [u for u in hit if u.changed]
        blocked = [u for u in hit if not u.changed]
        kept = [u for u in ups if u not in hit]
        for group, face, edge, label in (
            (changed, "#d1342f", "black", f"draw < p: pace or activity changed ({len(changed)})"),
            (blocked, "#f4b6b3", "#d1342f", f"draw < p: change not applied (at a ladder end / held) "
                                             f"({len(blocked)})"),
            (kept, "white", "black", f"draw ≥ p: no change ({len(kept)})"),
        ):
            if group:
                ax.scatter([u.hr for u in group], [u.p for u in group], s=34, facecolors=face,
                           edgecolors=edge, linewidths=0.8, zorder=5, label=f"rule update, {label}")
    ax.set_xlim(lo, hi)
    ax.set_ylim(-0.03, 1.25)
    ax.set_yticks(np.linspace(0, 1, 6))
    ax.set_xlabel("Mean heart rate over the last rule period (bpm)")
    ax.set_ylabel("Probability of a pace change")
    ax.grid(color="#eeeeee", lw=0.6)
    ax.legend(loc="lower left", fontsize=8, framealpha=0.95, bbox_to_anchor=(0.0, 0.02))
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=DPI)
    return path


def fuzzy_overlay_figure(path: Path, timeline: Timeline, hr: HeartRate | None, title: str) -> Path:
    """Thesis Fig. 4.14: the update probability along the heart-rate trace."""
    model = _zone_model(timeline)
    t0 = timeline.t0
    fig = Figure(figsize=(12, 5.6), dpi=DPI, layout="constrained")
    grid = fig.add_gridspec(2, 1, height_ratios=[3, 1.3])
    ax = fig.add_subplot(grid[0])
    ax_p = fig.add_subplot(grid[1], sharex=ax)
    ax.axhspan(model.low, model.high, color=ZONE_COLOR, lw=0, zorder=0)
    ax.axhline(model.target, color=ZONE_EDGE, lw=0.8, ls="--")
    exercise = [p for p in timeline.phases if p.kind in EXERCISE_KINDS]
    start = exercise[0].start if exercise else t0
    if hr is not None:
        sel = hr.valid & (hr.t >= start) & (hr.t <= timeline.end)
        p = np.array([fuzzy_probability(v, model) for v in hr.bpm[sel]])
        points = ax.scatter(_minutes(hr.t[sel], t0), hr.bpm[sel], c=p, cmap="RdYlGn_r", vmin=0, vmax=1, s=6,
                            lw=0, zorder=3)
        fig.colorbar(points, ax=ax, label="p(HR)", pad=0.01, fraction=0.03)
        t, y = _broken_line(hr.t[sel], p, 3 * (hr.period if math.isfinite(hr.period) else 1.0))
        ax_p.plot(_minutes(t, t0), y, color="#b8b8b8", lw=0.6, label="p of each HR sample")
    ups = [u for u in timeline.rule_updates if u.p is not None]
    took = [u for u in ups if u.draw is not None and u.draw < u.p]
    ax_p.vlines([_minutes(u.t, t0) for u in ups], 0, [u.p for u in ups], color="black", lw=1.0)
    ax_p.scatter([_minutes(u.t, t0) for u in ups], [u.p for u in ups], s=18, color="black", zorder=4,
                 label="p at the rule update")
    ax_p.scatter([_minutes(u.t, t0) for u in ups if u.draw is not None],
                 [u.draw for u in ups if u.draw is not None], marker="x", s=22, color="#3f7fbf", zorder=5,
                 label="random draw")
    ax_p.scatter([_minutes(u.t, t0) for u in took], [u.p for u in took], s=50, facecolors="none",
                 edgecolors="#d1342f", lw=1.3, zorder=6, label=f"draw < p ({len(took)})")
    for u in timeline.rule_updates:
        if u.hr is not None and u.outcome in (RuleOutcome.SPEED_UP, RuleOutcome.SLOW_DOWN):
            style = OUTCOME_STYLE[u.outcome]
            ax.scatter([_minutes(u.t, t0)], [u.hr], marker=style["marker"], s=style["size"],
                       color=style["color"], edgecolors="black", linewidths=0.5, zorder=5)
    for p_span in timeline.phases:
        if p_span.end <= start:
            continue
        for a in (ax, ax_p):
            a.axvline(_minutes(p_span.start, t0), color="#b5b5b5", lw=0.7)
        ax.text(_minutes(max(p_span.start, start), t0) + 0.1, 0.985, _pretty(p_span.name),
                transform=ax.get_xaxis_transform(), fontsize=8, va="top", color="#555555")
    changes = [Line2D([], [], ls="", marker=OUTCOME_STYLE[o]["marker"], color=OUTCOME_STYLE[o]["color"],
                      markeredgecolor="black", markeredgewidth=0.5, label=o)
               for o in (RuleOutcome.SPEED_UP, RuleOutcome.SLOW_DOWN)
               if any(u.outcome == o for u in timeline.rule_updates)]
    if changes:
        ax.legend(handles=[Patch(facecolor=ZONE_COLOR, label="target zone"), *changes], loc="lower right",
                  fontsize=7.5, framealpha=0.92)
    ax.set_ylabel("Heart rate (bpm)")
    ax.tick_params(axis="x", labelbottom=False)
    ax_p.set_ylim(-0.05, 1.08)
    ax_p.set_ylabel("p / draw")
    ax_p.set_xlabel("Session time (min)")
    ax_p.legend(loc="upper center", bbox_to_anchor=(0.5, -0.42), fontsize=7.5, ncol=4, frameon=False)
    ax.set_xlim(_minutes(start, t0), _minutes(timeline.end, t0))
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=DPI)
    return path


HRV_LABELS = {"lf": "LF (ms²)", "hf": "HF (ms²)", "lfhf": "LF/HF"}


def hrv_figure(path: Path, timeline: Timeline, tables: BagTables, clock: SessionClock,
               title: str) -> Path | None:
    """LF, HF (ms²) and LF/HF over the session, with the method and window under the axes (None if the
    processor published no finite value)."""
    finite = {t: s for t, s in hrv_series(tables).items() if np.isfinite(s.values[:, 0]).any()}
    if not finite:
        return None
    t0 = timeline.t0
    fig = Figure(figsize=(12, 1.6 + 1.5 * len(finite)), dpi=DPI, layout="constrained")
    axes = fig.subplots(len(finite), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (topic, stream) in zip(axes, sorted(finite.items()), strict=True):
        for p in timeline.phases:
            ax.axvspan(_minutes(p.start, t0), _minutes(p.end, t0), color=PHASE_COLORS.get(p.kind, "#999999"),
                       alpha=0.10, lw=0)
        feature = topic.rsplit("/", 1)[-1]
        ax.plot(_minutes(feature_times(tables, topic, clock), t0), stream.values[:, 0], marker="o", ms=2.5,
                lw=1.0, color="#1b3a6b")
        ax.set_ylabel(HRV_LABELS.get(feature, feature), fontsize=9)
        ax.set_title(topic, fontsize=8, loc="right", color="#666666")
        ax.grid(color="#eeeeee", lw=0.6)
    axes[-1].set_xlabel("Session time (min)\n\n" + "\n".join(textwrap.wrap(
        hrv_method_text(hrv_method(tables)), 170)), fontsize=8)
    axes[-1].set_xlim(0, max(_minutes(timeline.end, t0), 1e-3))
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=DPI)
    return path

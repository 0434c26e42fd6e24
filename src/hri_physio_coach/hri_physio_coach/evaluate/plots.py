"""The evaluation's figures (matplotlib, written to PNG files without a display)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no display needed (a tool, not a GUI)

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from hri_physio_coach.evaluate.metrics import smoothed

PHASE_COLOURS = {"warm_up": "#fff4d6", "conditioning": "#e6f2e6", "cool_down": "#e6eef8"}


def plot_in_zone(sessions: pd.DataFrame, policies: Sequence[str], path: Path, seed: int = 0) -> Path:
    """Distribution of conditioning time in zone per policy: box plot and one dot per person."""
    rng = np.random.default_rng(seed)
    data = [100.0 * sessions[sessions["policy"] == p]["in_zone"].to_numpy(dtype=float) for p in policies]
    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(policies), 4.2), dpi=110)
    ax.boxplot(data, showfliers=False, widths=0.55, medianprops={"color": "black"})
    for i, values in enumerate(data, start=1):
        ax.scatter(i + rng.uniform(-0.18, 0.18, len(values)), values, s=7, alpha=0.45, color=f"C{i - 1}",
                   linewidths=0)
        ax.text(i, 103, f"{np.nanmedian(values):.0f}% / {np.nanmean(values):.0f}%", ha="center", fontsize=8)
    ax.set_xticks(range(1, len(policies) + 1), list(policies))
    ax.set_ylim(-3, 108)
    ax.set_ylabel("conditioning time in zone (%)")
    n = len(data[0]) if data else 0
    ax.set_title(f"Time in zone per policy, {n} simulated people (median / mean)", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_traces(traces: Sequence[dict[str, Any]], policies: Sequence[str], path: Path) -> Path:
    """Heart rate of a few people (rows) under each policy (columns), zone shaded, phases tinted."""
    people = sorted({t["participant"] for t in traces})
    by_key = {(t["participant"], t["policy"]): t for t in traces}
    fig, axes = plt.subplots(len(people), len(policies), figsize=(3.2 * len(policies), 2.3 * len(people)),
                             dpi=100, sharex=True, squeeze=False)
    for r, person in enumerate(people):
        for c, policy in enumerate(policies):
            ax = axes[r][c]
            tr = by_key.get((person, policy))
            if tr is None:
                ax.set_visible(False)
                continue
            for kind, (start, end) in tr["phases"].items():
                if kind in PHASE_COLOURS:
                    ax.axvspan(start / 60, end / 60, color=PHASE_COLOURS[kind], zorder=0)
            low, high = tr["zone"]
            ax.axhspan(low, high, color="tab:green", alpha=0.18, zorder=1)
            minutes = tr["t"] / 60.0
            ax.plot(minutes, tr["model_hr"], color="0.6", lw=0.8, zorder=2, label="model")
            ax.plot(minutes, smoothed(tr["hr"]), color="tab:red", lw=1.0, zorder=3, label="strap (5 s)")
            start, end = tr["phases"].get("conditioning", (np.nan, np.nan))
            cond = (tr["t"] >= start) & (tr["t"] < end)
            hr5 = smoothed(tr["hr"])
            share = 100.0 * np.mean((hr5[cond] >= low) & (hr5[cond] <= high)) if cond.any() else np.nan
            ax.set_title(f"P{person} {policy}: {share:.0f}% in zone", fontsize=8)
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel("HR (bpm)", fontsize=8)
            if r == len(people) - 1:
                ax.set_xlabel("session time (min)", fontsize=8)
    axes[0][0].legend(fontsize=6, loc="lower right")
    fig.suptitle("Heart rate with the zone shaded (phases tinted: warm-up, conditioning, cool-down)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path

"""From per-session rows to the per-policy summary, the paired comparisons and the sensitivity table.

* ``in_zone_*``: fraction (0-1) of conditioning time with the participant's true heart rate in the
  coach's zone; the CI is a percentile bootstrap (95 %) of the median, seeded.
  ``in_zone_strap_median``: the same median on the strap's 5-s smoothed heart rate (artefacts in).
* ``in_zone_mean_reachable``, ``in_zone_p10_reachable``: the mean and the tenth percentile over the
  people whose zone the policy's controls can reach (:mod:`~hri_physio_coach.evaluate.reach`);
  ``unreachable_share`` is the rest, ``out_of_reach_share`` the part of it that every setting leaves
  on one side of the zone (``below`` or ``above``; people in a ``gap`` can be served by alternating).
* Paired comparisons: every policy against a reference on the same people; Wilcoxon
  signed-rank test (scipy, two-sided) on the per-person differences.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from hri_physio_coach.evaluate.reach import ABOVE, BELOW

SUMMARY_COLUMNS = (
    "policy", "n", "in_zone_median", "in_zone_mean", "in_zone_ci_low", "in_zone_ci_high",
    "in_zone_p10", "in_zone_mean_reachable", "in_zone_p10_reachable", "in_zone_strap_median",
    "above_hrr70_s_median", "above_hrr70_s_p90",
    "adaptations_per_10min_median", "cooldown_end_frac_hrr_median", "unreachable_share",
    "out_of_reach_share", "at_least_threshold_share",
)
#: The goals of issue 24 for the best new policy, on every participant model: (column, comparison, value).
GOALS = (
    ("in_zone_median", ">=", 0.98),
    ("in_zone_p10", ">=", 0.85),
    ("in_zone_mean_reachable", ">=", 0.97),
    ("above_hrr70_s_p90", "<=", 30.0),
    ("at_least_threshold_share", ">=", 0.95),
    ("adaptations_per_10min_median", "<=", 3.0),
)
REFERENCES = ("threshold", "fuzzy")


def median_ci(values: np.ndarray, seed: int, resamples: int = 2000) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the median."""
    values = values[np.isfinite(values)]
    if len(values) < 2 or np.all(values == values[0]):
        v = float(values[0]) if len(values) else math.nan
        return v, v
    res = stats.bootstrap((values,), np.median, confidence_level=0.95, n_resamples=resamples,
                          method="percentile", random_state=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def summarise(sessions: pd.DataFrame, seed: int, policies: Sequence[str] | None = None,
              resamples: int = 2000) -> pd.DataFrame:
    """One row per policy (in the order given), columns :data:`SUMMARY_COLUMNS`."""
    rows = []
    reference = sessions[sessions["policy"] == "threshold"].set_index("participant")["in_zone"]
    for policy in policies or list(dict.fromkeys(sessions["policy"])):
        s = sessions[sessions["policy"] == policy]
        mine = s.set_index("participant")["in_zone"]
        both = mine.index.intersection(reference.index)
        # At least as good as threshold, paired (a tenth of a point of slack for float rounding).
        at_least = (float(np.mean(mine.loc[both].to_numpy() >= reference.loc[both].to_numpy() - 1e-3))
                    if len(both) else math.nan)
        x = s["in_zone"].to_numpy(dtype=float)
        low, high = median_ci(x, seed, resamples)
        reachable = s[s["reachable"].astype(bool)]
        x_reachable = reachable["in_zone"].to_numpy(dtype=float)
        rows.append({
            "policy": policy, "n": len(s), "in_zone_median": float(np.nanmedian(x)),
            "in_zone_mean": float(np.nanmean(x)), "in_zone_ci_low": low, "in_zone_ci_high": high,
            "in_zone_p10": float(np.nanpercentile(x, 10)) if np.isfinite(x).any() else math.nan,
            "in_zone_mean_reachable": float(reachable["in_zone"].mean()) if len(reachable) else math.nan,
            "in_zone_p10_reachable": (float(np.nanpercentile(x_reachable, 10))
                                      if np.isfinite(x_reachable).any() else math.nan),
            "in_zone_strap_median": float(s["in_zone_strap"].median()),
            "above_hrr70_s_median": float(s["above_hrr70_s"].median()),
            "above_hrr70_s_p90": float(s["above_hrr70_s"].quantile(0.9)),
            "adaptations_per_10min_median": float(s["adaptations_per_10min"].median()),
            "cooldown_end_frac_hrr_median": float(s["cooldown_end_frac_hrr"].median()),
            "unreachable_share": float(1.0 - s["reachable"].astype(bool).mean()),
            "out_of_reach_share": float(s["reach"].isin((BELOW, ABOVE)).mean()),
            "at_least_threshold_share": at_least,
        })
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def paired(sessions: pd.DataFrame, policy: str, reference: str, metric: str = "in_zone") -> dict[str, Any]:
    """``policy`` minus ``reference`` on the same people: median and mean difference, Wilcoxon p."""
    a = sessions[sessions["policy"] == policy].set_index("participant")[metric]
    b = sessions[sessions["policy"] == reference].set_index("participant")[metric]
    both = a.index.intersection(b.index)
    diff = (a.loc[both] - b.loc[both]).to_numpy(dtype=float)
    diff = diff[np.isfinite(diff)]
    p = math.nan
    if len(diff) and np.any(diff != 0):
        p = float(stats.wilcoxon(diff).pvalue)
    return {"policy": policy, "reference": reference, "n": len(diff),
            "median_diff": float(np.median(diff)) if len(diff) else math.nan,
            "mean_diff": float(np.mean(diff)) if len(diff) else math.nan,
            "better": int(np.sum(diff > 0)), "worse": int(np.sum(diff < 0)), "p": p}


def comparisons(sessions: pd.DataFrame, references: Sequence[str] = REFERENCES) -> pd.DataFrame:
    present = list(dict.fromkeys(sessions["policy"]))
    rows = [paired(sessions, policy, ref) for ref in references if ref in present
            for policy in present if policy != ref]
    return pd.DataFrame(rows, columns=["policy", "reference", "n", "median_diff", "mean_diff", "better",
                                       "worse", "p"])


def goals_met(row: pd.Series) -> dict[str, bool]:
    """Per goal of :data:`GOALS`, whether a summary row meets it (a missing figure does not)."""
    out = {}
    for column, op, value in GOALS:
        x = float(row[column])
        out[column] = math.isfinite(x) and (x >= value - 1e-9 if op == ">=" else x <= value + 1e-9)
    return out


def p10_out_of_reach(row: pd.Series) -> bool:
    """More than a tenth of the people settle on one side of the zone at every setting of the policy's
    controls: the tenth percentile is then one of them, whatever the policy does."""
    return float(row["out_of_reach_share"]) > 0.10


def _out_of_reach_note(row: pd.Series) -> str:
    """What a missed p10 adds when no policy could meet it ("" when one could)."""
    if not p10_out_of_reach(row):
        return ""
    return f" ({100 * float(row['out_of_reach_share']):.1f} % out of reach)"


def missed_goals(row: pd.Series) -> list[str]:
    """The goals a summary row misses; a missed p10 says when no policy could meet it."""
    met = goals_met(row)
    missed = []
    for column, _, _ in GOALS:
        if met[column] or (column == "at_least_threshold_share" and row["policy"] == "threshold"):
            continue
        missed.append(column + (_out_of_reach_note(row) if column == "in_zone_p10" else ""))
    return missed


def goals_table(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per policy: each goal's figure with 'ok' or 'MISSED'."""
    rows = []
    for _, r in summary.iterrows():
        met = goals_met(r)
        row: dict[str, Any] = {"policy": r["policy"]}
        for column, op, value in GOALS:
            verdict = "ok" if met[column] else "MISSED"
            if column == "in_zone_p10" and not met[column]:
                verdict += _out_of_reach_note(r)
            row[f"{column} {op} {value:g}"] = f"{_cell(float(r[column]))} {verdict}"
        row["all"] = "yes" if all(met.values()) else "no"
        rows.append(row)
    return pd.DataFrame(rows)


def models_table(summaries: Sequence[tuple[str, pd.DataFrame]]) -> str:
    """Markdown: one row per (participant model, policy) of ``hri_physio_evaluate`` summaries, with the
    goals each row misses (for README and docs/EVALUATION.md: generated, not typed)."""
    head = ("| model | policy | median | p10 | mean | mean, reachable | p10, reachable | s above HRR70 (p90) "
            "| >= threshold | adaptations / 10 min (median) | unreachable | median, strap | goals missed |")
    lines = [head, "|" + "---|" * 13]
    for model, summary in summaries:
        for _, r in summary.iterrows():
            missed = missed_goals(r)

            def pct(x: float) -> str:
                return "-" if not math.isfinite(x) else f"{100 * x:.1f} %"
            lines.append(
                f"| {model} | {r['policy']} | {pct(r['in_zone_median'])} | {pct(r['in_zone_p10'])} | "
                f"{pct(r['in_zone_mean'])} | {pct(r['in_zone_mean_reachable'])} | "
                f"{pct(r['in_zone_p10_reachable'])} | {r['above_hrr70_s_p90']:.0f} | "
                f"{pct(r['at_least_threshold_share'])} | {r['adaptations_per_10min_median']:.1f} | "
                f"{pct(r['unreachable_share'])} | {pct(r['in_zone_strap_median'])} | "
                f"{', '.join(missed) if missed else 'none'} |")
    return "\n".join(lines)


def winner(summary: pd.DataFrame) -> str:
    """The policy with the most conditioning time in zone (mean; median breaks ties)."""
    best = summary.sort_values(["in_zone_mean", "in_zone_median"], ascending=False)
    return str(best.iloc[0]["policy"])


def sensitivity(sessions: pd.DataFrame, best: str, policies: Sequence[str]) -> pd.DataFrame:
    """Per model variant: each policy's in-zone median and mean, and whether ``best`` still wins."""
    rows = []
    for variant, s in sessions.groupby("variant", sort=False):
        row: dict[str, Any] = {"variant": variant}
        for policy in policies:
            x = s[s["policy"] == policy]["in_zone"]
            row[f"{policy}_median"] = float(x.median()) if len(x) else math.nan
            row[f"{policy}_mean"] = float(x.mean()) if len(x) else math.nan
        others = [p for p in policies if p != best and p in set(s["policy"])]
        ps = {ref: paired(s, best, ref) for ref in others}
        row["winner_still_best"] = all(c["mean_diff"] > 0 and c["p"] < 0.01 for c in ps.values())
        for ref, c in ps.items():
            row[f"p_vs_{ref}"] = c["p"]
        rows.append(row)
    return pd.DataFrame(rows)


# --- markdown -------------------------------------------------------------------------------------
def _cell(value: Any) -> str:
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        if not math.isfinite(value):
            return "-"
        return f"{value:.3g}" if abs(value) < 1e-3 and value != 0 else f"{value:.3f}".rstrip("0").rstrip(".")
    return str(value)


def markdown_table(df: pd.DataFrame, p_columns: Sequence[str] = ()) -> str:
    """A GitHub markdown table (p-values in scientific notation)."""
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    rule = "|" + "|".join("---" for _ in df.columns) + "|"
    lines = [head, rule]
    for _, r in df.iterrows():
        cells = [(f"{r[c]:.2g}" if c in p_columns and isinstance(r[c], float) and math.isfinite(r[c])
                  else _cell(r[c])) for c in df.columns]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_markdown(summary: pd.DataFrame, comps: pd.DataFrame, sens: pd.DataFrame | None,
                     command: str, cohort: int, seed: int, plots: Sequence[str],
                     model: str = "standard") -> str:
    parts = [
        f"# Policy evaluation: {cohort} simulated people, seed {seed}, participant model {model}",
        "",
        f"Command: `{command}`",
        "",
        "In-zone = fraction of conditioning time with the participant's true heart rate inside the coach's "
        "zone (HRR40-HRR70 of its calibrated rest and age-predicted maximum); `in_zone_strap_median`: the "
        "same on the strap's 5-s smoothed heart rate, artefacts in. CI: bootstrap 95 % of the median. "
        "`in_zone_mean_reachable`, `in_zone_p10_reachable`: mean and tenth percentile over the people whose "
        "zone the policy's controls can reach in the model; `unreachable_share`: the others; "
        "`out_of_reach_share`: those every setting leaves below (or above) the zone. A missed p10 says "
        "'out of reach' when that share is over 10 %: no policy with these controls could meet it.",
        "",
        markdown_table(summary),
        "",
        "## Goals (issue 24; `at_least_threshold_share`: people with at least threshold's in-zone time, "
        "paired)",
        "",
        markdown_table(goals_table(summary)),
        "",
        "## Paired differences (same people, policy minus reference; Wilcoxon signed-rank, two-sided)",
        "",
        markdown_table(comps, p_columns=("p",)) if len(comps) else "(no reference policy in this run)",
    ]
    if sens is not None and len(sens):
        parts += ["", "## Sensitivity: each assumed model parameter at an end of its range, for everyone", "",
                  markdown_table(sens, p_columns=[c for c in sens.columns if c.startswith("p_vs_")])]
    if plots:
        parts += ["", "## Plots", ""] + [f"![{name}]({name})" for name in plots]
    return "\n".join(parts) + "\n"

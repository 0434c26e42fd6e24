"""Per-policy summary, paired comparisons and the sensitivity table, on tables with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from hri_physio_coach.evaluate.summary import (
    SUMMARY_COLUMNS,
    comparisons,
    goals_met,
    goals_table,
    markdown_table,
    median_ci,
    missed_goals,
    models_table,
    paired,
    sensitivity,
    summarise,
    winner,
)


def sessions(variant: str = "main", shift: float = 0.2) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    n = 40
    base = rng.uniform(0.3, 0.8, n)
    rows = []
    for policy, x in (("threshold", base), ("fuzzy", base + rng.normal(0, 0.02, n)),
                      ("predictive", np.minimum(base + shift, 1.0))):
        for i in range(n):
            rows.append({"variant": variant, "policy": policy, "participant": i, "in_zone": float(x[i]),
                         "in_zone_strap": float(x[i]) - 0.05,
                         "reachable": i % 4 != 0,
                         "reach": "reachable" if i % 4 else ("below", "gap")[i % 8 // 4],
                         "above_hrr70_s": i % 3, "adaptations_per_10min": 1.0,
                         "cooldown_end_frac_hrr": 0.3})
    return pd.DataFrame(rows)


def test_summary_columns_and_values() -> None:
    df = sessions()
    s = summarise(df, seed=1, resamples=500)
    assert list(s.columns) == list(SUMMARY_COLUMNS)
    assert list(s["policy"]) == ["threshold", "fuzzy", "predictive"]
    row = s.set_index("policy").loc["predictive"]
    x = df[df.policy == "predictive"]["in_zone"]
    assert row["n"] == 40
    assert row["in_zone_median"] == pytest.approx(x.median())
    assert row["in_zone_mean"] == pytest.approx(x.mean())
    assert row["in_zone_ci_low"] <= row["in_zone_median"] <= row["in_zone_ci_high"]
    reachable = df[(df.policy == "predictive") & df.reachable]["in_zone"]
    assert row["in_zone_mean_reachable"] == pytest.approx(reachable.mean())
    assert row["in_zone_p10_reachable"] == pytest.approx(np.percentile(reachable, 10))
    assert row["in_zone_p10_reachable"] != pytest.approx(row["in_zone_p10"])
    assert row["in_zone_strap_median"] == pytest.approx(x.median() - 0.05)
    assert row["unreachable_share"] == pytest.approx(0.25)
    assert row["out_of_reach_share"] == pytest.approx(0.125)  # not those in a gap: alternating serves them
    assert row["above_hrr70_s_median"] == 1.0
    assert winner(s) == "predictive"


def test_median_ci_is_seeded_and_brackets_the_median() -> None:
    x = np.random.default_rng(0).normal(0.7, 0.1, 100)
    assert median_ci(x, 5) == median_ci(x, 5)
    low, high = median_ci(x, 5)
    assert low < np.median(x) < high and high - low < 0.1
    assert median_ci(np.full(10, 0.5), 1) == (0.5, 0.5)  # no spread, no interval


def test_paired_comparison_is_scipy_wilcoxon_on_the_same_people() -> None:
    df = sessions()
    c = paired(df, "predictive", "threshold")
    a = df[df.policy == "predictive"].sort_values("participant")["in_zone"].to_numpy()
    b = df[df.policy == "threshold"].sort_values("participant")["in_zone"].to_numpy()
    assert c["p"] == pytest.approx(stats.wilcoxon(a - b).pvalue)
    assert c["better"] == int(np.sum(a > b)) and c["worse"] == 0 and c["n"] == 40
    assert c["median_diff"] == pytest.approx(np.median(a - b))
    table = comparisons(df)
    assert set(table["reference"]) == {"threshold", "fuzzy"}
    same = paired(df, "threshold", "threshold")
    assert np.isnan(same["p"]) and same["mean_diff"] == 0  # no difference, no test


def test_sensitivity_table_says_whether_the_winner_still_wins() -> None:
    df = pd.concat([sessions("main"), sessions("tau_on=20"), sessions("gesture_gain=0", shift=0.0)])
    table = sensitivity(df, "predictive", ["threshold", "fuzzy", "predictive"]).set_index("variant")
    assert table.loc["main", "winner_still_best"] and table.loc["tau_on=20", "winner_still_best"]
    assert not table.loc["gesture_gain=0", "winner_still_best"]  # no better than threshold there
    assert table.loc["main", "p_vs_threshold"] < 0.01


def test_markdown_table() -> None:
    df = pd.DataFrame([{"policy": "a", "x": 0.12345, "ok": True, "p": 0.000123}])
    assert markdown_table(df, p_columns=("p",)).splitlines() == [
        "| policy | x | ok | p |", "|---|---|---|---|", "| a | 0.123 | yes | 0.00012 |"]


def goal_row(policy: str = "adaptive", p10: float = 0.9, out_of_reach: float = 0.05,
             **figures: float) -> pd.Series:
    row = {"policy": policy, "in_zone_median": 0.99, "in_zone_mean": 0.95, "in_zone_p10": p10,
           "in_zone_mean_reachable": 0.98, "in_zone_p10_reachable": 0.95, "in_zone_strap_median": 0.97,
           "above_hrr70_s_p90": 10.0, "at_least_threshold_share": 0.97, "adaptations_per_10min_median": 1.0,
           "unreachable_share": out_of_reach + 0.02, "out_of_reach_share": out_of_reach}
    return pd.Series({**row, **figures})


def test_goals_are_checked_against_each_limit_and_a_missed_p10_says_when_no_policy_could_meet_it() -> None:
    assert all(goals_met(goal_row()).values())
    assert missed_goals(goal_row()) == []
    assert missed_goals(goal_row(in_zone_median=0.979, above_hrr70_s_p90=31.0)) == [
        "in_zone_median", "above_hrr70_s_p90"]
    # p10 missed while nine people in ten could reach the zone: the policy's miss, said plainly.
    assert missed_goals(goal_row(p10=0.5, out_of_reach=0.08)) == ["in_zone_p10"]
    assert missed_goals(goal_row(p10=0.5, out_of_reach=0.10)) == ["in_zone_p10"]
    # More than a tenth stay on one side of it at every setting: the tenth percentile is one of them.
    assert missed_goals(goal_row(p10=0.0, out_of_reach=0.125)) == ["in_zone_p10 (12.5 % out of reach)"]
    # Threshold is the reference: "at least as good as threshold" is not a goal it can miss.
    assert missed_goals(goal_row("threshold", at_least_threshold_share=0.5)) == []
    assert missed_goals(goal_row("fuzzy", at_least_threshold_share=0.5)) == ["at_least_threshold_share"]


def test_goals_and_models_tables_show_each_figure_and_what_is_missed() -> None:
    summary = pd.DataFrame([goal_row(), goal_row("predictive", p10=0.0, out_of_reach=0.125)])
    table = goals_table(summary).set_index("policy")
    assert table.loc["adaptive", "all"] == "yes"
    assert table.loc["predictive", "in_zone_p10 >= 0.85"] == "0 MISSED (12.5 % out of reach)"
    assert table.loc["predictive", "in_zone_median >= 0.98"] == "0.99 ok"
    lines = models_table([("vagal", summary)]).splitlines()
    assert len(lines) == 4 and all(line.count("|") == 14 for line in lines)
    assert lines[2].startswith("| vagal | adaptive | 99.0 % | 90.0 % |") and lines[2].endswith("| none |")
    assert "| 14.5 % | 97.0 % | in_zone_p10 (12.5 % out of reach) |" in lines[3]

"""Per-policy summary, paired comparisons and the sensitivity table, on tables with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from hri_physio_coach.evaluate.summary import (
    SUMMARY_COLUMNS,
    comparisons,
    markdown_table,
    median_ci,
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
                         "reachable": i % 4 != 0, "above_hrr70_s": i % 3, "adaptations_per_10min": 1.0,
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
    assert row["unreachable_share"] == pytest.approx(0.25)
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

"""The evaluation table per participant model, from hri_physio_evaluate's output directories.

    python bench/evaluation_tables.py standard=eval_standard vagal=eval_vagal vo2drive=eval_vo2drive

Prints one markdown table (model, policy, median, p10, mean, mean over the reachable, p90 of seconds
above HRR70, share of people at least as good as threshold, adaptations, unreachable, goals of issue
24 missed) read from each directory's summary.csv: the README's and docs/EVALUATION.md's tables are
this output, not typed by hand.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from hri_physio_coach.evaluate.summary import models_table


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    runs = []
    for arg in argv:
        model, _, folder = arg.partition("=")
        runs.append((model, pd.read_csv(Path(folder) / "summary.csv")))
    print(models_table(runs))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""The same sessions in one process, in a process pool and on a Dask cluster give the same rows."""

from __future__ import annotations

import pandas as pd
import pytest

from hri_physio_coach.evaluate.cohort import make_cohort
from hri_physio_coach.evaluate.evaluation import tasks_for
from hri_physio_coach.evaluate.runner import run_tasks


@pytest.fixture(scope="module")
def tasks():
    return tasks_for(make_cohort(5, seed=4), ["threshold", "fuzzy", "predictive"], seed=4, traces=1)


@pytest.fixture(scope="module")
def serial(tasks) -> pd.DataFrame:
    return pd.DataFrame([r.row for r in run_tasks(tasks, jobs=1, progress=False)])


def test_process_pool_matches_one_process(tasks, serial) -> None:
    results = run_tasks(tasks, jobs=2, progress=False)
    pd.testing.assert_frame_equal(serial, pd.DataFrame([r.row for r in results]))
    traced = [r.trace for r in results if r.trace is not None]
    assert {(t["policy"], t["participant"]) for t in traced} == {
        (p, 0) for p in ("threshold", "fuzzy", "predictive")}


def test_dask_cluster_matches_one_process(tasks, serial) -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        results = run_tasks(tasks, scheduler=cluster.scheduler_address, progress=False)
    pd.testing.assert_frame_equal(serial, pd.DataFrame([r.row for r in results]))

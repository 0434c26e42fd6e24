"""How fast hri_physio_evaluate runs: one session per policy, then a whole cohort in parallel.

Goals (issues 14, 24): one 23-minute session <= 0.5 s; 200 people x 5 policies x 3 participant models
<= 3 min on this machine's cores. Prints measured figures side by side with the goals; asserts nothing (the
machine may be shared).

    python bench/bench_evaluate.py                 # 10 sessions per policy, then 200 people x 3 models
    python bench/bench_evaluate.py --cohort 50     # a smaller cohort
    python bench/bench_evaluate.py --sessions-only
    python bench/bench_evaluate.py --baseline-ref HEAD~3   # the cohort on commit HEAD~3's sources too

``--baseline-ref REF`` runs the same cohort on the sources of git commit REF first (``git archive``
into a temporary folder, first on PYTHONPATH) and prints both, and their ratio, side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from baseline import source_tree

from hri_physio_coach.evaluate.cohort import make_cohort
from hri_physio_coach.evaluate.evaluation import tasks_for
from hri_physio_coach.evaluate.runner import default_jobs, run_task, run_tasks

POLICIES = ["static", "threshold", "fuzzy", "predictive", "adaptive"]
MODELS = ["standard", "vagal", "vo2drive"]
SESSION_GOAL_S = 0.5
COHORT_GOAL_S = 180.0  # 200 people x 5 policies x 3 models
SESSION_LENGTH_S = 23 * 60


def one_session_times(n: int, seed: int) -> dict[str, tuple[float, float]]:
    """Per policy: median wall and CPU seconds of one session (simulation + metrics), in this process."""
    people = make_cohort(n, seed)
    out = {}
    run_task(tasks_for(people[:1], ["predictive"], seed)[0])  # warm caches (routine file, imports)
    for policy in POLICIES:
        walls, cpus = [], []
        for task in tasks_for(people, [policy], seed):
            w, c = time.perf_counter(), time.process_time()
            run_task(task)
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        out[policy] = (statistics.median(walls), statistics.median(cpus))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sessions", type=int, default=10, help="sessions per policy, per-session time")
    parser.add_argument("--cohort", type=int, default=200, help="people in the parallel run")
    parser.add_argument("--jobs", type=int, default=0, help="worker processes (0: every core)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--models", default=",".join(MODELS), help="participant models, comma-separated")
    parser.add_argument("--sessions-only", action="store_true", help="skip the parallel cohort run")
    parser.add_argument("--baseline-ref", metavar="REF",
                        help="also run the cohort on the sources of git commit REF first, side by side")
    parser.add_argument("--cohort-json", action="store_true", help=argparse.SUPPRESS)  # the baseline's child
    args = parser.parse_args()
    jobs = args.jobs or default_jobs()
    models = [m for m in args.models.split(",") if m]
    if args.cohort_json:
        print(json.dumps({"wall": cohort_wall(args.cohort, args.seed, models, jobs)}))
        return
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"cores available: {default_jobs()}, load average: {load} (other work on the machine slows this)")
    print(f"\none 23-min session (median of {args.sessions}; goal <= {SESSION_GOAL_S} s):")
    print(f"  {'policy':<12} {'wall s':>8} {'cpu s':>8} {'x real time':>12}")
    times = one_session_times(args.sessions, args.seed)
    for policy, (wall, cpu) in times.items():
        print(f"  {policy:<12} {wall:>8.3f} {cpu:>8.3f} {SESSION_LENGTH_S / wall:>12.0f}")
    if args.sessions_only:
        return
    n_sessions = args.cohort * len(POLICIES) * len(models)
    base = None
    if args.baseline_ref:
        with tempfile.TemporaryDirectory(prefix="bench_evaluate_") as tmp:
            env = source_tree(args.baseline_ref, Path(tmp))
            child = [sys.executable, __file__, "--cohort-json", "--cohort", str(args.cohort), "--seed",
                     str(args.seed), "--models", ",".join(models), "--jobs", str(jobs)]
            out = subprocess.run(child, env=env, check=True, capture_output=True, text=True).stdout
        base = json.loads(out.strip().splitlines()[-1])["wall"]
    wall = cohort_wall(args.cohort, args.seed, models, jobs)
    per = wall / n_sessions
    projected = per * 200 * 5 * 3
    print(f"\n{args.cohort} people x {len(POLICIES)} policies x {len(models)} models on {jobs} processes: "
          f"{wall:.1f} s wall ({per * 1000:.0f} ms per session, {n_sessions / wall:.1f} sessions/s)")
    if base is not None:
        print(f"  the same on {args.baseline_ref}'s sources, run just before: {base:.1f} s wall "
              f"(now / then: {wall / base:.2f})")
    print(f"  projected 200 people x 5 policies x 3 models: {projected:.0f} s "
          f"(goal <= {COHORT_GOAL_S:.0f} s, "
          f"ratio {projected / COHORT_GOAL_S:.2f})")


def cohort_wall(cohort: int, seed: int, models: list[str], jobs: int) -> float:
    """Wall seconds of every policy's session for ``cohort`` people of each model, on ``jobs`` processes."""
    tasks = []
    for model in models:
        tasks += tasks_for(make_cohort(cohort, seed, model=model), POLICIES, seed)
    start = time.perf_counter()
    run_tasks(tasks, jobs=jobs, progress=False)
    return time.perf_counter() - start


if __name__ == "__main__":
    main()

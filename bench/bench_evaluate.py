"""How fast hri_physio_evaluate runs: one session per policy, then a whole cohort in parallel.

Goals (issues 14, 24): one 23-minute session <= 0.5 s; 200 people x 5 policies x 3 participant models
<= 3 min on this machine's cores. Prints measured figures side by side with the goals; asserts nothing (the
machine may be shared).

    python bench/bench_evaluate.py                 # 10 sessions per policy, then 200 people x 3 models
    python bench/bench_evaluate.py --cohort 50     # a smaller cohort
    python bench/bench_evaluate.py --sessions-only
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

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
    args = parser.parse_args()
    jobs = args.jobs or default_jobs()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"cores available: {default_jobs()}, load average: {load} (other work on the machine slows this)")
    print(f"\none 23-min session (median of {args.sessions}; goal <= {SESSION_GOAL_S} s):")
    print(f"  {'policy':<12} {'wall s':>8} {'cpu s':>8} {'x real time':>12}")
    times = one_session_times(args.sessions, args.seed)
    for policy, (wall, cpu) in times.items():
        print(f"  {policy:<12} {wall:>8.3f} {cpu:>8.3f} {SESSION_LENGTH_S / wall:>12.0f}")
    if args.sessions_only:
        return
    models = [m for m in args.models.split(",") if m]
    tasks = []
    for model in models:
        tasks += tasks_for(make_cohort(args.cohort, args.seed, model=model), POLICIES, args.seed)
    start = time.perf_counter()
    run_tasks(tasks, jobs=jobs, progress=False)
    wall = time.perf_counter() - start
    per = wall / len(tasks)
    projected = per * 200 * 5 * 3
    print(f"\n{args.cohort} people x {len(POLICIES)} policies x {len(models)} models on {jobs} processes: "
          f"{wall:.1f} s wall ({per * 1000:.0f} ms per session, {len(tasks) / wall:.1f} sessions/s)")
    print(f"  projected 200 people x 5 policies x 3 models: {projected:.0f} s "
          f"(goal <= {COHORT_GOAL_S:.0f} s, "
          f"ratio {projected / COHORT_GOAL_S:.2f})")


if __name__ == "__main__":
    main()

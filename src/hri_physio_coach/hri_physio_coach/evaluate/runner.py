"""Running many sessions: one task per (policy, person), in parallel, with a progress bar.

By default the tasks go to a pool of ``jobs`` processes on this machine; with a scheduler
address they go to an existing Dask distributed cluster instead (the same task function, so
a sweep that outgrows one machine gives the same numbers). Results come back in task order
whatever order they finish in.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

from tqdm import tqdm

from hri_physio_coach.config import CoachConfig
from hri_physio_coach.evaluate.metrics import phase_spans, session_metrics
from hri_physio_coach.evaluate.reach import reach
from hri_physio_coach.evaluate.simulation import SessionSpec, coach_config, session_routine, simulate_session
from hri_physio_coach.policies.registry import make_policy
from hri_physio_coach.policies.simple import StaticPolicy

#: Sessions per task sent to a worker: large enough to hide the hand-over, small enough to balance.
CHUNK = 8


@dataclass(frozen=True)
class Task:
    spec: SessionSpec
    keep_trace: bool = False


@dataclass
class Result:
    row: dict[str, Any]
    trace: dict[str, Any] | None = None


def run_task(task: Task, base: dict[str, Any] | None = None) -> Result:
    """Simulate one session and measure it (the unit of work of every executor)."""
    spec = task.spec
    base_cfg = CoachConfig.from_mapping(base, "coach configuration") if base else None
    run = simulate_session(spec, base_cfg)
    cfg = coach_config(spec, base_cfg)
    routine = session_routine(cfg)
    zone = run.of("zone")[-1]
    policy = make_policy(spec.policy)
    conditioning = next(p.name for p in routine.phases if p.kind == "conditioning")
    verdict = reach(spec.params, float(zone["low"]), float(zone["high"]), routine, conditioning,
                    tuple(cfg.speed_modifier), tuple(cfg.audio_suffix), cfg.speed_idx,
                    adapts=not isinstance(policy, StaticPolicy),
                    chooses_activity=bool(getattr(policy, "chooses_activity", False)))
    row = session_metrics(run, verdict)
    trace = None
    if task.keep_trace:
        trace = {"policy": spec.policy, "participant": spec.participant, "t": run.t, "hr": run.hr,
                 "model_hr": run.model_hr, "ladder": run.ladder, "mets": run.mets,
                 "zone": (float(zone["low"]), float(zone["high"])), "phases": phase_spans(run)}
    return Result(row, trace)


def run_chunk(tasks: Sequence[Task], base: dict[str, Any] | None = None) -> list[Result]:
    return [run_task(t, base) for t in tasks]


def _chunks(tasks: Sequence[Task], size: int) -> list[list[Task]]:
    return [list(tasks[i:i + size]) for i in range(0, len(tasks), size)]


def default_jobs() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


Done = Iterator[tuple[int, list[Result]]]  # (chunk index, its results), as chunks finish


def _local(chunks: list[list[Task]], base: dict[str, Any] | None, jobs: int) -> Done:
    if jobs == 1:
        for i, chunk in enumerate(chunks):
            yield i, run_chunk(chunk, base)
        return
    pool = ProcessPoolExecutor(max_workers=jobs)
    try:
        pending: dict[Future[list[Result]], int] = {pool.submit(run_chunk, c, base): i
                                                    for i, c in enumerate(chunks)}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()
    finally:
        # Ended early (Ctrl-C, an error): the chunks not started are dropped, not run to the end first.
        pool.shutdown(wait=True, cancel_futures=True)


def _dask(chunks: list[list[Task]], base: dict[str, Any] | None, scheduler: Any) -> Done:
    from distributed import Client, as_completed  # only when asked for: the default needs no cluster

    client = scheduler if isinstance(scheduler, Client) else Client(scheduler, timeout="20s")
    try:
        futures = client.map(run_chunk, chunks, base=base, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for future in as_completed(futures):
            yield index[future.key], future.result()
    finally:
        if client is not scheduler:
            client.close()


def run_tasks(tasks: Sequence[Task], base: dict[str, Any] | None = None, jobs: int = 0,
              scheduler: Any = None, progress: bool = True, label: str = "sessions",
              on_result: Callable[[Result], None] | None = None) -> list[Result]:
    """Every task's result, in task order.

    ``scheduler``: a Dask scheduler address (or a ``distributed.Client``); else ``jobs`` local processes.
    """
    chunks = _chunks(tasks, CHUNK)
    results: list[list[Result] | None] = [None] * len(chunks)
    source = (_dask(chunks, base, scheduler) if scheduler
              else _local(chunks, base, jobs if jobs > 0 else default_jobs()))
    with tqdm(total=len(tasks), desc=label, unit="session", disable=not progress, dynamic_ncols=True) as bar:
        for i, chunk_results in source:
            results[i] = chunk_results
            bar.update(len(chunk_results))
            if on_result is not None:
                for r in chunk_results:
                    on_result(r)
    return [r for chunk in results for r in (chunk or [])]

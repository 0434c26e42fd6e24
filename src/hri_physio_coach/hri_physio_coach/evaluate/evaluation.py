"""The whole evaluation: cohort -> sessions (paired across policies) -> CSV, markdown, plots."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from hri_physio_bridge.config import ConfigError
from hri_physio_coach.config import COACH_NODE, CoachConfig
from hri_physio_coach.evaluate.cohort import ASSUMPTIONS, make_cohort, participant_seeds, variants
from hri_physio_coach.evaluate.config import EvaluateConfig
from hri_physio_coach.evaluate.plots import plot_in_zone, plot_traces
from hri_physio_coach.evaluate.runner import Result, Task, run_tasks
from hri_physio_coach.evaluate.simulation import SessionSpec
from hri_physio_coach.evaluate.summary import (
    comparisons,
    missed_goals,
    sensitivity,
    summarise,
    summary_markdown,
    winner,
)
from hri_physio_coach.participant.physiology import ParticipantParams

IN_ZONE_PLOT, TRACES_PLOT = "in_zone.png", "traces.png"


@dataclass
class Evaluation:
    out: Path
    sessions: pd.DataFrame
    summary: pd.DataFrame
    comparisons: pd.DataFrame
    sensitivity: pd.DataFrame | None


def prepare_out(path: str) -> Path:
    """The output directory, created and proven writable (ConfigError otherwise)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".hri_physio_evaluate_probe"
        probe.write_text("ok", encoding="utf-8")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"out: cannot write to {out}: {exc.strerror or exc}") from None
    return out


def base_coach_options(cfg: EvaluateConfig) -> dict[str, Any] | None:
    """The coach options the sessions run with (validated now, so a bad file fails before any work)."""
    if not cfg.coach_conf:
        return None
    return CoachConfig.from_file(cfg.coach_conf, COACH_NODE).as_dict()


def check_coach_for_people(people: list[ParticipantParams], base: dict[str, Any] | None) -> None:
    """Each session's coach takes the base options with its person's age: a rule between the two (the
    resting_default below that person's HR_max) fails here, naming the person, before any work."""
    for age in sorted({float(p.age) for p in people}):
        CoachConfig.from_mapping({**(base or {}), "part_age": age}, f"the coach for a person aged {age:g}")


def cohort_of(cfg: EvaluateConfig) -> list[ParticipantParams]:
    return make_cohort(cfg.cohort, cfg.seed, (cfg.age_min, cfg.age_max), cfg.population or None, cfg.model)


def tasks_for(people: list[ParticipantParams], policies: list[str], seed: int, variant: str = "main",
              traces: int = 0, hr_latency: float = 0.1) -> list[Task]:
    seeds = participant_seeds(seed, len(people))
    return [Task(SessionSpec(policy, i, p, seeds[i][0], seeds[i][1], variant, hr_latency),
                 keep_trace=i < traces)
            for policy in policies for i, p in enumerate(people)]


def run_evaluation(cfg: EvaluateConfig, people: list[ParticipantParams], out: Path,
                   base: dict[str, Any] | None = None, command: str = "hri_physio_evaluate",
                   scheduler: Any = None) -> Evaluation:
    """Run every session, write the result files into ``out`` and return the tables."""
    scheduler = scheduler if scheduler is not None else (cfg.scheduler or None)
    policies = list(cfg.policies)
    tasks = tasks_for(people, policies, cfg.seed, traces=cfg.traces, hr_latency=cfg.hr_latency)
    results = run_tasks(tasks, base, cfg.jobs, scheduler, cfg.progress, "sessions")
    sessions = pd.DataFrame([r.row for r in results])
    sessions.to_csv(out / "sessions.csv", index=False)
    summary = summarise(sessions, cfg.seed, policies, cfg.bootstrap)
    summary.to_csv(out / "summary.csv", index=False)
    comps = comparisons(sessions)
    sens = None
    if cfg.sensitivity:
        sens = _sensitivity(cfg, people, policies, summary, sessions, base, scheduler, out)
    plots = [plot_in_zone(sessions, policies, out / IN_ZONE_PLOT, cfg.seed).name]
    traces = [r.trace for r in results if r.trace is not None]
    if traces:
        plots.append(plot_traces(traces, policies, out / TRACES_PLOT).name)
    (out / "summary.md").write_text(
        summary_markdown(summary, comps, sens, command, len(people), cfg.seed, plots, cfg.model),
        encoding="utf-8")
    return Evaluation(out, sessions, summary, comps, sens)


def _sensitivity(cfg: EvaluateConfig, people: list[ParticipantParams], policies: list[str],
                 summary: pd.DataFrame, sessions: pd.DataFrame, base: dict[str, Any] | None, scheduler: Any,
                 out: Path) -> pd.DataFrame:
    """Every assumed parameter at both ends of its range (same people, same seeds), and the main run."""
    sub = people[:min(cfg.sensitivity_cohort, len(people))]
    best = winner(summary)
    chosen = list(cfg.sensitivity_policies) or list(policies)
    policies = [p for p in policies if p in chosen or p == best]
    tasks: list[Task] = []
    for name, group in variants(sub, ASSUMPTIONS):
        tasks += tasks_for(group, policies, cfg.seed, variant=name, hr_latency=cfg.hr_latency)
    results: list[Result] = run_tasks(tasks, base, cfg.jobs, scheduler, cfg.progress, "sensitivity")
    rows = pd.DataFrame([r.row for r in results])
    rows.to_csv(out / "sensitivity_sessions.csv", index=False)
    main = sessions[(sessions["participant"] < len(sub)) & sessions["policy"].isin(policies)]
    table = sensitivity(pd.concat([main, rows], ignore_index=True), best, policies)
    table.insert(1, "winner", best)
    table.to_csv(out / "sensitivity.csv", index=False)
    return table


def headline(ev: Evaluation) -> str:
    """A few lines for the terminal."""
    lines = [f"{'policy':<12} {'n':>4} {'median':>7} {'mean':>6} {'p10':>6} {'reach.':>7} {'p10 r.':>6} "
             f"{'>HRR70 s':>8} "
             f"{'p90 s':>6} {'>=thr':>6} {'adapt/10':>8} {'cd HRR':>6} {'unreach':>7}  goals (issue 24)"]
    for _, r in ev.summary.iterrows():
        def pct(x: float) -> str:
            return "-" if not math.isfinite(x) else f"{100 * x:.1f}"
        missed = missed_goals(r)
        lines.append(f"{r['policy']:<12} {r['n']:>4} {pct(r['in_zone_median']):>7} "
                     f"{pct(r['in_zone_mean']):>6} {pct(r['in_zone_p10']):>6} "
                     f"{pct(r['in_zone_mean_reachable']):>7} {pct(r['in_zone_p10_reachable']):>6} "
                     f"{r['above_hrr70_s_median']:>8.0f} "
                     f"{r['above_hrr70_s_p90']:>6.0f} {pct(r['at_least_threshold_share']):>6} "
                     f"{r['adaptations_per_10min_median']:>8.1f} {r['cooldown_end_frac_hrr_median']:>6.2f} "
                     f"{pct(r['unreachable_share']):>7}  "
                     + ("all met" if not missed else "missed: " + ", ".join(missed)))
    lines.append(f"written to {ev.out}: sessions.csv, summary.csv, summary.md, plots")
    return "\n".join(lines)

"""hri_physio_evaluate: every adaptation policy on the same simulated cohort, discrete-event.

Runs the coach the nodes run (engine, policies, routine) against the simulated participant
the nodes run, on one injected clock with no ROS and no LSL, for a seeded cohort, every
policy on the same people with the same random draws. Writes into --out:
sessions.csv (one row per policy and person), summary.csv and summary.md (per policy, paired
differences with Wilcoxon p-values, and with --sensitivity the sensitivity table), in_zone.png
and traces.png.

Examples::

    hri_physio_evaluate --cohort 200 --seed 1 --policies static,threshold,fuzzy,predictive --out eval
    hri_physio_evaluate --cohort 200 --seed 1 --sensitivity --out eval
    hri_physio_evaluate --scheduler tcp://10.0.0.5:8786 --cohort 2000 --out big
"""

from __future__ import annotations

import argparse
import shlex
import sys

from hri_physio_bridge.config import (
    ConfigError,
    OneLineErrorParser,
    add_config_arguments,
    given_options,
    load_yaml,
)
from hri_physio_coach.evaluate.cohort import PopulationError
from hri_physio_coach.evaluate.config import EvaluateConfig
from hri_physio_coach.evaluate.evaluation import (
    base_coach_options,
    check_coach_for_people,
    cohort_of,
    headline,
    prepare_out,
    run_evaluation,
)

PROG = "hri_physio_evaluate"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrorParser(prog=PROG, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--conf", help="YAML file with any of the options below (flags win)")
    add_config_arguments(parser, EvaluateConfig)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    try:
        values = load_yaml(args.conf, PROG) if args.conf else {}
        values.update(given_options(args, EvaluateConfig))
        cfg = EvaluateConfig.from_mapping(values, args.conf or "options")
        base = base_coach_options(cfg)
        people = cohort_of(cfg)
        check_coach_for_people(people, base)
        out = prepare_out(cfg.out)
    except (ConfigError, PopulationError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    command = " ".join([PROG, *map(shlex.quote, argv)])
    try:
        evaluation = run_evaluation(cfg, people, out, base, command)
    except OSError as exc:  # e.g. the scheduler cannot be reached, the disk filled up
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted before the evaluation finished: the files in {out} are not a "
              "complete result of this run", file=sys.stderr)
        return 130
    print(headline(evaluation))
    return 0


if __name__ == "__main__":
    sys.exit(main())

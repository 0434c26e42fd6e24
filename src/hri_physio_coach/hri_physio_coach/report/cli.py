"""hri_physio_report <session folder | bag directory | .mcap file> [--out DIR] [--hr-topic TOPIC]."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hri_physio_bridge.config import OneLineErrorParser
from hri_physio_coach.report.bagdata import ReportError
from hri_physio_coach.report.build import make_report

PROG = "hri_physio_report"


def build_parser() -> argparse.ArgumentParser:
    p = OneLineErrorParser(
        prog=PROG,
        description="Figures (hr_session.png, fuzzy_probability.png, fuzzy_overlay.png, hrv.png), "
        "report.json and a self-contained report.html of one recorded session. Works on a bag whose "
        "recorder was killed. docs/REPORT.md explains every number and figure.",
        epilog="Examples: hri_physio_report sessions/P01_2026-05-04_10-30-00  |  "
        "hri_physio_report bags/session_2026_05_04-10_30_00 --out /tmp/report",
    )
    p.add_argument("path", type=Path, help="a session folder, a rosbag2 directory or an .mcap file")
    p.add_argument("--out", type=Path, help="folder for the report files (default: the session folder, "
                   "or the parent folder of a bag directory)")
    p.add_argument("--hr-topic", help="the coach's heart-rate input topic (default: from the session's "
                   "configuration or the coach's log in the bag)")
    p.add_argument("--no-figures", action="store_true",
                   help="write report.json and report.html only (fast, e.g. for many sessions)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        result = make_report(args.path, args.out, args.hr_topic, figures=not args.no_figures)
    except ReportError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{PROG}: error: cannot write the report: {exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        for line in result.warnings:
            print(f"{PROG}: warning: {line}", file=sys.stderr)
        for line in result.missing:
            print(f"{PROG}: note: {line}", file=sys.stderr)
        names = ", ".join(p.name for p in result.files.values())
        print(f"{PROG}: wrote {names} to {result.out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

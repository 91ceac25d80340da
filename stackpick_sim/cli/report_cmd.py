"""``stackpick report``: report.md with plots for a run or sweep directory."""

from __future__ import annotations

import argparse
from pathlib import Path

from stackpick_sim.runs.report import write_report


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``report`` subcommand."""
    p = sub.add_parser(
        "report", help="write report.md with plots for a run or sweep directory",
        description="Writes DIR/report.md and PNG plots beside it: success rate vs. the "
        "swept parameter with 95 % intervals (sweeps), failure reasons, histograms of the "
        "detection centre/theta errors and the prediction error, the cycle time "
        "distribution; the failed seeds with their 'stackpick replay' commands; the "
        "paper's Tables 1 and 2. Needs matplotlib: pip install 'stackpick-sim[plot]'.")
    p.add_argument("dir", type=Path, help="the --out of 'stackpick run' or 'stackpick sweep'")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the report and say where."""
    path = write_report(args.dir)
    print(f"wrote {path} and its plots")
    return 0

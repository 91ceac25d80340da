"""``stackpick check``: the regression gate of a run against a baseline summary."""

from __future__ import annotations

import argparse
from pathlib import Path

from stackpick_sim.runs.check import (
    DEFAULT_ALPHA,
    DEFAULT_TOLERANCE,
    check,
    check_table,
    load_summary,
)

#: Exit code when the gate fails (2 is taken by bad input).
EXIT_REGRESSION = 1


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``check`` subcommand."""
    p = sub.add_parser(
        "check", help="fail when a run regresses against a baseline",
        description="Compare the run in DIR with BASELINE (a previous run's summary.json "
        "or run directory). Fails (exit 1) when the success rate is significantly lower "
        "(one-sided Fisher exact test, p < --alpha) or the median of an error statistic "
        "(detection centre/theta errors, prediction error, cycle time) exceeds "
        "baseline x (1 + --tolerance) + a small absolute floor. Prints a table either way.")
    p.add_argument("dir", type=Path, help="the run directory (or its summary.json) to check")
    p.add_argument("--baseline", type=Path, required=True,
                   help="the baseline: a summary.json or a run directory")
    p.add_argument("--alpha", type=float, default=DEFAULT_ALPHA,
                   help=f"significance level of the test (default: {DEFAULT_ALPHA})")
    p.add_argument("--tolerance", type=float, default=DEFAULT_TOLERANCE,
                   help="relative tolerance of the error medians (default: "
                   f"{DEFAULT_TOLERANCE})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Compare, print the table, return 0 (pass) or EXIT_REGRESSION."""
    rows = check(load_summary(args.dir), load_summary(args.baseline), alpha=args.alpha,
                 tolerance=args.tolerance)
    print(check_table(rows))
    passed = all(r.ok for r in rows)
    print("check: PASS" if passed else "check: FAIL (regression against the baseline)")
    return 0 if passed else EXIT_REGRESSION

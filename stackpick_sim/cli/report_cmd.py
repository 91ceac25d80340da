"""``stackpick report``: report.md and report.html with plots for a run or sweep directory."""

from __future__ import annotations

import argparse
from pathlib import Path

from stackpick_sim.runs.html_report import write_html
from stackpick_sim.runs.report import REPORT_FILE, write_report


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``report`` subcommand."""
    p = sub.add_parser(
        "report", help="write report.md and report.html with plots for a run or sweep",
        description="Writes DIR/report.md, DIR/report.html and PNG plots beside them: success "
        "rate vs. the swept parameter with 95 %% intervals (sweeps), failure reasons, the "
        "detection centre/theta errors and the prediction error, the cycle time (successes "
        "and failures apart, per cell for a sweep); the failed seeds with their reasons and "
        "'stackpick replay' commands; the paper's Tables 1 and 2. report.html is one "
        "self-contained page (open it in any browser): the same content, a thumbnail of each "
        "failed seed's wrist frame, links to replay videos made with the listed commands and "
        "a sortable table of every episode. Needs matplotlib: "
        "pip install 'stackpick-sim[plot]'.")
    p.add_argument("dir", type=Path, help="the --out of 'stackpick run' or 'stackpick sweep'")
    p.add_argument("--no-html", dest="html", action="store_false",
                   help="write report.md and the plots only (report.html regenerates each "
                   "failed seed's look-pose frame: about a second per failed seed)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the reports and say where."""
    data = write_report(args.dir)
    written = [str(args.dir / REPORT_FILE)]
    if args.html:
        written.append(str(write_html(data)))
    print(f"wrote {' and '.join(written)} with {len(data.plots)} plots")
    return 0

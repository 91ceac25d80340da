"""Reproduce the detection benchmark results in benchmarks/results/.

Runs ``stackpick bench-detect`` for the held-out paper seeds (frames from a data set written by
``stackpick dataset --scene paper --seeds 9000:10000 --out DATA``) and for the cluttered scene
(frames from a data set given by --cluttered-data, else rendered in-process). Usage::

    python benchmarks/bench_detect.py --paper-data DATA \\
        [--paper-seeds 9000:10000] [--cluttered-data DIR] [--cluttered-seeds 9000:9150]

The reported numbers are on seeds 9000-9999 (paper) and 9000-9149 (cluttered), which the
detector was never tuned on (paper seeds 0-6499 were: keep new work off the held-out
ranges; docs/figures.md lists every figure's seeds).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from stackpick_sim.cli.main import main

RESULTS = Path(__file__).resolve().parent / "results"


def run() -> int:
    """Run both benchmarks; return the first non-zero exit code, else 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--paper-data", type=Path, required=True)
    p.add_argument("--paper-seeds", default="9000:10000")
    p.add_argument("--cluttered-data", type=Path, default=None)
    p.add_argument("--cluttered-seeds", default="9000:9150")
    p.add_argument("--methods", default="ours,rht,findellipses,edgedrawing")
    args = p.parse_args()
    code = main(["bench-detect", "--data", str(args.paper_data), "--seeds", args.paper_seeds,
                 "--methods", args.methods, "--out", str(RESULTS / "paper_holdout")])
    source = (["--data", str(args.cluttered_data)] if args.cluttered_data is not None
              else ["--scene", "cluttered"])
    code2 = main(["bench-detect", *source, "--seeds", args.cluttered_seeds,
                  "--methods", args.methods, "--out", str(RESULTS / "cluttered")])
    return code or code2


if __name__ == "__main__":
    raise SystemExit(run())

"""Reproduce the detection benchmark results in benchmarks/results/.

Runs ``stackpick bench-detect`` for the held-out paper seeds (frames from a data set written by
``stackpick dataset --scene paper --seeds 1000:2000 --out DATA``) and for the cluttered scene
(rendered in-process). Usage::

    python benchmarks/bench_detect.py --paper-data /work/data/ds_paper_holdout \\
        [--paper-seeds 1000:2000] [--cluttered-seeds 0:200]

Development used seeds 0-299 of the paper scene; the reported numbers are on other seeds.
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
    p.add_argument("--paper-seeds", default="1000:2000")
    p.add_argument("--cluttered-seeds", default="0:200")
    p.add_argument("--methods", default="ours,rht,findellipses,edgedrawing")
    args = p.parse_args()
    code = main(["bench-detect", "--data", str(args.paper_data), "--seeds", args.paper_seeds,
                 "--methods", args.methods, "--out", str(RESULTS / "paper_holdout")])
    code2 = main(["bench-detect", "--scene", "cluttered", "--seeds", args.cluttered_seeds,
                  "--methods", args.methods, "--out", str(RESULTS / "cluttered")])
    return code or code2


if __name__ == "__main__":
    raise SystemExit(run())

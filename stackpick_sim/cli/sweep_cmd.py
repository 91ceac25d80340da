"""``stackpick sweep``: run a grid of scene settings over seeds; success rate per cell."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stackpick_sim.cli.common import DEFAULT_SEEDS, SEEDS_HELP, add_scene_args, parse_seeds
from stackpick_sim.cli.run_cmd import (
    add_execution_args,
    add_stage_args,
    executor_from_args,
    spec_from_args,
)
from stackpick_sim.files import write_text
from stackpick_sim.runs.lock import RunLock
from stackpick_sim.runs.runner import run_dirs
from stackpick_sim.runs.sweep import (
    cell_rows,
    load_sweep,
    parse_param,
    sweep_jobs,
    sweep_markdown,
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` subcommand."""
    p = sub.add_parser(
        "sweep", help="run pick episodes over a grid of scene settings",
        description="For every combination of the --param values (their product), run the "
        "seeds as 'stackpick run' would, into OUT/cells/<cell>/, and report the success "
        "rate with its 95 % Wilson interval per cell (OUT/sweep.md, "
        "OUT/sweep_summary.json). All cells share one pool of workers. --resume continues "
        "an interrupted sweep. 'stackpick report OUT' plots it.")
    add_scene_args(p)
    p.add_argument("--param", action="append", required=True, metavar="KEY=V1,V2,...",
                   help="a scene key and its values (TOML); repeatable: the grid is the "
                   "product, e.g. --param conveyor.speed=0.05,0.1,0.2,0.3")
    p.add_argument("--seeds", default=DEFAULT_SEEDS, metavar="SEEDS",
                   help=f"{SEEDS_HELP}; every cell runs them")
    add_stage_args(p)
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the grid, write the per-cell table, print it."""
    seeds = parse_seeds(args.seeds)
    params = [parse_param(t) for t in args.param]
    base = spec_from_args(args)
    with RunLock(args.out):
        jobs = sweep_jobs(args.out, base.scene, base.overrides, params, seeds,
                          resume=args.resume)
        stats = run_dirs(jobs, executor_from_args(args), resume=args.resume,
                         retry_unfinished=args.retry_unfinished, show_progress=not args.quiet)
        desc = load_sweep(args.out)
        rows = cell_rows(desc, stats.summaries)
        write_text(args.out / "sweep_summary.json", json.dumps(rows, indent=1))
        text = sweep_markdown(desc, rows)
        write_text(args.out / "sweep.md", text)
    print(text)
    print(f"ran {stats.ran} episodes ({stats.skipped} already recorded) in "
          f"{stats.wall_s:.1f} s: {stats.episodes_per_s:.3f} episodes/s")
    print(f"wrote {args.out}/sweep.md, sweep_summary.json, cells/; 'stackpick report "
          f"{args.out}' plots it")
    return 0

"""``stackpick run``: pick episodes over a seed range; results.jsonl, summary.md/json."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from stackpick_sim.cli.common import add_scene_args, parse_seeds
from stackpick_sim.config.scene_config import DETECTORS, TRACKER_FRAMES
from stackpick_sim.episodes.batch import RunSpec, run_batch
from stackpick_sim.episodes.summary import summarize, summary_markdown


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run`` subcommand."""
    p = sub.add_parser(
        "run", help="run pick episodes over seeds and summarise them",
        description="For each seed: build and settle the pile, then run one pick episode "
        "(look, detect, track, approach, servo, descend, grasp, lift, verify). Writes "
        "OUT/results.jsonl (one record per episode), OUT/summary.md and OUT/summary.json, "
        "and OUT/episodes/SEED/{scene.xml,initial_qpos.npy,final_qpos.npy} for audit and "
        "'stackpick replay'.")
    add_scene_args(p)
    p.add_argument("--seeds", default="0:10", help="N, START:STOP (end exclusive) or N,N,... "
                   "(default: 0:10)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (default: 1)")
    p.add_argument("--detector", choices=DETECTORS, default=None,
                   help="ours: the vision pipeline; oracle: ground-truth top object and pose "
                   "(default: the scene's episode.detector)")
    p.add_argument("--tracker", choices=TRACKER_FRAMES, default=None,
                   help="Kalman frame: belt (back-projected) or image (the paper's); default: "
                   "the scene's episode.tracker_frame")
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    p.add_argument("--quiet", action="store_true", help="no per-episode lines")
    p.set_defaults(func=run)


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """The scene and overrides to run, the --detector/--tracker shortcuts included."""
    overrides = list(args.overrides)
    if args.detector is not None:
        overrides.append(f"episode.detector={args.detector}")
    if args.tracker is not None:
        overrides.append(f"episode.tracker_frame={args.tracker}")
    return RunSpec(scene=args.scene, overrides=tuple(overrides))


def run(args: argparse.Namespace) -> int:
    """Run the batch, write the files, print the summary."""
    seeds = parse_seeds(args.seeds)

    def progress(rec: dict[str, Any]) -> None:
        if args.quiet:
            return
        if "error" in rec:
            print(f"seed {rec['seed']}: scene error: {rec['error']}", file=sys.stderr)
            return
        outcome = "ok" if rec["success"] else f"FAIL {rec['failure']}"
        print(f"seed {rec['seed']:5d}: {outcome:22s} cycle {rec['cycle_time_s'] or 0:.2f} s  "
              f"pred {rec['prediction_error_mm'] or float('nan'):.2f} mm  "
              f"wall {rec['wall_s']:.2f} s", flush=True)

    records = run_batch(spec_from_args(args), seeds, workers=args.workers, out=args.out,
                        progress=progress)
    print(summary_markdown(summarize(records)))
    print(f"wrote {args.out}/results.jsonl, summary.md, summary.json, episodes/")
    return 0

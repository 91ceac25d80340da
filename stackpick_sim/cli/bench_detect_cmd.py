"""``stackpick bench-detect``: our detector against the baselines on the same frames."""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

from tqdm import tqdm

from stackpick_sim.cli.common import (
    DEFAULT_SEEDS,
    SEEDS_HELP,
    add_scene_args,
    parse_seeds,
    scene_from_args,
)
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.files import write_text
from stackpick_sim.vision.benchmark import (
    METHOD_NAMES,
    make_methods,
    markdown,
    run_benchmark,
    summarise,
    table1,
)
from stackpick_sim.vision.benchmark.frames import (
    dataset_seeds,
    iter_dataset,
    iter_generated,
)
from stackpick_sim.vision.benchmark.scoring import COUNTED_VISIBLE_FRACTION, MATCH_IOU


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench-detect`` subcommand."""
    p = sub.add_parser(
        "bench-detect", help="benchmark top-object detection against the baselines",
        description="Run the methods on the same frames (read from --data, or rendered for "
        "--scene/--seeds) and write DIR/results.md and DIR/results.json: top-object success, "
        "precision/recall/F of all face ellipses, centre and theta errors, time per frame "
        "(one thread) with ratios to ours, and the paper's Table 1 layout.")
    add_scene_args(p)
    p.add_argument("--seeds", default=None, metavar="SEEDS",
                   help=f"{SEEDS_HELP}; with "
                   "--data, the seeds of the data set to use (default: all present)")
    p.add_argument("--data", type=Path, metavar="DIR",
                   help="read frames from a `stackpick dataset` directory instead of rendering")
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    p.add_argument("--methods", default=",".join(METHOD_NAMES),
                   help=f"comma-separated subset of {','.join(METHOD_NAMES)} (default: all)")
    p.add_argument("--rht-seed", type=int, default=0, help="seed of the RHT's sampling")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and write the results; exit 1 if no frame was scored."""
    names = [n.strip() for n in args.methods.split(",") if n.strip()]
    methods = make_methods(names, seed=args.rht_seed)
    cfg = scene_from_args(args)
    if args.data is not None:
        if not args.data.is_dir():
            raise ConfigError(f"--data {args.data} is not a directory")
        seeds = dataset_seeds(args.data) if args.seeds is None else parse_seeds(args.seeds)
        present = set(dataset_seeds(args.data))
        seeds = [s for s in seeds if s in present]
        frames = iter_dataset(args.data, seeds, cfg)
        source = f"data set {args.data}"
    else:
        seeds = parse_seeds(args.seeds or DEFAULT_SEEDS)
        frames = iter_generated(cfg, seeds)
        source = f"scene {cfg.name}, rendered"
    bar = tqdm(frames, total=len(seeds), desc="bench-detect", unit="frame", file=sys.stderr,
               disable=args.quiet)
    kept, records = run_benchmark(bar, methods)
    if not kept:
        print("bench-detect: no frames to score", file=sys.stderr)
        return 1
    summaries = {name: summarise(rec) for name, rec in records.items()}
    title = (f"Detection benchmark: {source}, seeds {kept[0].seed}-{kept[-1].seed} "
             f"({len(kept)} frames)")
    text = markdown(summaries, title)
    first = records.get("ours", next(iter(records.values())))
    text += "\n" + table1(kept, first)
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "results.md", text)
    meta = {"source": source, "scene": cfg.name, "seeds": [f.seed for f in kept],
            "methods": names, "match_iou": MATCH_IOU,
            "counted_visible_fraction": COUNTED_VISIBLE_FRACTION, "threads": 1,
            "machine": platform.processor() or platform.machine(),
            "python": platform.python_version()}
    write_text(args.out / "results.json", json.dumps({"meta": meta, "methods": summaries},
                                                     indent=1))
    print(text)
    return 0

"""``stackpick dataset``: one look-pose image and one ground-truth JSON per seed."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from stackpick_sim.cli.common import (
    DEFAULT_SEEDS,
    SEEDS_HELP,
    add_scene_args,
    parse_seeds,
    scene_from_args,
)
from stackpick_sim.config.loader import scene_to_dict
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import SceneGenerationError
from stackpick_sim.files import shown, write_text
from stackpick_sim.image_io import write_image
from stackpick_sim.sim.snapshot import seeded_look_frame


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``dataset`` subcommand."""
    p = sub.add_parser(
        "dataset", help="write look-pose images and ground truth for a range of seeds",
        description="For each seed write DIR/<seed:06d>.png (the wrist camera's frame, with the "
        "scene's noise) and DIR/<seed:06d>.json (its ground truth), plus DIR/index.json (the "
        "scene config, per-seed summaries and any seed whose pile could not be generated; "
        "rewritten after every seed, so a stopped run leaves a usable data set). "
        "This is the input of the detection benchmark.")
    add_scene_args(p)
    p.add_argument("--seeds", default=DEFAULT_SEEDS, metavar="SEEDS", help=SEEDS_HELP)
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _write_index(out: Path, cfg: SceneConfig, summaries: list[dict[str, Any]],
                 failures: dict[int, str]) -> None:
    """DIR/index.json: the scene config, the frames written so far, the seeds that failed."""
    index = {"scene": scene_to_dict(cfg), "seeds": summaries,
             "failed": {str(k): v for k, v in failures.items()}}
    write_text(out / "index.json", json.dumps(index, indent=1))


def run(args: argparse.Namespace) -> int:
    """Write the data set; exit code 1 if no seed at all could be generated."""
    cfg = scene_from_args(args)
    seeds = parse_seeds(args.seeds)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    summaries: list[dict[str, Any]] = []
    failures: dict[int, str] = {}
    _write_index(out, cfg, summaries, failures)
    bar = tqdm(seeds, desc=f"dataset {cfg.name}", unit="scene", disable=args.quiet,
               file=sys.stderr)
    for seed in bar:
        try:
            scene, image, truth = seeded_look_frame(cfg, seed)
        except SceneGenerationError as exc:
            failures[seed] = str(exc)
            tqdm.write(f"warning: {exc}", file=sys.stderr)
        else:
            stem = out / f"{seed:06d}"
            write_image(f"{stem}.png", image, order="rgb")
            record = {"scene": cfg.name, "seed": seed, "attempts": scene.attempts,
                      **truth.as_dict()}
            write_text(f"{stem}.json", json.dumps(record, indent=1))
            summaries.append({"seed": seed, "objects": len(truth.objects),
                              "top_objects": truth.top_objects, "attempts": scene.attempts,
                              "build_wall_s": round(scene.build_wall_s, 4)})
        _write_index(out, cfg, summaries, failures)
    print(f"wrote {len(summaries)} frames to {shown(out)} ({len(failures)} seed(s) failed)")
    return 0 if summaries else 1

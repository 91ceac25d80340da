"""``stackpick bench-detect``: our detector against the baselines on the same frames.

``--methods`` takes the benchmark's methods by name and any episode detector (a plug-in
``module:attr`` or entry point of ``stackpick_sim.detectors``): the latter sees each frame
as an episode's first frame (no hints; the camera pose is not known here: identity), and
its top candidate is scored.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from stackpick_sim.cli.common import (
    DEFAULT_SEEDS,
    SEEDS_HELP,
    add_scene_args,
    parse_seeds,
    scene_from_args,
)
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.files import shown, write_text
from stackpick_sim.geometry import tilt_angles
from stackpick_sim.pipeline import Detector, Frame, Hints
from stackpick_sim.registry import TRUTH_STAGES, PluginError, load
from stackpick_sim.vision.benchmark import (
    METHOD_NAMES,
    make_methods,
    markdown,
    run_benchmark,
    summarise,
    table1,
)
from stackpick_sim.vision.benchmark.frames import (
    BenchFrame,
    dataset_seeds,
    iter_dataset,
    iter_generated,
)
from stackpick_sim.vision.benchmark.methods import Method
from stackpick_sim.vision.benchmark.scoring import (
    COUNTED_VISIBLE_FRACTION,
    MATCH_IOU,
    MethodOutput,
)


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
                   help=f"comma-separated subset of {','.join(METHOD_NAMES)} (default: all), "
                   "and episode detectors by name, e.g. mypkg.mod:MyDetector")
    p.add_argument("--rht-seed", type=int, default=0, help="seed of the RHT's sampling")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def detector_method(name: str, cfg: SceneConfig) -> Method:
    """An episode detector (:class:`stackpick_sim.pipeline.Detector`) as a benchmark method."""
    if ("detector", name) in TRUTH_STAGES:
        raise ConfigError(f"--methods {name}: that detector reads the episode's ground truth, "
                          "there is nothing to benchmark")
    try:
        factory = load("detector", name)
    except PluginError as exc:
        raise PluginError(f"--methods: {exc}; benchmark methods: {', '.join(METHOD_NAMES)}"
                          ) from None
    detector: Detector = factory(cfg)

    def run(frame: BenchFrame) -> MethodOutput:
        image = frame.image_rgb if getattr(detector, "needs_image", True) else None
        t0 = time.perf_counter()
        found = detector.detect(Frame(image=image, intrinsics=frame.intrinsics,
                                      world_T_cam=np.eye(4), time=0.0), Hints())
        ms = (time.perf_counter() - t0) * 1e3
        top = next((c for c in found.candidates if c.is_top), None)
        pose = None
        if top is not None and top.normal_cam is not None:
            pose = (float(top.pixel[0]), float(top.pixel[1]), *tilt_angles(top.normal_cam))
        return MethodOutput(ellipses=tuple(c.ellipse for c in found.candidates
                                           if c.ellipse is not None),
                            top=None if top is None else top.ellipse, pose=pose, total_ms=ms,
                            detector_ms=ms, stages_ms={})

    return Method(name, run)


def methods_by_name(names: list[str], cfg: SceneConfig, rht_seed: int) -> list[Method]:
    """The benchmark's own methods and episode detectors, in the order of ``names``."""
    builtin = [n for n in names if n in METHOD_NAMES]
    by_name = {m.name: m for m in make_methods(builtin, seed=rht_seed, vision=cfg.vision)}
    by_name.update({n: detector_method(n, cfg) for n in names if n not in METHOD_NAMES})
    return [by_name[n] for n in names]


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and write the results; exit 1 if no frame was scored."""
    names = [n.strip() for n in args.methods.split(",") if n.strip()]
    cfg = scene_from_args(args)
    methods = methods_by_name(names, cfg, args.rht_seed)
    if args.data is not None:
        if not args.data.is_dir():
            raise ConfigError(f"--data {args.data} is not a directory")
        seeds = dataset_seeds(args.data) if args.seeds is None else parse_seeds(args.seeds)
        present = set(dataset_seeds(args.data))
        seeds = [s for s in seeds if s in present]
        if not (args.data / "index.json").exists():
            print(f"warning: {shown(args.data)} has no index.json; the object kinds, belt "
                  f"height and face height are scene {cfg.name!r}'s (--scene)", file=sys.stderr)
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

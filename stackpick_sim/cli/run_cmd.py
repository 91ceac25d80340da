"""``stackpick run``: pick episodes over a seed range; results.jsonl, summary.md/json."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from stackpick_sim.cli.common import (
    DEFAULT_SEEDS,
    SEEDS_HELP,
    add_scene_args,
    parse_seeds,
    positive_int,
)
from stackpick_sim.config.scene_config import TRACKER_FRAMES
from stackpick_sim.episodes.record import Record, SceneErrorRecord
from stackpick_sim.episodes.summary import summary_markdown
from stackpick_sim.registry import KINDS, check, known
from stackpick_sim.runs.progress import Progress
from stackpick_sim.runs.runner import RunJob, default_workers, make_executor, run_dirs
from stackpick_sim.runs.spec import RunSpec

#: Default wall-clock limit of one episode (pile + pick), s: ~100x a typical episode.
DEFAULT_EPISODE_TIMEOUT_S = 300.0


def positive_float(text: str) -> float:
    """argparse type: a number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {value}")
    return value


def add_execution_args(p: argparse.ArgumentParser) -> None:
    """--workers, --backend, --address, --episode-timeout, --resume, --retry-unfinished,
    --quiet, --verbose."""
    p.add_argument("--workers", type=positive_int, default=None,
                   help=f"local worker processes (default: all cores, {default_workers()} "
                   "here); with --backend ray: the CPUs of a private local Ray instance")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local: worker processes on this machine; ray: a Ray cluster "
                   "(pip install 'stackpick-sim[ray]')")
    p.add_argument("--address", default=None,
                   help="Ray cluster to join: 'auto' (this machine's cluster) or "
                   "'ray://HEAD:10001' (default: start a private local instance)")
    p.add_argument("--episode-timeout", type=positive_float, default=DEFAULT_EPISODE_TIMEOUT_S,
                   metavar="S", help="wall-clock limit of one episode; past it the worker is "
                   "killed and the episode recorded as failed, reason 'timeout' (default: "
                   f"{DEFAULT_EPISODE_TIMEOUT_S:g})")
    p.add_argument("--resume", action="store_true",
                   help="keep the records already in --out and run only the missing seeds "
                   "(repairs a torn last line)")
    p.add_argument("--retry-unfinished", action="store_true",
                   help="with --resume: also run again the recorded episodes that did not "
                   "finish (reason 'error' or 'timeout' from a worker crash, out of memory or "
                   "--episode-timeout; not episodes that failed a phase)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true", help="one line per finished episode")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run`` subcommand."""
    p = sub.add_parser(
        "run", help="run pick episodes over seeds and summarise them",
        description="For each seed: build and settle the pile, then run one pick episode "
        "(look, detect, track, approach, servo, descend, grasp, lift, verify). Each record "
        "is appended to OUT/results.jsonl (and fsync-ed) as its episode ends; at the end "
        "the file is put in seed order and OUT/summary.md and OUT/summary.json are written. "
        "OUT/episodes/SEED/{scene.xml,initial_qpos.npy,final_qpos.npy} are for audit and "
        "'stackpick replay'; OUT/run.log has the tracebacks of failed workers.")
    add_scene_args(p)
    p.add_argument("--seeds", default=DEFAULT_SEEDS, metavar="SEEDS", help=SEEDS_HELP)
    add_stage_args(p)
    p.add_argument("--tracker", choices=TRACKER_FRAMES, default=None,
                   help="Kalman frame: belt (back-projected) or image (the paper's); default: "
                   "the scene's episode.tracker_frame")
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    add_execution_args(p)
    p.set_defaults(func=run)


def add_stage_args(p: argparse.ArgumentParser) -> None:
    """--detector, --estimator, --controller: pipeline stages by name."""
    p.add_argument("--detector", default=None, metavar="NAME",
                   help=f"{', '.join(known('detector'))} (ours: the vision pipeline; oracle: "
                   "ground-truth top object and pose; rht, findellipses: baseline ellipse "
                   "detectors) or a plug-in module:attr (default: the scene's "
                   "episode.detector)")
    p.add_argument("--estimator", default=None, metavar="NAME",
                   help=f"{', '.join(known('estimator'))} (the Kalman tracker in that frame) or "
                   "module:attr (default: the scene's episode.estimator)")
    p.add_argument("--controller", default=None, metavar="NAME",
                   help=f"{', '.join(known('controller'))} or module:attr (default: the "
                   "scene's episode.controller)")


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """The scene and overrides to run, the stage and --tracker shortcuts included; the
    stages are checked here (PluginError, one line) before any worker starts."""
    overrides = list(args.overrides)
    for kind in KINDS:
        name = getattr(args, kind, None)
        if name is not None:
            check(kind, name)
            overrides.append(f"episode.{kind}={name}")
    if getattr(args, "tracker", None) is not None:
        overrides.append(f"episode.tracker_frame={args.tracker}")
    return RunSpec(scene=args.scene, overrides=tuple(overrides))


def episode_line(rec: Record) -> str:
    """One line about a finished episode (--verbose)."""
    if isinstance(rec, SceneErrorRecord):
        return f"seed {rec.seed}: scene error: {rec.error}"
    outcome = "ok" if rec.success else f"FAIL {rec.failure}"
    return (f"seed {rec.seed:5d}: {outcome:22s} cycle {rec.cycle_time_s or 0:.2f} s  "
            f"pred {rec.prediction_error_mm or float('nan'):.2f} mm  "
            f"wall {rec.wall_s:.2f} s")


def executor_from_args(args: argparse.Namespace) -> Any:
    """The executor named by --backend/--workers/--address/--episode-timeout."""
    return make_executor(args.backend, workers=args.workers, address=args.address,
                         episode_timeout=args.episode_timeout)


def run(args: argparse.Namespace) -> int:
    """Run the batch, write the files, print the summary."""
    seeds = parse_seeds(args.seeds)

    def on_record(rec: Record, bar: Progress) -> None:
        if args.verbose:
            bar.write(episode_line(rec))

    job = RunJob(key="run", spec=spec_from_args(args), seeds=seeds, out=args.out)
    stats = run_dirs([job], executor_from_args(args), resume=args.resume,
                     retry_unfinished=args.retry_unfinished, show_progress=not args.quiet,
                     on_record=on_record)
    print(summary_markdown(stats.summaries["run"]))
    print(f"ran {stats.ran} episodes ({stats.skipped} already recorded) in "
          f"{stats.wall_s:.1f} s: {stats.episodes_per_s:.3f} episodes/s")
    print(f"wrote {args.out}/results.jsonl, summary.md, summary.json, episodes/")
    return 0

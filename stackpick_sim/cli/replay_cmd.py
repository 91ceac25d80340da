"""``stackpick replay``: re-run one episode of a batch and write a video of it."""

from __future__ import annotations

import argparse
from pathlib import Path

from stackpick_sim.cli.common import seed_arg
from stackpick_sim.runs.replay import replay_run


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``replay`` subcommand."""
    p = sub.add_parser(
        "replay", help="re-run one episode of a 'stackpick run' batch and record a video",
        description="Re-run seed SEED with the scene and overrides of DIR/run.json, check that "
        "it starts and ends in the recorded states, and write an H.264 video: a banner with "
        "the sim time, phase and outcome over the wrist camera with the detections and the "
        "tracker's estimate drawn (left) beside an outside view that follows the pile (right).")
    p.add_argument("dir", type=Path, help="the --out directory of 'stackpick run'")
    p.add_argument("seed", type=seed_arg, help="episode seed")
    p.add_argument("--video", type=Path, required=True,
                   help="output .mp4 file (H.264, plays in browsers; needs "
                   "pip install 'stackpick-sim[video]')")
    p.add_argument("--truth", action="store_true",
                   help="draw the true top faces (ground truth) over the wrist camera's frames")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Replay and report."""
    result = replay_run(args.dir, args.seed, args.video, show_truth=args.truth)
    rec = result.record
    outcome = "success" if rec.success else f"failure {rec.failure} ({rec.failure_detail})"
    print(f"seed {args.seed}: {outcome}; {result.frames} video frames -> {args.video}")
    print(f"state vs. recorded: initial max |dq| {result.initial_diff:.3g}, final max |dq| "
          f"{result.final_diff:.3g}")
    return 0

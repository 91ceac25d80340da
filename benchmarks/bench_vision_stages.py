"""Per-stage time of the detector against a baseline commit, as ratios, on the same frames.

    python benchmarks/bench_vision_stages.py --data DATA --seeds 0:400 \\
        [--scene paper] [--scene-settings] [--baseline main] [--rounds 3] [--repeats 3] \\
        [--slowest N]

The baseline commit's ``stackpick_sim`` and ``scenes`` are exported to a temporary directory;
the baseline and the working tree then run in alternation (``--rounds`` times each), each in
its own process timing every frame ``--repeats`` times. Stage times are the detector's own
(``Detection.timings_ms``) read on the thread's CPU clock rather than the wall clock: on a
machine shared with other jobs, preemption then adds nothing, while the ratios stay those of
the work done. Per frame the fastest repeat counts; the table gives medians over the frames
and rounds and the ratio baseline / working tree; a second table gives the p50, p95, p99 and
maximum over frames (and rounds) of the whole pipeline's time per frame; ``--slowest N``
lists the working tree's N slowest frames stage by stage (the tail's seeds, to profile).
The outputs (ellipses, top, pose) of the two are compared as well: a speed-up should not
change them.

DATA is a ``stackpick dataset --scene SCENE --seeds 0:400`` directory (``--scene``: the
same scene, whose object kinds the detector is given). Both detectors run with their default
settings unless ``--scene-settings`` is given: then each runs with the ``[vision]`` table of
its own commit's scene file (the scene as each commit ships it; where the two tables differ,
the outputs may differ too). Time on seeds outside the held-out ranges of the reported
figures (docs/figures.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
STAGES = ("roi", "edges", "segments", "fitting", "merging", "refine", "top", "pose", "total")

#: Run in a child process with the code under test first on sys.path: time each frame.
WORKER = r"""
import pickle, sys, time
import cv2
cv2.setNumThreads(1)
time.perf_counter = time.thread_time  # the detector's stage clock: this thread's CPU time
from stackpick_sim.geometry import CameraIntrinsics
from stackpick_sim.vision.detector import (DEFAULT_RADII_M, DetectorConfig, TopObjectDetector,
                                           object_kinds)
try:  # the compiled kernels loaded (or compiled) before any timing
    from stackpick_sim.vision.kernels import warm_up
    warm_up()
except ImportError:  # a baseline without them
    pass
frames_path, repeats, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
vision = None
if len(sys.argv) > 4:  # the scene's own [vision] table, as this commit ships it
    from stackpick_sim.config.loader import load_scene
    vision = load_scene(sys.argv[4]).vision
with open(frames_path, "rb") as f:
    frames = pickle.load(f)
times, outputs = [], []
for frame in frames:
    kinds = frame["kinds"]
    try:
        got = object_kinds(kinds) if kinds else (DEFAULT_RADII_M, None, None)
    except ValueError:  # a baseline from before the kinds carried heights: (radius, rgb)
        got = object_kinds([k[:2] for k in kinds])
    radii, colours, heights = (tuple(got) + (None,))[:3]
    extra = {} if heights is None else {"heights_m": heights}
    config = DetectorConfig(intrinsics=CameraIntrinsics(**frame["intrinsics"]), radii_m=radii,
                            depth_range_m=frame["depth_range_m"], kind_colours=colours, **extra)
    det = TopObjectDetector(config if vision is None else config.with_vision(vision))
    runs = [det.detect(frame["image"]) for _ in range(repeats)]
    times.append([r.timings_ms for r in runs])
    r = runs[-1]
    outputs.append(([(e.ellipse.cx, e.ellipse.cy, e.ellipse.a, e.ellipse.b, e.ellipse.angle_deg)
                     for e in r.ellipses], r.top,
                    None if r.pose is None else (r.pose.x, r.pose.y, r.pose.theta_x_deg,
                                                 r.pose.theta_y_deg, r.pose.depth_m)))
with open(out, "wb") as f:
    pickle.dump({"times": times, "outputs": outputs}, f)
"""


def save_frames(data: Path, seeds: list[int], out: Path, scene: str = "paper") -> list[int]:
    """The frames of a data set of ``scene`` as plain values (readable by any version of
    the package), pickled to ``out``; returns their seeds, in order."""
    from stackpick_sim.config.loader import load_scene
    from stackpick_sim.vision.benchmark.frames import iter_dataset

    frames, timed = [], []
    for f in iter_dataset(data, seeds, load_scene(scene)):
        frames.append({"image": f.image_rgb, "depth_range_m": f.depth_range_m,
                       "kinds": f.kinds, "intrinsics": dataclasses.asdict(f.intrinsics)})
        timed.append(f.seed)
    with open(out, "wb") as fh:
        pickle.dump(frames, fh)
    return timed


def export(ref: str, into: Path) -> Path:
    """``stackpick_sim`` and ``scenes`` of commit ``ref`` written under ``into``; returns the
    directory to put on sys.path."""
    archive = into / "baseline.tar"
    subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", "-o", str(archive), ref,
                    "stackpick_sim", "scenes"], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    return into


def run_worker(code_root: Path, frames: Path, repeats: int, out: Path, scene: str | None = None
               ) -> dict:
    """Time the detector of ``code_root`` on the pickled ``frames`` in a child process (with
    the ``[vision]`` table of that code's ``scene``, when given); its results."""
    env = dict(os.environ, PYTHONPATH=str(code_root))
    # -P: no current directory ahead of PYTHONPATH (it may hold another stackpick_sim).
    extra = [] if scene is None else [scene]
    subprocess.run([sys.executable, "-P", "-c", WORKER, str(frames), str(repeats), str(out),
                    *extra], check=True, env=env)
    with open(out, "rb") as f:
        return pickle.load(f)


def stage_medians(results: list[dict]) -> dict[str, float]:
    """Median over frames (and rounds) of each stage's fastest repeat, ms."""
    return {s: float(np.median([min(r.get(s, 0.0) for r in per)
                                for res in results for per in res["times"]]))
            for s in STAGES}


def total_percentiles(results: list[dict]) -> dict[str, float]:
    """p50, p95, p99 and max over frames (and rounds) of the whole pipeline's per-frame CPU
    time (``total``, the fastest repeat), ms."""
    totals = [min(r.get("total", 0.0) for r in per) for res in results for per in res["times"]]
    p50, p95, p99, top = np.percentile(totals, [50, 95, 99, 100]).tolist()
    return {"p50": p50, "p95": p95, "p99": p99, "max": top}


def slowest_frames(results: list[dict], seeds: list[int], count: int) -> list[str]:
    """Table rows of the ``count`` frames with the largest whole-pipeline time (the fastest
    repeat of each round, then the median round, the slower of two): seed, then each stage's
    time (ms) in that repeat."""
    per_frame = []
    for k, seed in enumerate(seeds):
        fastest = [min(res["times"][k], key=lambda r: r.get("total", 0.0)) for res in results]
        fastest.sort(key=lambda r: r.get("total", 0.0))
        per_frame.append((seed, fastest[len(fastest) // 2]))
    per_frame.sort(key=lambda f: -f[1].get("total", 0.0))
    return [f"| {seed} | " + " | ".join(f"{t.get(s, 0.0):.3f}" for s in STAGES) + " |"
            for seed, t in per_frame[:count]]


def differences(a: list, b: list) -> str:
    """How the outputs of two runs differ (counts and largest differences)."""
    count = top = 0
    ellipse_diff = pose_diff = 0.0
    for (e1, t1, p1), (e2, t2, p2) in zip(a, b, strict=True):
        if len(e1) != len(e2):
            count += 1
        elif e1:
            ellipse_diff = max(ellipse_diff, float(np.abs(np.subtract(e1, e2)).max()))
        if t1 != t2 or (p1 is None) != (p2 is None):
            top += 1
        elif p1 is not None:
            pose_diff = max(pose_diff, float(np.abs(np.subtract(p1, p2)).max()))
    return (f"frames whose ellipse count differs: {count}; whose top differs: {top}; largest "
            f"ellipse parameter difference {ellipse_diff:.3g}; largest pose difference "
            f"{pose_diff:.3g}")


def main() -> int:
    """Run the comparison and print the table."""
    from stackpick_sim.cli.common import parse_seeds

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, required=True, help="a `stackpick dataset` directory")
    p.add_argument("--seeds", default="0:400", help="seeds of the data set to time (default 0:400)")
    p.add_argument("--scene", default="paper", help="the data set's scene (default paper)")
    p.add_argument("--scene-settings", action="store_true",
                   help="run each detector with its own commit's scene [vision] table "
                        "(default: the detectors' default settings)")
    p.add_argument("--baseline", default="main", help="git ref of the baseline (default main)")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--slowest", type=int, default=0, metavar="N",
                   help="also list the N slowest frames of the working tree, stage by stage")
    args = p.parse_args()
    seeds = parse_seeds(args.seeds)
    scene = args.scene if args.scene_settings else None
    with tempfile.TemporaryDirectory() as tmp:
        frames = Path(tmp) / "frames.pkl"
        timed = save_frames(args.data, seeds, frames, args.scene)
        if not timed:
            print(f"no frames of seeds {args.seeds} in {args.data}", file=sys.stderr)
            return 1
        base_root = export(args.baseline, Path(tmp))
        base, work = [], []
        for k in range(args.rounds):
            base.append(run_worker(base_root, frames, args.repeats, Path(tmp) / f"base{k}.pkl",
                                   scene))
            work.append(run_worker(REPO, frames, args.repeats, Path(tmp) / f"work{k}.pkl",
                                   scene))
    old, new = stage_medians(base), stage_medians(work)
    print(f"Detector stage times, CPU ms (median over {len(base[0]['times'])} frames x "
          f"{args.rounds} rounds of the fastest of {args.repeats}), baseline {args.baseline} "
          f"vs working tree, {'each with its own' if scene else 'default settings, not the'} "
          f"{args.scene} scene's [vision] table:\n")
    print("| stage | baseline | working tree | baseline / working tree |")
    print("|---|---|---|---|")
    for s in STAGES:
        print(f"| {s} | {old[s]:.3f} | {new[s]:.3f} | {old[s] / max(new[s], 1e-9):.2f} |")
    old_tail, new_tail = total_percentiles(base), total_percentiles(work)
    print("\nWhole pipeline per frame (total), CPU ms:\n")
    print("| percentile | baseline | working tree | baseline / working tree |")
    print("|---|---|---|---|")
    for q in old_tail:
        print(f"| {q} | {old_tail[q]:.3f} | {new_tail[q]:.3f} | "
              f"{old_tail[q] / max(new_tail[q], 1e-9):.2f} |")
    if args.slowest:
        print(f"\nThe {args.slowest} slowest frames of the working tree (the fastest repeat, "
              "median round), CPU ms:\n")
        print("| seed | " + " | ".join(STAGES) + " |")
        print("|" + "---|" * (len(STAGES) + 1))
        print("\n".join(slowest_frames(work, timed, args.slowest)))
    print("\n" + differences(base[0]["outputs"], work[0]["outputs"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Where an episode's wall time goes, and the belt-frame vs. image-frame Kalman tracker.

Builds the piles first (timed separately: the batch runner may cache them), then runs the
episodes only, once per tracker frame asked for, on the same piles (each run on a fresh
copy: an episode changes its cell). Prints, per tracker frame: success, the prediction
error at the pick moment (px in the look view, mm), cycle time, the per-activity wall-time
breakdown the records carry and the episode wall time as a ratio to a baseline measured in
the same run (``sim seconds x plain mj_step cost``: how many times slower than bare
physics). ``--profile`` adds the top functions by cumulative time (first tracker frame).

    .venv/bin/python benchmarks/bench_episodes.py [--scene paper] [--detector ours|oracle]
        [--seeds 0:5] [--trackers belt,image] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
from collections import Counter

import numpy as np

import stackpick_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from stackpick_sim.cli.common import parse_seeds
from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes import EpisodeRecord, run_episode
from stackpick_sim.episodes.summary import wilson_interval
from stackpick_sim.sim.stacks import generate_scene


def _quantiles(values: list[float]) -> str:
    if not values:
        return "n=0"
    v = np.asarray(values)
    return f"median {np.median(v):.3g}, p95 {np.percentile(v, 95):.3g} (n={len(v)})"


def _report(frame: str, records: list[EpisodeRecord], step_s: float, timestep: float) -> None:
    ok = sum(r.success for r in records)
    walls = np.array([r.wall_s for r in records])
    sims = np.array([max(r.sim_time_s, timestep) for r in records])
    ratio = walls / (sims / timestep * step_s)
    lo, hi = wilson_interval(ok, len(records))
    failures = Counter(r.failure for r in records if r.failure)
    print(f"\n[{frame}] success {ok}/{len(records)} (95 % Wilson CI {100 * lo:.1f}-"
          f"{100 * hi:.1f} %); failures {dict(sorted(failures.items()))}")
    print("  prediction error at pick, px:",
          _quantiles([r.prediction_error_px for r in records
                      if r.prediction_error_px is not None]))
    print("  prediction error at pick, mm:",
          _quantiles([r.prediction_error_mm for r in records
                      if r.prediction_error_mm is not None]))
    print("  cycle time, s:", _quantiles([r.cycle_time_s for r in records
                                         if r.cycle_time_s is not None]))
    print(f"  episode wall median {np.median(walls):.3f} s for {np.median(sims):.2f} s sim: "
          f"{np.median(ratio):.1f}x bare physics ({step_s * 1e6:.0f} us/step)")
    keys = sorted({k for r in records for k in r.wall_breakdown_s})
    for k in keys:
        v = np.array([r.wall_breakdown_s.get(k, 0.0) for r in records])
        print(f"    {k:8s} median {np.median(v):.3f} s  ({100 * np.sum(v) / np.sum(walls):.0f} %)")
    frames = np.array([r.frames for r in records])
    used = np.array([r.frames_processed for r in records])
    print(f"  frames captured median {np.median(frames):.0f}, processed {np.median(used):.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--detector", default="ours", choices=("ours", "oracle"))
    parser.add_argument("--seeds", default="0:5")
    parser.add_argument("--trackers", default="belt", help="comma list of belt, image")
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()
    seeds = parse_seeds(args.seeds)
    frames = [f.strip() for f in args.trackers.split(",") if f.strip()]
    base_cfg = load_scene(args.scene, [f"episode.detector={args.detector}"])
    start = time.perf_counter()
    scenes = [generate_scene(base_cfg, s) for s in seeds]
    build = time.perf_counter() - start
    print(f"{len(seeds)} piles ({args.scene}, {args.detector}): generation "
          f"{build / len(seeds):.2f} s each")
    import mujoco  # after stackpick_sim, which chooses the headless GL backend

    # Baseline: bare physics steps on a copy of the first scene's state.
    model = scenes[0].cell.model
    data = mujoco.MjData(model)
    data.qpos[:] = scenes[0].cell.data.qpos
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(model, data)
    step_s = (time.perf_counter() - t0) / n
    for i, frame in enumerate(frames):
        cfg = load_scene(args.scene, [f"episode.detector={args.detector}",
                                      f"episode.tracker_frame={frame}"])
        profiler = cProfile.Profile() if args.profile and i == 0 else None
        records = []
        for seed in seeds:
            scene = generate_scene(cfg, seed)  # same pile: the seed fixes it bit for bit
            if profiler is not None:
                profiler.enable()
            records.append(run_episode(scene))
            if profiler is not None:
                profiler.disable()
        _report(frame, records, step_s, model.opt.timestep)
        if profiler is not None:
            out = io.StringIO()
            pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(25)
            print(out.getvalue())


if __name__ == "__main__":
    main()

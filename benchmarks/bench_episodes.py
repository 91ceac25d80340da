"""Where an episode's wall time goes: a cProfile of pick episodes, pile generation apart.

Builds the piles first (timed separately: a later issue may cache them), then profiles the
episodes only. Prints the per-activity breakdown the records carry, the top functions by
cumulative time, and the episode time as a ratio to a baseline measured in the same run:
``sim seconds x (plain mj_step cost)``, i.e. how many times slower than bare physics.

    .venv/bin/python benchmarks/bench_episodes.py [--detector ours|oracle] [--seeds 0:5]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

import mujoco
import numpy as np

import stackpick_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from stackpick_sim.cli.common import parse_seeds
from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes import run_episode
from stackpick_sim.sim.stacks import generate_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--detector", default="ours", choices=("ours", "oracle"))
    parser.add_argument("--seeds", default="0:5")
    args = parser.parse_args()
    cfg = load_scene(args.scene, [f"episode.detector={args.detector}"])
    seeds = parse_seeds(args.seeds)
    start = time.perf_counter()
    scenes = [generate_scene(cfg, s) for s in seeds]
    build = time.perf_counter() - start
    # Baseline: bare physics steps on a copy of the first scene's state.
    base = scenes[0].cell
    data = mujoco.MjData(base.model)
    data.qpos[:] = base.data.qpos
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(base.model, data)
    step_s = (time.perf_counter() - t0) / n
    profiler = cProfile.Profile()
    records = []
    profiler.enable()
    for scene in scenes:
        records.append(run_episode(scene))
    profiler.disable()
    walls = np.array([r.wall_s for r in records])
    sims = np.array([r.sim_time_s for r in records])
    ratio = walls / (sims / base.model.opt.timestep * step_s)
    print(f"{len(seeds)} episodes ({args.detector}): pile generation {build / len(seeds):.2f} s "
          f"each; episode wall median {np.median(walls):.2f} s for {np.median(sims):.2f} s "
          f"sim; {np.median(ratio):.1f}x bare physics ({step_s * 1e6:.0f} us/step)")
    keys = sorted({k for r in records for k in r.wall_breakdown_s})
    for k in keys:
        v = np.array([r.wall_breakdown_s.get(k, 0.0) for r in records])
        print(f"  {k:8s} median {np.median(v):.3f} s  ({100 * np.sum(v) / np.sum(walls):.0f} %)")
    print("outcomes:", [r.failure or "ok" for r in records])
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(25)
    print(out.getvalue())


if __name__ == "__main__":
    main()

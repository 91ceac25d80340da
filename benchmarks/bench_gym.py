"""StackPick-v0 speed and the reference policy's picks. Writes
benchmarks/results/gym_<scene>_<step>.md and .json.

    python benchmarks/bench_gym.py [--scene paper] [--step frame] [--seeds 0:5]
        [--episodes 0:100 --compare OUT]

Speed: env steps per second on one core (the process pinned to one CPU, BLAS and OpenMP on
one thread) with the reference policy, over whole episodes of ``--seeds``; the target is the
camera's 30 Hz (one step is one camera frame). Also given as a ratio, sim time per wall time
(1: real time), and against ``run_episode`` on the same seeds in the same run (the batch's
own loop, no observations).

``--episodes``: the reference policy's success on those seeds beside ``stackpick run``'s,
seed by seed, read from ``--compare OUT`` (the ``--out`` of ``stackpick run`` on the same
scene and seeds). With ``--step tick`` the two must agree on every seed; with ``--step frame``
each command is held for a camera frame, so outcomes can differ.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import gymnasium  # noqa: E402

import stackpick_sim.gym  # noqa: E402,F401
from stackpick_sim.cli.common import parse_seeds  # noqa: E402
from stackpick_sim.config.loader import load_scene  # noqa: E402
from stackpick_sim.episodes import run_episode  # noqa: E402
from stackpick_sim.gym.env import ReferencePolicy  # noqa: E402
from stackpick_sim.sim.stacks import generate_scene  # noqa: E402


def policy_episode(env: Any, seed: int) -> tuple[int, float, float, float, dict[str, Any]]:
    """One episode with the reference policy: steps, wall s of the steps, wall s of the
    episode after its pile (the reset's look, detect and track too), sim s, last info."""
    policy = ReferencePolicy()
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    pile = env.episode.scene.build_wall_s
    reset = time.perf_counter() - t0
    steps, wall = 0, 0.0
    while True:
        t0 = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(policy(obs, info))
        wall += time.perf_counter() - t0
        steps += 1
        if terminated or truncated:
            return steps, wall, wall + reset - pile, float(info["time"]), info


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--seeds", default="0:5", help="seeds of the speed measurement")
    parser.add_argument("--step", choices=("frame", "tick"), default="frame")
    parser.add_argument("--episodes", default=None, help="seeds of the success comparison")
    parser.add_argument("--compare", type=Path, default=None,
                        help="a `stackpick run` output directory with those seeds")
    parser.add_argument("--cpu", type=int, default=None,
                        help="the CPU to run on (default: the lowest this process may use)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        cpus = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(cpus) if args.cpu is None else args.cpu})
    cfg = load_scene(args.scene)
    env = gymnasium.make("StackPick-v0", scene=args.scene, step=args.step).unwrapped
    steps = 0
    wall = episode_wall = sim = batch_wall = 0.0
    for seed in parse_seeds(args.seeds):
        n, w, e, s, _ = policy_episode(env, seed)
        steps, wall, episode_wall, sim = steps + n, wall + w, episode_wall + e, sim + s
        scene = generate_scene(cfg, seed)
        t0 = time.perf_counter()
        run_episode(scene)
        batch_wall += time.perf_counter() - t0
    result: dict[str, Any] = {
        "scene": args.scene, "seeds": args.seeds, "steps": steps,
        "steps_per_s": steps / wall, "sim_per_wall": sim / episode_wall,
        "env_wall_per_batch_wall": episode_wall / batch_wall, "cores": 1,
        "load_average": os.getloadavg()[0], "machine_cpus": os.cpu_count()}
    result["step"] = args.step
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, cwd=Path(__file__).parent, check=False).stdout.strip()
    result["commit"], result["command"] = commit, " ".join(["python", *sys.argv])
    lines = [f"# StackPick-v0 on {args.scene}, step={args.step}, one core", "",
             f"Commit {commit or '?'}: `{result['command']}`",
             "", f"- env steps/s (reference policy, seeds {args.seeds}): "
             f"{result['steps_per_s']:.1f} (target >= 30: real time at 30 fps)",
             f"- sim time per wall time (whole episodes, pile excluded): "
             f"{result['sim_per_wall']:.2f}",
             f"- env wall time / run_episode wall time, same seeds (pile excluded): "
             f"{result['env_wall_per_batch_wall']:.2f}",
             f"- machine: {result['machine_cpus']} CPUs, 1-minute load average "
             f"{result['load_average']:.1f} at the end (other work slows every figure)"]
    if args.episodes and args.compare:
        infos = {seed: policy_episode(env, seed)[4] for seed in parse_seeds(args.episodes)}
        recorded = {r["seed"]: r for r in map(json.loads, (args.compare / "results.jsonl")
                                                  .read_text().splitlines())}
        rows = []
        for seed, info in infos.items():
            batch = recorded[seed]
            rows.append({"seed": seed, "policy": bool(info["success"]),
                         "policy_failure": info["failure"], "batch": bool(batch["success"]),
                         "batch_failure": batch["failure"]})
        n = len(rows)
        pol, bat = sum(r["policy"] for r in rows), sum(r["batch"] for r in rows)
        same = sum(r["policy"] == r["batch"] for r in rows)
        result["episodes"] = rows
        lines += [f"- reference policy: {pol}/{n} picks; stackpick run: {bat}/{n};"
                  f" same outcome on {same}/{n} seeds ({args.episodes})"]
        lines += [f"  - seed {r['seed']}: policy {r['policy_failure'] or 'ok'}, run "
                  f"{r['batch_failure'] or 'ok'}" for r in rows if r["policy"] != r["batch"]]
    env.close()
    args.out.mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines) + "\n"
    name = f"gym_{args.scene}_{args.step}"
    (args.out / f"{name}.md").write_text(text)
    (args.out / f"{name}.json").write_text(json.dumps(result, indent=1))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

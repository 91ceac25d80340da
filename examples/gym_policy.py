"""Drive StackPick-v0 with our controller as the reference policy, then with random actions.

    python examples/gym_policy.py --seeds 0:3 [--step tick]

The reference policy acts on ``info["reference_action"]``, our controller's command for the
goal the action is for (with ``--step tick`` the episode is then that of ``stackpick run``;
one step per camera frame holds each command for three control ticks); random actions move
the arm anywhere within its speed limits (the phase machine still detects, tracks, grasps and
lifts on its own, and ends the episode when a phase times out).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np

import stackpick_sim.gym  # noqa: F401  (registers StackPick-v0)
from stackpick_sim.gym.env import ReferencePolicy

Policy = Callable[[dict[str, Any], dict[str, Any]], np.ndarray]


def run(env: gymnasium.Env, policy: Policy, seed: int) -> tuple[float, int, dict[str, Any]]:
    """One episode: total reward, steps, the last info."""
    obs, info = env.reset(seed=seed)
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        total += float(reward)
        steps += 1
        if terminated or truncated:
            return total, steps, info


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="paper")
    p.add_argument("--seeds", default="0:2", help="START:STOP")
    p.add_argument("--step", choices=("frame", "tick"), default="frame")
    args = p.parse_args(argv)
    start, stop = (int(x) for x in args.seeds.split(":"))
    env = gymnasium.make("StackPick-v0", scene=args.scene, step=args.step)
    rng = np.random.default_rng(0)
    space = env.action_space

    def random_policy(obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        return rng.uniform(space.low, space.high)  # type: ignore[attr-defined]

    for name, policy in (("reference", ReferencePolicy()), ("random", random_policy)):
        for seed in range(start, stop):
            reward, steps, info = run(env, policy, seed)
            print(f"{name:9s} seed {seed}: reward {reward:.0f} in {steps} steps, "
                  f"failure {info['failure']}")
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

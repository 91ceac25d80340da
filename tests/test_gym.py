"""StackPick-v0: passes gymnasium's checker, resets to `stackpick run`'s pile, the reference
policy picks as `stackpick run` does, random actions end with a failure reason, renders."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env  # noqa: E402

import stackpick_sim.gym  # noqa: E402,F401
from stackpick_sim.config.loader import load_scene  # noqa: E402
from stackpick_sim.episodes import run_episode  # noqa: E402
from stackpick_sim.episodes.record import FAILURES, PHASES, WALL_CLOCK_KEYS  # noqa: E402
from stackpick_sim.gym.env import ReferencePolicy, StackPickEnv  # noqa: E402
from stackpick_sim.sim.stacks import generate_scene  # noqa: E402

SEED = 1


@pytest.fixture(scope="module")
def env() -> StackPickEnv:
    e = gymnasium.make("StackPick-v0", scene="paper", render_mode="rgb_array")
    yield e.unwrapped
    e.close()


def test_env_passes_gymnasium_checks(env: StackPickEnv) -> None:
    check_env(env, skip_render_check=True)


def test_reset_builds_the_pile_of_stackpick_run(env: StackPickEnv) -> None:
    obs, info = env.reset(seed=SEED)
    scene = generate_scene(load_scene("paper"), SEED)
    assert env.episode.scene.cell.spec_xml == scene.cell.spec_xml
    assert env.observation_space.contains(obs)
    assert obs["image"].any()
    # Look, detect and track ran on their own: the agent is first asked in the approach.
    assert PHASES[obs["phase"]] == info["phase"] == "approach" and info["time"] > 0
    assert np.any(info["reference_action"] != 0)


def _drive(env: StackPickEnv, seed: int) -> tuple[float, int, dict]:
    obs, info = env.reset(seed=seed)
    policy = ReferencePolicy()
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        total, steps = total + reward, steps + 1
        if terminated or truncated:
            return total, steps, info


def test_reference_policy_reproduces_stackpick_run_tick_by_tick() -> None:
    env = gymnasium.make("StackPick-v0", scene="paper", step="tick").unwrapped
    total, steps, info = _drive(env, SEED)
    env.close()
    batch = run_episode(generate_scene(load_scene("paper"), SEED)).as_dict()
    policy = info["record"]
    for key in WALL_CLOCK_KEYS:
        batch.pop(key), policy.pop(key)
    assert policy == batch and total == 1.0 and info["success"]
    assert steps > 20  # one step per control tick of the approach, servo and descent


def test_reference_policy_at_the_camera_rate(env: StackPickEnv) -> None:
    """One step per camera frame: the episode ends with a verdict, the view renders."""
    total, steps, info = _drive(env, 2)
    assert info["failure"] in (None, *FAILURES) and info["failure"] != "error"
    assert total == (1.0 if info["success"] else 0.0) and steps > 3
    frame = env.render()
    assert frame is not None and frame.shape == (480, 1280, 3) and frame.dtype == np.uint8
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(np.zeros(6))


def test_random_actions_end_with_a_failure_reason(env: StackPickEnv) -> None:
    rng = np.random.default_rng(0)
    env.reset(seed=SEED)
    for _ in range(400):
        _, reward, terminated, _, info = env.step(rng.uniform(-env.limit, env.limit))
        if terminated:
            break
    assert terminated and reward == 0.0
    assert info["failure"] in FAILURES and info["failure"] != "error", info["failure_detail"]

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
from stackpick_sim.episodes.record import FAILURES, PHASES  # noqa: E402
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
    cell = env.episode.scene.cell
    assert [o.name for o in cell.objects] == [o.name for o in scene.cell.objects]
    bodies = [o.body_id for o in scene.cell.objects]
    # One control tick has run (the first frame): the belt (along y) has carried the pile
    # for it, nothing else has moved.
    now, built = cell.data.xpos[bodies], scene.cell.data.xpos[bodies]
    assert np.allclose(now[:, [0, 2]], built[:, [0, 2]], atol=1e-4)
    travel = cell.cfg.conveyor.speed * info["time"]
    assert np.allclose(now[:, 1] - built[:, 1], travel, atol=0.3 * travel)
    assert obs["image"].shape == (240, 320, 3) and obs["image"].any()
    assert PHASES[obs["phase"]] in ("look", "detect") and info["time"] > 0


def test_reference_policy_picks_like_stackpick_run(env: StackPickEnv) -> None:
    obs, info = env.reset(seed=SEED)
    policy = ReferencePolicy()
    total, moved = 0.0, False
    while True:
        action = policy(obs, info)
        moved |= bool(np.any(action != 0))
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        if terminated or truncated:
            break
    batch = run_episode(generate_scene(load_scene("paper"), SEED))
    assert moved and total == 1.0 and info["success"] == batch.success is True
    assert info["record"]["picked_object"] == batch.picked_object
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

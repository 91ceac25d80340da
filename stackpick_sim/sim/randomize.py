"""Domain randomisation: scene keys drawn per seed from the ranges of the ``[randomize]`` table.

``randomize = {"camera.exposure_s" = [0.001, 0.008], "camera.distortion.0" = [-0.3, -0.05]}``
draws each listed key uniformly in its [low, high] range (an integer key: an integer in it,
both ends included) from the seed-sequence stream ``[seed, RANDOMIZE_STREAM]``, in the
keys' sorted order, before the pile is built: same scene and seed, same draws, whatever the
worker. A key is a dotted scene key (``object_types.can.specular``), with ``.N`` for the
N-th element of a list key (``camera.distortion.0`` is k1).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from stackpick_sim.config.scene_config import SceneConfig

#: Seed-sequence stream of the randomised keys (``[seed, RANDOMIZE_STREAM]``).
RANDOMIZE_STREAM = 7


def _replaced(node: Any, parts: list[str], value: float) -> Any:
    head, rest = parts[0], parts[1:]
    if isinstance(node, tuple):
        i = int(head)
        return (*node[:i], value if not rest else _replaced(node[i], rest, value), *node[i + 1:])
    if isinstance(node, dict):
        return {**node, head: value if not rest else _replaced(node[head], rest, value)}
    child = value if not rest else _replaced(getattr(node, head), rest, value)
    return dataclasses.replace(node, **{head: child})


def draw(cfg: SceneConfig, seed: int) -> SceneConfig:
    """``cfg`` with every ``randomize`` key drawn for ``seed`` (``cfg`` itself when none)."""
    if not cfg.randomize:
        return cfg
    rng = np.random.default_rng([seed, RANDOMIZE_STREAM])
    out = dataclasses.replace(cfg, randomize={})
    for key in sorted(cfg.randomize):
        lo, hi = cfg.randomize[key]
        current = cfg.value_at(key)
        value: float = (int(rng.integers(int(lo), int(hi) + 1)) if isinstance(current, int)
                        else float(rng.uniform(lo, hi)))
        out = _replaced(out, key.split("."), value)
    return out

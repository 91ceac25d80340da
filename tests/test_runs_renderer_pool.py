"""Reused renderers give the images of fresh ones, bit for bit, across piles of different
object counts and kinds, shadows on (the context fields that follow stat.extent)."""

from __future__ import annotations

import mujoco
import numpy as np

from stackpick_sim.config.loader import load_scene
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.renderer_pool import RendererPool, render_asset_fingerprint
from stackpick_sim.sim.stacks import generate_scene

#: Seeds with 3, 4 and 5 objects and both kinds (two different fingerprints).
SEEDS = (0, 1, 2, 4)


def test_pooled_renderers_match_fresh_ones_bit_for_bit(monkeypatch) -> None:
    cfg = load_scene("paper", ["camera.shadows=true"])
    scenes = [generate_scene(cfg, s) for s in SEEDS]
    assert len({s.cell.model.nbody for s in scenes}) > 1  # the models do differ

    def shots() -> list[tuple[np.ndarray, np.ndarray]]:
        out = []
        for sc in scenes:
            mujoco.mj_forward(sc.cell.model, sc.cell.data)
            cam = WristCamera(sc.cell)
            out.append((cam.render(), cam.segmentation()))
            cam.close()
        return out

    fresh = shots()
    pool = RendererPool()
    monkeypatch.setattr("stackpick_sim.sim.camera.active_pool", lambda: pool)
    pooled = shots()
    assert pool.reused > 0 and pool.built < 2 * len(SEEDS)
    for (a, sa), (b, sb) in zip(fresh, pooled, strict=True):
        assert np.array_equal(a, b) and np.array_equal(sa, sb)
    pool.clear()


def test_fingerprint_tells_render_assets_apart() -> None:
    a = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom type='plane' size='1 1 .1'/>"
                                       "<geom type='box' size='.1 .1 .1'/></worldbody></mujoco>")
    b = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom type='plane' size='1 1 .1'/>"
                                       "<geom type='box' size='.2 .1 .1' pos='1 0 0'/>"
                                       "</worldbody></mujoco>")
    c = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom type='plane' size='2 1 .1'/>"
                                       "</worldbody></mujoco>")
    assert render_asset_fingerprint(a) == render_asset_fingerprint(b)  # primitives only
    assert render_asset_fingerprint(a) != render_asset_fingerprint(c)  # plane size differs

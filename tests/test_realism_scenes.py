"""Object kinds, the belt's skin, realistic and randomised scenes: seeded and deterministic."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.cell import build_cell
from stackpick_sim.sim.conveyor import Conveyor
from stackpick_sim.sim.ground_truth import frame_truth
from stackpick_sim.sim.randomize import draw
from stackpick_sim.sim.stacks import generate_scene

TAPE = ('object_types.tape={kind="tape", radius=0.045, height=0.03, mass=0.1, '
        'hole_radius=0.014, rgba=[0.9, 0.85, 0.7, 1.0]}')


def _pair(kind: str, *sets: str) -> SceneConfig:
    """Piles of two objects of one kind (a pile needs overlaps)."""
    return load_scene("realistic", ["objects.count=[2, 2]", f'objects.types=["{kind}"]', *sets])


def test_randomized_draws_are_seeded_in_range_and_differ_by_seed() -> None:
    cfg = load_scene("randomized")
    a, again, b = draw(cfg, 11), draw(cfg, 11), draw(cfg, 12)
    assert a == again and a != b
    assert not a.randomize
    for key, (lo, hi) in cfg.randomize.items():
        value = a.value_at(key)
        assert isinstance(value, int | float) and lo <= value <= hi
    assert isinstance(a.object_types["printed_large"].print_seed, int)
    paper = load_scene("paper")
    assert draw(paper, 11) is paper


def test_randomize_rejects_unknown_keys_and_bad_ranges() -> None:
    with pytest.raises(ConfigError, match="not a scene key"):
        load_scene("paper", ['randomize={"camera.nope" = [0, 1]}'])
    with pytest.raises(ConfigError, match="low <= high"):
        load_scene("paper", ['randomize={"camera.gain" = [3.0, 1.0]}'])


def test_realistic_piles_are_all_printed_lids_and_cans() -> None:
    cfg = load_scene("realistic")
    kinds = {cfg.object_types[t].kind for t in cfg.objects.types}
    assert kinds <= {"printed", "can", "tape"}
    assert cfg.camera.exposure_s >= 0.003 and cfg.camera.distortion[0] <= -0.15
    assert cfg.camera.full_well > 0 and cfg.camera.read_noise > 0 and cfg.camera.shadows
    assert cfg.conveyor.texture


def test_a_tape_roll_is_a_top_object_through_its_hole() -> None:
    cfg = _pair("tape", TAPE)
    cell = build_cell(cfg, ["tape"])
    (info,) = cell.objects
    # Upright on the belt, straight below the camera.
    centre = cell.look_point + np.array([0.0, 0.0, 0.015])
    cell.data.qpos[info.qpos_adr:info.qpos_adr + 7] = [*centre, 1.0, 0.0, 0.0, 0.0]
    mujoco.mj_forward(cell.model, cell.data)
    camera = WristCamera(cell)
    try:
        seg = camera.segmentation()
        truth = frame_truth(cell, seg)
    finally:
        camera.close()
    (obj,) = truth.objects
    assert obj.is_top and obj.visible_fraction > 0.98  # the ring is the face seen whole
    u, v = obj.face_center_px
    assert seg[round(v), round(u)] not in info.visual_geom_ids  # the belt, through the hole


def test_printed_lids_carry_artwork_and_the_render_is_deterministic() -> None:
    cfg = _pair("printed_large", "camera.distortion=[0.0, 0.0, 0.0, 0.0, 0.0]")
    frames = []
    for _ in range(2):
        scene = generate_scene(cfg, 4)
        camera = WristCamera(scene.cell)
        try:
            frames.append(camera.render(np.random.default_rng(0)))
            truth = frame_truth(scene.cell, camera.segmentation())
        finally:
            camera.close()
    assert np.array_equal(frames[0], frames[1])
    obj = next(o for o in truth.objects if o.is_top)
    assert obj.ellipse is not None
    inside = replace(obj.ellipse, a=0.8 * obj.ellipse.a, b=0.8 * obj.ellipse.b).mask(
        frames[0].shape[:2])
    face = frames[0][inside].astype(float)
    assert face.std(axis=0).max() > 25  # print across the face, not one flat colour


def test_the_belt_skin_moves_with_the_belt() -> None:
    scene = generate_scene(_pair("can"), 2)
    cell = scene.cell
    assert cell.belt_skin_mocap is not None
    before = float(cell.data.mocap_pos[cell.belt_skin_mocap, 1])
    conveyor = Conveyor(cell, np.random.default_rng(0))
    conveyor.start()  # one update
    for _ in range(10):
        conveyor.update()
    moved = float(cell.data.mocap_pos[cell.belt_skin_mocap, 1]) - before
    assert moved == pytest.approx(11 * conveyor.speed * cell.model.opt.timestep, rel=1e-6)


def test_clutter_is_seeded_and_beside_the_belt() -> None:
    cfg = load_scene("paper", ["conveyor.clutter=6"])

    def clutter(seed: int) -> np.ndarray:
        cell = build_cell(cfg, ["large"], seed)
        ids = [cell.model.geom(f"clutter{i}").id for i in range(6)]
        return cell.model.geom_pos[ids].copy()

    a, again, b = clutter(1), clutter(1), clutter(2)
    assert np.array_equal(a, again) and not np.array_equal(a, b)
    beyond = np.abs(a[:, 0] - cfg.conveyor.x) - cfg.conveyor.width / 2
    assert np.all(beyond > 0.02)  # off the belt: never under the pile

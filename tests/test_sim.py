"""The cell: scenes compile and step cleanly, piles are valid and deterministic, ground truth
agrees with the rendered image, the belt carries piles at its speed and drops them at its end."""

from __future__ import annotations

import math

import cv2
import mujoco
import numpy as np
import pytest

from stackpick_sim.config.loader import available_scenes, load_scene
from stackpick_sim.episodes.episode import BELT_STREAM
from stackpick_sim.exceptions import SceneGenerationError
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.conveyor import Conveyor
from stackpick_sim.sim.ground_truth import TOP_VISIBLE_FRACTION, top_face
from stackpick_sim.sim.snapshot import look_frame
from stackpick_sim.sim.stacks import Scene, generate_scene

PAPER_SEEDS = (3, 11)


@pytest.fixture(scope="module")
def paper_scenes() -> dict[int, Scene]:
    cfg = load_scene("paper")
    return {seed: generate_scene(cfg, seed) for seed in PAPER_SEEDS}


def _warnings(data: mujoco.MjData) -> dict[str, int]:
    return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(data.warning)
            if w.number}


@pytest.mark.parametrize("name", available_scenes())
def test_every_scene_steps_one_second_under_noisy_controls_without_warnings(name: str) -> None:
    scene = generate_scene(load_scene(name), 0)
    cell = scene.cell
    model, data = cell.model, cell.data
    Conveyor(cell, np.random.default_rng(0)).start()
    rng = np.random.default_rng(1)
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    for _ in range(round(1.0 / model.opt.timestep)):
        data.ctrl[:] = np.clip(data.ctrl + 0.02 * (hi - lo) * rng.standard_normal(model.nu),
                               lo, hi)
        mujoco.mj_step(model, data)
    assert _warnings(data) == {}
    assert np.all(np.isfinite(data.qpos))


def test_pile_is_valid(paper_scenes: dict[int, Scene]) -> None:
    cfg = load_scene("paper")
    for scene in paper_scenes.values():
        cell = scene.cell
        camera = WristCamera(cell)
        try:
            _, truth = look_frame(scene, camera)
        finally:
            camera.close()
        lo, hi = cfg.objects.count
        assert lo <= len(truth.objects) <= hi
        for obj in truth.objects:
            assert obj.on_belt
            assert obj.tilt_deg <= cfg.objects.max_tilt_deg
            assert obj.face_center_world[2] - cfg.conveyor.top_z <= cfg.objects.max_face_height
            assert obj.ellipse is not None
        assert truth.top_objects, "a settled pile always has an object nothing rests on"
        for obj in truth.objects:
            if obj.is_top:
                assert not obj.supports and obj.visible_fraction >= TOP_VISIBLE_FRACTION


def test_same_seed_same_scene_bit_for_bit_and_same_image(paper_scenes: dict[int, Scene]) -> None:
    seed = PAPER_SEEDS[0]
    again = generate_scene(load_scene("paper"), seed)
    first = paper_scenes[seed]
    assert np.array_equal(first.cell.data.qpos, again.cell.data.qpos)
    assert first.attempts == again.attempts
    images = []
    for scene in (first, again):
        camera = WristCamera(scene.cell)
        try:
            images.append(look_frame(scene, camera)[0])
        finally:
            camera.close()
    assert np.array_equal(images[0], images[1])


def test_different_seeds_differ(paper_scenes: dict[int, Scene]) -> None:
    a, b = (paper_scenes[s].cell for s in PAPER_SEEDS)
    assert len(a.objects) != len(b.objects) or not np.allclose(
        a.data.xpos[[o.body_id for o in a.objects]], b.data.xpos[[o.body_id for o in b.objects]])


def _gradient_peak_offsets(gray: np.ndarray, ellipse_points: np.ndarray,
                           centre: np.ndarray) -> np.ndarray:
    """For each outline point, the offset (px, along the radial direction) of the strongest
    image gradient within +-3 px."""
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3)
    mag = cv2.magnitude(gx, gy)
    radial = ellipse_points - centre
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    offsets = np.arange(-3.0, 3.01, 0.5)
    samples = ellipse_points[:, None, :] + offsets[None, :, None] * radial[:, None, :]
    map_x = samples[..., 0].astype(np.float32)
    map_y = samples[..., 1].astype(np.float32)
    profile = cv2.remap(mag, map_x, map_y, cv2.INTER_LINEAR)
    return offsets[np.argmax(profile, axis=1)]


def test_ground_truth_outline_of_top_faces_lies_on_image_edges(
        paper_scenes: dict[int, Scene]) -> None:
    checked = 0
    for scene in paper_scenes.values():
        camera = WristCamera(scene.cell)
        try:
            image = camera.render()  # clean: no noise, so the edge position is exact
            _, truth = look_frame(scene, camera)
        finally:
            camera.close()
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
        for obj in truth.objects:
            if not obj.is_top or obj.ellipse is None:
                continue
            e = obj.ellipse
            peaks = _gradient_peak_offsets(gray, e.points(120), np.array([e.cx, e.cy]))
            # The rendered rim is where the ground truth says, within a pixel, nearly all round.
            assert np.mean(np.abs(peaks) <= 1.0) >= 0.9, (obj.name, np.round(peaks, 1))
            checked += 1
    assert checked >= len(PAPER_SEEDS)


def test_visible_fraction_matches_segmentation_of_an_unoccluded_face(
        paper_scenes: dict[int, Scene]) -> None:
    scene = paper_scenes[PAPER_SEEDS[0]]
    camera = WristCamera(scene.cell)
    try:
        _, truth = look_frame(scene, camera)
    finally:
        camera.close()
    fractions = sorted(o.visible_fraction for o in truth.objects)
    assert fractions[-1] >= 0.99  # a top face is seen whole
    assert 0.0 <= fractions[0] < TOP_VISIBLE_FRACTION  # the pile overlaps: someone is hidden


@pytest.mark.parametrize("speed", [0.1, 0.3])
def test_conveyor_carries_the_pile_at_its_speed_within_one_percent(speed: float) -> None:
    cfg = load_scene("paper", [f"conveyor.speed={speed}", "conveyor.speed_jitter=0"])
    cell = generate_scene(cfg, PAPER_SEEDS[0]).cell
    belt = Conveyor(cell, np.random.default_rng(0))
    belt.start()
    ids = [o.body_id for o in cell.objects]

    def run(seconds: float) -> None:
        for _ in range(round(seconds / cell.model.opt.timestep)):
            belt.update()
            mujoco.mj_step(cell.model, cell.data)

    run(0.5)  # the pile may shift by a millimetre as it starts moving: measure steady state
    start, t0 = cell.data.xpos[ids].copy(), cell.data.time
    run(1.0)
    velocity = (cell.data.xpos[ids] - start) / (cell.data.time - t0)
    # The stack as a whole moves at the belt speed within 1% (measured: 0.1004 at 0.1 m/s).
    assert abs(float(np.mean(velocity[:, 1])) - speed) <= 0.01 * speed
    # Each object keeps with it: cylinders resting on others creep ~1 mm/s relative to the
    # belt (MuJoCo's soft contacts allow slow slip), i.e. at most ~1.7% of 0.1 m/s.
    np.testing.assert_allclose(velocity[:, 1], speed, rtol=0.02)
    assert np.all(np.abs(velocity[:, 0]) < 0.01 * speed)


def test_belt_speed_noise_is_seeded_and_has_the_configured_spread() -> None:
    cfg = load_scene("paper", ["conveyor.speed=0.2", "conveyor.speed_jitter=0.01",
                               "conveyor.jitter_period=0.01"])
    cell = generate_scene(cfg, PAPER_SEEDS[0]).cell
    runs = []
    for _ in range(2):
        belt = Conveyor(cell, np.random.default_rng(5))
        speeds = []
        for k in range(400):
            cell.data.time = 0.01 * k
            belt.update()
            speeds.append(belt.speed)
        runs.append(speeds)
    assert runs[0] == runs[1]
    assert math.isclose(float(np.mean(runs[0])), 0.2, abs_tol=0.003)
    assert math.isclose(float(np.std(runs[0])), 0.01, rel_tol=0.2)


def test_objects_past_the_belt_end_are_removed_cleanly() -> None:
    cfg = load_scene("paper", ["conveyor.length=0.5", "conveyor.speed=0.6",
                               "conveyor.speed_jitter=0"])
    cell = generate_scene(cfg, PAPER_SEEDS[0]).cell
    belt = Conveyor(cell, np.random.default_rng(0))
    belt.start()
    for _ in range(round(1.5 / cell.model.opt.timestep)):
        belt.update()
        mujoco.mj_step(cell.model, cell.data)
    assert sorted(belt.removed) == sorted(o.name for o in cell.objects)
    for obj in cell.objects:  # parked at rest outside the cell
        assert cell.data.xpos[obj.body_id][0] < -1.0
    assert _warnings(cell.data) == {}


def test_piles_taller_than_max_face_height_are_redrawn() -> None:
    # Low enough that many piles have a face above it (a cylinder on top of two others).
    cfg = load_scene("paper", ["objects.count=[3,3]", "objects.max_face_height=0.06"])
    redrawn = 0
    for seed in (0, 1, 2):
        scene = generate_scene(cfg, seed)
        redrawn += scene.rejections.get("face is above objects.max_face_height", 0)
        for obj in scene.cell.objects:
            centre, _ = top_face(scene.cell, obj, scene.cell.world_T_cam()[:3, 3])
            assert centre[2] - cfg.conveyor.top_z <= 0.06
    assert redrawn > 0


def test_impossible_pile_gives_one_clear_error() -> None:
    cfg = load_scene("paper", ["objects.count=[10,10]", "objects.pile_radius=0.0",
                               "objects.max_tilt_deg=1", "sim.max_attempts=2"])
    with pytest.raises(SceneGenerationError, match=r"no valid pile of 10 objects in 2 attempts"):
        generate_scene(cfg, 0)


# Seeds whose piles once collapsed on the belt: 38 and 99 on a steady one; 5671 and 5897
# under the belt's speed noise, in their episodes' own noise (stream BELT_STREAM).
@pytest.mark.parametrize(("seed", "jitter"), [(38, 0.0), (99, 0.0), (5671, 0.002),
                                              (5897, 0.002)])
def test_accepted_piles_ride_the_running_belt_without_collapsing(seed: int,
                                                                 jitter: float) -> None:
    cfg = load_scene("paper", [f"conveyor.speed_jitter={jitter}"])
    cell = generate_scene(cfg, seed).cell
    belt = Conveyor(cell, np.random.default_rng([seed, BELT_STREAM]))
    belt.start()
    ids = [o.body_id for o in cell.objects]
    pos0, axis0 = cell.data.xpos[ids].copy(), cell.data.xmat[ids][:, 6:9].copy()
    carried = 0.0
    for _ in range(round(1.5 / cell.model.opt.timestep)):  # as long as a pick takes
        belt.update()
        carried += belt.speed * cell.model.opt.timestep
        mujoco.mj_step(cell.model, cell.data)
    shift = np.linalg.norm(cell.data.xpos[ids] - pos0 - [0.0, carried, 0.0], axis=1)
    turn = np.degrees(np.arccos(np.clip(np.sum(cell.data.xmat[ids][:, 6:9] * axis0, 1), -1, 1)))
    assert np.all(shift < 0.005), np.round(shift * 1000, 2)  # mm: creep, not a collapse
    assert np.all(turn < 5.0), np.round(turn, 2)

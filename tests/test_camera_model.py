"""The camera model: lens distortion against exact ground truth, motion blur, sensor noise."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from stackpick_sim.config.scene_config import CameraCfg, ObjectsCfg, SceneConfig
from stackpick_sim.geometry import Ellipse
from stackpick_sim.sim import exposure, sensor
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.exposure import subframe_offsets
from stackpick_sim.sim.ground_truth import frame_truth
from stackpick_sim.sim.stacks import Scene, generate_scene
from stackpick_sim.vision.undistort import undistort, undistort_points

#: Strong barrel distortion: about 3 px at a face 80 px off the image centre.
DISTORTION = (-0.4, 0.1, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def scene() -> Scene:
    cfg = SceneConfig(objects=ObjectsCfg(count=(3, 3), pile_radius=0.1),
                      camera=CameraCfg(distortion=DISTORTION))
    return generate_scene(cfg, 5)


def _face_iou(image: np.ndarray, ellipse: Ellipse) -> float:
    """IoU of the pixels of the face's colour (read at its centre) and the ellipse, in a box."""
    u0, v0, u1, v1 = (int(x) for x in ellipse.bounds())
    box = (slice(max(v0 - 6, 0), v1 + 7), slice(max(u0 - 6, 0), u1 + 7))
    colour = image[round(ellipse.cy), round(ellipse.cx)].astype(float)
    near = np.linalg.norm(image.astype(float) - colour, axis=2) < 40.0
    inside = ellipse.mask(image.shape[:2])
    a, b = near[box], inside[box]
    return float(np.count_nonzero(a & b)) / float(np.count_nonzero(a | b))


def test_truth_ellipses_fit_the_undistorted_outlines(scene: Scene) -> None:
    camera = WristCamera(scene.cell)
    try:
        image = camera.render()
        truth = frame_truth(scene.cell, camera.segmentation())
    finally:
        camera.close()
    assert truth.as_dict()["distortion"] == list(DISTORTION)
    pinhole = undistort(image, truth.intrinsics)
    tops = [o for o in truth.objects if o.is_top and o.ellipse is not None]
    assert tops
    for o in tops:
        assert o.ellipse is not None
        fitted, raw = _face_iou(pinhole, o.ellipse), _face_iou(image, o.ellipse)
        assert fitted > 0.97, (o.name, fitted)
        assert raw < fitted  # the distorted frame does not fit the pinhole ellipse as well


def test_undistort_points_inverts_the_lens(scene: Scene) -> None:
    import cv2

    k = scene.cell.intrinsics
    pinhole = np.array([[40.0, 30.0], [300.0, 200.0], [160.0, 120.0]])
    normalised = np.column_stack([k.normalized(pinhole), np.ones(3)])
    distorted, _ = cv2.projectPoints(normalised, np.zeros(3), np.zeros(3), k.K,
                                     np.asarray(k.dist))
    back = undistort_points(distorted.reshape(-1, 2), k)
    assert np.allclose(back, pinhole, atol=1e-3)


def test_subframes_centre_on_the_time_stamp() -> None:
    t = subframe_offsets(0.004, 4)
    assert np.allclose(t, [-0.0015, -0.0005, 0.0005, 0.0015])


def test_motion_blur_smears_a_moving_pile_and_is_deterministic(scene: Scene) -> None:
    cell = scene.cell
    state = cell.data.qpos.copy(), cell.data.qvel.copy()
    for o in cell.objects:
        cell.data.qvel[o.dof_adr + 1] = 0.5  # m/s along +y: ~2 px over 4 ms at 0.3 m
    old_cfg = cell.cfg

    def exposed(**kw: object) -> np.ndarray:
        cell.cfg = replace(old_cfg, camera=replace(old_cfg.camera, exposure_s=0.004, **kw))
        cam = WristCamera(cell)
        try:
            out = cam.render()
            assert np.array_equal(out, cam.render())  # the state is restored after a frame
        finally:
            cam.close()
        return out.astype(float)

    try:
        sharp = WristCamera(cell).render().astype(float)
        ref = exposed(blur_subframes=64)
        coarse, fine = exposed(blur_subframes=4), exposed(blur_subframes=16)
        shifted = exposed(blur="shift")
    finally:
        cell.cfg = old_cfg
        cell.data.qpos[:], cell.data.qvel[:] = state
    assert np.array_equal(cell.data.qpos, state[0])
    edges = np.abs(ref - sharp).max(axis=2) > 2
    effect = np.abs(ref - sharp)[edges].mean()
    assert edges.sum() > 300 and effect > 5  # ~2 px of motion along every outline
    err_coarse, err_fine = (np.abs(x - ref)[edges].mean() for x in (coarse, fine))
    assert err_fine < 0.5 * err_coarse and err_fine < 0.1 * effect  # sub-frames converge
    assert np.abs(shifted - sharp)[edges].mean() > 0.5 * effect  # one render, smeared too


def test_photon_noise_grows_with_the_signal() -> None:
    cam = CameraCfg(full_well=5000.0, read_noise=5.0, gain=2.0)
    rng = np.random.default_rng(0)
    per_grey = 5000.0 / 255.0 / 2.0
    for grey in (1.0, 20.0, 200.0):  # 20 electrons: drawn from the Poisson law itself
        flat = np.full((200, 200, 3), grey, dtype=np.float32)
        out = sensor.expose(flat, cam, rng)
        expected = np.sqrt(grey / per_grey + (5.0 / per_grey) ** 2)
        assert out.std() == pytest.approx(expected, rel=0.05)
        assert out.mean() == pytest.approx(grey, abs=0.05 * grey + 0.02)


def test_jpeg_and_vignetting() -> None:
    flat = np.full((60, 80, 3), 200.0, dtype=np.float32)
    v = sensor.vignette(flat, 0.3)
    assert v[30, 40, 0] == pytest.approx(200.0, rel=0.01)
    assert v[0, 0, 0] == pytest.approx(140.0, rel=0.01)
    img = np.random.default_rng(1).integers(0, 255, (60, 80, 3), dtype=np.uint8)
    assert sensor.jpeg(img, 0) is img
    lossy = sensor.jpeg(img, 50)
    assert lossy.shape == img.shape and not np.array_equal(lossy, img)


def test_the_smear_filter_is_the_mean_of_shifted_copies() -> None:
    rng = np.random.default_rng(3)
    image = cv2.GaussianBlur(rng.random((40, 50, 3)).astype(np.float32) * 255, (0, 0), 1.5)
    for shift in ((0.5, 0.1), (2.3, -1.7), (-6.2, 3.3)):
        d = np.array(shift)
        n = max(2, math.ceil(float(np.hypot(*d)) * exposure.SHIFT_COPIES_PER_PX) + 1)
        copies = [cv2.warpAffine(image, np.array([[1.0, 0.0, s * d[0]], [0.0, 1.0, s * d[1]]]),
                                 (50, 40), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REPLICATE)
                  for s in np.linspace(-0.5, 0.5, n)]
        assert np.abs(exposure.smear(image, d) - np.mean(copies, axis=0)).max() < 1e-3

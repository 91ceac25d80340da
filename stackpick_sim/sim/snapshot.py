"""One look-pose frame of a scene with its ground truth, and its pictures for people."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stackpick_sim import overlay
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.ground_truth import FrameTruth, frame_truth
from stackpick_sim.sim.stacks import Scene, generate_scene
from stackpick_sim.vision.undistort import undistort

#: Second entry of the seed sequence of the look frame's pixel noise and light jitter, so that
#: they never share draws with the pile generator seeded by the scene seed alone.
LOOK_FRAME_STREAM = 1
#: Overlays are drawn on the frame enlarged by this factor.
OVERLAY_SCALE = 2


def look_frame(scene: Scene, camera: WristCamera) -> tuple[NDArray[np.uint8], FrameTruth]:
    """(RGB image with the scene's noise, ground truth) of the scene's current state."""
    rng = np.random.default_rng([scene.seed, LOOK_FRAME_STREAM])
    image = camera.render(rng)
    return image, frame_truth(scene.cell, camera.segmentation())


def seeded_look_frame(cfg: SceneConfig,
                      seed: int) -> tuple[Scene, NDArray[np.uint8], FrameTruth]:
    """Generate the scene of ``cfg`` and ``seed`` and take its look frame (RGB) and truth."""
    scene = generate_scene(cfg, seed)
    camera = WristCamera(scene.cell)
    try:
        image, truth = look_frame(scene, camera)
    finally:
        camera.close()
    return scene, image, truth


def truth_overlay(image_rgb: NDArray[np.uint8], truth: FrameTruth) -> NDArray[np.uint8]:
    """BGR picture: ground-truth face ellipses (green: top objects), face centres, labels.

    A distorted frame is drawn undistorted: the ellipses are exact in pinhole pixels.
    """
    return overlay.truth_overlay(undistort(image_rgb, truth.intrinsics), truth, OVERLAY_SCALE)

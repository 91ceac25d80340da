"""The ``complete`` stage: faces the merge never fitted whose outline is faint along part of
its length, proposed from arc pairs whose whole outline shows a consistent edge, on pinned
rendered frames and on synthetic images."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from dev_frames import GREY, GREY_DATA, dev_frame

from stackpick_sim.config.loader import load_scene
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, mask_iou
from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.detector import DetectorConfig, TopObjectDetector, detect
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.faint_faces import area_iou, contrast_shares
from stackpick_sim.vision.params import CompleteParams

K = CameraIntrinsics.from_fovy(45.0, 320, 240)
SHAPE = (240, 320)


def _ious(frame: BenchFrame, scene: str, overrides: tuple[str, ...] = (),
          complete: bool = True) -> tuple[float, float]:
    """(best IoU of a reported ellipse, IoU of the chosen face) with the best true top face,
    with the scene's settings, the ``complete`` stage run or skipped."""
    config = detector_config(frame, load_scene(scene, overrides).vision)
    if not complete:
        config = config.without("complete")
    found = TopObjectDetector(config).detect(frame.image_rgb)

    def best(e: Ellipse) -> float:
        return max(mask_iou(e, f.ellipse, frame.shape) for f in frame.tops)

    top = 0.0 if found.top_ellipse is None else best(found.top_ellipse)
    return max((best(e.ellipse) for e in found.ellipses), default=0.0), top


@pytest.mark.parametrize(("seed", "grey"), [(70135, False), (70163, True)])
def test_a_top_face_the_merge_never_fitted_is_proposed_and_chosen(seed: int,
                                                                  grey: bool) -> None:
    # Cluttered frame 70135: a steep blue face (tilt ~65 deg) whose boundary with its own
    # wall is faint; grey frame 70163 (both kinds light grey): a top face across faces of its
    # shade. In both, no merged ellipse is the face, and the top rule takes a lower one.
    frame = (dev_frame(seed, GREY_DATA, "paper", GREY) if grey else dev_frame(seed))
    scene, overrides = ("paper", GREY) if grey else ("cluttered", ())
    _, top_without = _ious(frame, scene, overrides, complete=False)
    assert top_without < MATCH_IOU
    _, top_with = _ious(frame, scene, overrides)
    assert top_with > 0.95


def test_a_proposal_needs_its_whole_outline_to_show() -> None:
    # Cluttered frame 70135 again: the face shows a consistent edge along ~97 % of its
    # outline; asking for all of it proposes nothing, and the lower face stays chosen.
    frame = dev_frame(70135)
    config = detector_config(frame, load_scene("cluttered").vision)
    strict = replace(config, complete=CompleteParams(min_contrast_share=1.0))
    found = TopObjectDetector(strict).detect(frame.image_rgb).top_ellipse
    assert found is None or max(mask_iou(found, f.ellipse, frame.shape)
                                for f in frame.tops) < MATCH_IOU


def _steep_face(step: float, seed: int) -> tuple[np.ndarray, Ellipse]:
    """A blue cylinder standing on the dark belt, seen from above its axis's plane: its face
    (34 x 14 px) ``step`` grey levels brighter than its wall below it (a faint boundary
    along the face's lower half, a strong one against the belt along its upper half), pixel
    noise of std 1; and the face."""
    rng = np.random.default_rng(seed)
    face = Ellipse(cx=160, cy=100, a=34, b=14, angle_deg=0)
    bottom = Ellipse(cx=160, cy=130, a=34, b=14, angle_deg=0)
    image = np.full((*SHAPE, 3), 30.0)
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    wall = bottom.mask(SHAPE) | ((np.abs(cols - 160) <= 34) & (rows >= 100) & (rows <= 130))
    image[wall] = (60.0, 110.0, 160.0)
    image[face.mask(SHAPE)] = (60.0 + 0.4 * step, 110.0 + 0.7 * step, 160.0 + step)
    image += rng.normal(0.0, 1.0, image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8), face


def test_a_steep_face_over_its_faint_wall_boundary_is_found_only_with_the_stage() -> None:
    image, face = _steep_face(12.0, 3)
    without = detect(image, DetectorConfig(intrinsics=K).without("complete"))
    assert max((mask_iou(e.ellipse, face, SHAPE) for e in without.ellipses), default=0.0) < 0.5
    found = detect(image, DetectorConfig(intrinsics=K))
    assert found.top_ellipse is not None
    assert mask_iou(found.top_ellipse, face, SHAPE) > 0.95
    assert "complete" in found.timings_ms


def test_a_whole_face_is_left_as_the_merge_fitted_it() -> None:
    # A strong boundary all round: the face is fitted whole, nothing is proposed, and the
    # detection is the one without the stage.
    image, face = _steep_face(40.0, 3)
    with_stage = detect(image, DetectorConfig(intrinsics=K))
    without = detect(image, DetectorConfig(intrinsics=K).without("complete"))
    assert with_stage.top_ellipse == without.top_ellipse
    assert [e.ellipse for e in with_stage.ellipses] == [e.ellipse for e in without.ellipses]
    assert with_stage.top_ellipse is not None
    assert mask_iou(with_stage.top_ellipse, face, SHAPE) > 0.95


def test_contrast_shares_read_a_face_whole_and_a_shifted_fit_in_part() -> None:
    image, face = _steep_face(12.0, 3)
    grad = edge_image(image)
    shifted = Ellipse(cx=face.cx + 40, cy=face.cy, a=face.a, b=face.b, angle_deg=0)
    whole, part = contrast_shares([face, shifted], grad).tolist()
    assert whole > 0.95
    assert part < 0.7
    assert contrast_shares([], grad).shape == (0,)


def test_area_iou_agrees_with_the_pixel_masks() -> None:
    one = Ellipse(cx=100, cy=80, a=30, b=20, angle_deg=20)
    other = Ellipse(cx=110, cy=85, a=28, b=18, angle_deg=35)
    assert area_iou(one, other) == pytest.approx(mask_iou(one, other, SHAPE), abs=0.02)
    assert area_iou(one, one) == 1.0
    far = Ellipse(cx=250, cy=200, a=20, b=10, angle_deg=0)
    assert area_iou(one, far) == 0.0


def test_the_settings_are_range_checked() -> None:
    with pytest.raises(ConfigError, match=r"vision\.complete\.min_contrast_share"):
        CompleteParams(min_contrast_share=1.5)
    with pytest.raises(ConfigError, match=r"vision\.complete\.max_faces"):
        CompleteParams(max_faces=-1)
    scene = load_scene("paper", ("vision.complete.same_face_iou=0.7",))
    assert scene.vision.complete.same_face_iou == 0.7

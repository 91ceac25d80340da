"""The top stage's face completion (``vision.complete``): faces the merge never fitted whose
outline is faint along part of its length, proposed from arc pairs whose whole outline shows
a consistent edge, on pinned rendered frames and on synthetic images."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

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
#: Pinned paper-scene frames.
PAPER_DATA = Path(__file__).parent / "data" / "paper_dev_frames"
#: The detector without the face completion.
OFF = DetectorConfig(intrinsics=K, complete=CompleteParams(enabled=False))


def _config(frame: BenchFrame, scene: str, overrides: tuple[str, ...] = (),
            **complete: object) -> DetectorConfig:
    """The detector's settings for ``frame`` in ``scene`` (``overrides`` applied), the
    ``complete`` fields replaced."""
    config = detector_config(frame, load_scene(scene, overrides).vision)
    return replace(config, complete=replace(config.complete, **complete))


def _top_iou(frame: BenchFrame, config: DetectorConfig) -> float:
    """IoU of the detector's choice with the best true top face; 0 for no choice."""
    found = TopObjectDetector(config).detect(frame.image_rgb).top_ellipse
    if found is None:
        return 0.0
    return max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)


@pytest.mark.parametrize(("seed", "grey"), [(70135, False), (70163, True)])
def test_after_a_clear_choice_faces_are_proposed_only_with_always(seed: int,
                                                                  grey: bool) -> None:
    # Cluttered frame 70135: a steep blue face (tilt ~53 deg), its boundary with its own wall
    # faint, leans on a whole orange face, which passes the rule outright (a clear choice).
    # Grey frame 70163 (both kinds light grey): a top face across faces of its shade, a
    # whole lower face passing outright. In both the merge fits no ellipse of the top face;
    # only with `always` is it proposed, and the rule then puts the lower face under it.
    frame = dev_frame(seed, GREY_DATA, "paper", GREY) if grey else dev_frame(seed)
    scene, overrides = ("paper", GREY) if grey else ("cluttered", ())
    assert _top_iou(frame, _config(frame, scene, overrides, enabled=False)) < MATCH_IOU
    assert _top_iou(frame, _config(frame, scene, overrides, always=False)) < MATCH_IOU
    assert _top_iou(frame, _config(frame, scene, overrides, always=True)) > 0.95


def test_the_cluttered_scene_proposes_faces_after_a_clear_choice() -> None:
    # Its piles often lay a top face the merge never fitted over a whole lower face that
    # passes the rule outright (frame 70135 above): the scene's own settings propose faces
    # after a clear choice as well, the paper scene's do not.
    assert load_scene("cluttered").vision.complete.always
    assert not load_scene("paper").vision.complete.always
    frame = dev_frame(70135)
    assert _top_iou(frame, detector_config(frame, load_scene("cluttered").vision)) > 0.95


def test_a_face_overlapping_a_merged_fit_by_the_same_face_iou_is_not_proposed() -> None:
    # Cluttered frame 70135 again: the merge's fit nearest the top face overlaps it by ~0.63;
    # counting that as the face fitted already proposes nothing.
    frame = dev_frame(70135)
    config = _config(frame, "cluttered", always=True, same_face_iou=0.6)
    assert _top_iou(frame, config) < MATCH_IOU


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
    without = detect(image, OFF)
    assert max((mask_iou(e.ellipse, face, SHAPE) for e in without.ellipses), default=0.0) < 0.5
    found = detect(image, DetectorConfig(intrinsics=K))
    assert found.top_ellipse is not None
    assert mask_iou(found.top_ellipse, face, SHAPE) > 0.95


def test_a_whole_face_is_left_as_the_merge_fitted_it() -> None:
    # A strong boundary all round: the face is fitted whole, nothing is proposed, and the
    # detection is the one without the stage.
    image, face = _steep_face(40.0, 3)
    with_stage = detect(image, DetectorConfig(intrinsics=K))
    without = detect(image, OFF)
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


def test_a_face_only_the_arc_pair_fallbacks_found_is_proposed_too() -> None:
    # Paper frame 3504: no fit passes the rule and the top face is found by the arc-pair
    # fallbacks alone; the face completion, after that unclear first choice, proposes it.
    frame = dev_frame(3504, PAPER_DATA, "paper")
    config = detector_config(frame)
    no_fallbacks = replace(config.top, fallbacks=())
    assert _top_iou(frame, replace(config, top=no_fallbacks)) > MATCH_IOU
    assert _top_iou(frame, replace(config, top=no_fallbacks,
                                   complete=CompleteParams(enabled=False))) == 0.0

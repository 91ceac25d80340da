"""Kinds that colour cannot tell apart: a face's kind from its size within the depth range
(:mod:`stackpick_sim.vision.kind_size`), for the top rule's depth test and its rest test
over every kind, on ellipses and on pinned rendered grey frames (both kinds light grey)."""

from __future__ import annotations

from dataclasses import replace

import pytest
from dev_frames import GREY, GREY_DATA, K, dev_frame

from stackpick_sim.config.loader import load_scene
from stackpick_sim.geometry import Ellipse, mask_iou
from stackpick_sim.vision import detector as detector_module
from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.detector import TopObjectDetector
from stackpick_sim.vision.kind_size import depth_per_metre, kinds_by_size, one_kind, size_kinds

#: The paper scene's kinds and depth range (camera 0.30 m above the belt, faces up to
#: 0.15 m above it).
RADII = (0.035, 0.025)
RANGE = (0.15, 0.30)


def _face(a: float) -> Ellipse:
    """A face seen square on at the image centre with semi-axes ``a`` px."""
    return Ellipse(cx=K.cx, cy=K.cy, a=a, b=a, angle_deg=0.0)


def test_a_face_imaged_small_is_of_the_smaller_kind() -> None:
    # 31 px: the large radius puts it ~0.33 m away, beyond the belt.
    per_metre = depth_per_metre(_face(31.0), K)
    assert per_metre * 0.035 > RANGE[1]
    assert size_kinds(per_metre, RADII, RANGE) == (0.025,)


def test_a_face_imaged_large_is_of_the_larger_kind() -> None:
    # 50 px: the small radius puts it ~0.145 m away, above the highest face.
    per_metre = depth_per_metre(_face(50.0), K)
    assert per_metre * 0.025 < RANGE[0]
    assert size_kinds(per_metre, RADII, RANGE) == (0.035,)


def test_a_face_both_kinds_fit_has_no_radius() -> None:
    # 40 px: 0.25 m as a large face, 0.18 m as a small one; both within the range.
    kinds_of = kinds_by_size(K, RADII, RANGE)
    assert kinds_of(_face(40.0)) == RADII
    assert one_kind(kinds_of)(_face(40.0)) is None
    assert one_kind(kinds_of)(_face(31.0)) == 0.025


def test_a_face_no_kind_fits_has_no_radius() -> None:
    # 20 px: beyond the belt even as a small face (0.43 m): no face of either kind.
    kinds_of = kinds_by_size(K, RADII, RANGE)
    assert kinds_of(_face(20.0)) == RADII
    assert one_kind(kinds_of)(_face(20.0)) is None


def _top_iou(frame: BenchFrame, **top: object) -> float:
    """IoU of the detector's choice on a grey frame (the paper scene with both kinds grey,
    ``top`` fields replaced) with the best true top face; 0 for no choice."""
    config = detector_config(frame, load_scene("paper", GREY).vision)
    config = replace(config, top=replace(config.top, **top))
    found = TopObjectDetector(config).detect(frame.image_rgb).top_ellipse
    if found is None:
        return 0.0
    return max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)


@pytest.mark.parametrize("seed", [
    # Two small faces show whole or nearly (the top one's outline 0.83 shown, nothing
    # crossing it); by its size each is of the small kind, and the top face reads 2.4 cm
    # nearer than the whole lower face, which the best-supported choice took.
    78129,
    # No face passes; the unobstructed fallback takes a lower face whose occluder clips its
    # rim, while the top face (two fits, 0.63 and 0.70 of the outline, nothing crossing)
    # reads 1.5 cm nearer, both of the small kind by their size.
    71315,
])
def test_a_grey_top_face_wins_the_depth_test_by_its_kind_from_its_size(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    frame = dev_frame(seed, GREY_DATA, "paper", GREY)
    assert _top_iou(frame) > MATCH_IOU
    # On frame 71315 the face completion, after the unclear first choice, proposes the top
    # face from arc pairs too: off.
    monkeypatch.setattr(detector_module, "complete_faces", lambda *a, **k: [])
    assert _top_iou(frame, kind_by_size=False) < MATCH_IOU


def test_the_rest_test_over_every_kind_takes_only_the_kinds_sizes_admit() -> None:
    # Grey frame 78054: three small faces show whole; an object leans on one of them, found
    # under the kinds their sizes admit (under every assignment of both kinds, a large radius
    # for either face left the lean undecided).
    frame = dev_frame(78054, GREY_DATA, "paper", GREY)
    assert _top_iou(frame) > MATCH_IOU
    assert _top_iou(frame, kind_by_size=False) < MATCH_IOU

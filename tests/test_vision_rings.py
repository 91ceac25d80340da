"""Ring faces round their hole (vision.rings) and faces whose rim band is not their own
surface (vision.markings.off_rim_share) in the top rule."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from painted import painted

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, mask_iou
from stackpick_sim.vision.benchmark.frames import iter_generated
from stackpick_sim.vision.benchmark.methods import run_ours
from stackpick_sim.vision.benchmark.scoring import score_frame
from stackpick_sim.vision.detector import DetectorConfig, detect
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.markings import MarkingTest, find_markings, off_rim_share
from stackpick_sim.vision.occlusion import OcclusionEvidence
from stackpick_sim.vision.params import MarkingParams
from stackpick_sim.vision.rings import hole_only

SHAPE = (240, 320)
K = CameraIntrinsics.from_fovy(45.0, 320, 240)
TAPE, LID = 0.05, 0.025
TAN, BLUE = (0.82, 0.74, 0.55), (0.3, 0.6, 0.85)
CONFIG = DetectorConfig(intrinsics=K, radii_m=(TAPE, LID), kind_colours=(TAN, BLUE),
                        heights_m=(0.025, 0.025), depth_range_m=(0.15, 0.30))
#: A tape roll's ring face, tilted, at ~0.26 m (f r / a), and its hole (a quarter of it).
RING = Ellipse(cx=130, cy=115, a=56, b=46, angle_deg=20)
HOLE = Ellipse(cx=130, cy=115, a=14, b=11.5, angle_deg=20)


def _image(layers: list[tuple[Ellipse, tuple[float, float, float]]]) -> np.ndarray:
    """RGB frame: dark belt, then each (ellipse, colour) painted filled, in order."""
    return painted(SHAPE, layers, seed=7)


def _points(image: np.ndarray) -> np.ndarray:
    vv, uu = np.nonzero(edge_image(image).edges)
    return np.stack([uu, vv], axis=1).astype(np.float64)


def _test(image: np.ndarray) -> MarkingTest:
    return MarkingTest(radii=(TAPE, LID), rim_radius_of=None, depth_ratio=1.0,
                       min_edge_share=0.75, margin_px=2.5, image=image)


def _whole(interior: int, perimeter: int) -> OcclusionEvidence:
    return OcclusionEvidence(support=1.0, longest_gap_px=0, occluded_ends=0,
                             interior_edge_px=interior, perimeter_px=perimeter)


def test_a_ring_face_with_its_hole_is_judged_as_a_face_with_markings() -> None:
    image = _image([(RING, TAN), (HOLE, (0.1, 0.1, 0.1))])
    points = _points(image)
    assert hole_only(RING, points, 2.5, 0.45, 0.95)
    # The hole's outline: about a quarter of the face's perimeter, below the markings
    # rule's share; the hole's fit, farther by its size, is the face's marking.
    evidence = [_whole(80, 320), _whole(0, 80)]
    found = find_markings([RING, HOLE], evidence, _test(image), None, points)
    assert found.marked == {0} and found.markings == {1}
    # Without the edge pixels the hole is not read: the face is not judged.
    assert find_markings([RING, HOLE], evidence, _test(image), None).marked == frozenset()


def test_edges_reaching_out_of_the_hole_are_no_hole() -> None:
    # A stripe across the face (printed artwork, or an object's edge running in): its edges
    # reach the rim, so the face is no ring round a hole.
    stripe = Ellipse(cx=130, cy=115, a=50, b=4, angle_deg=20)
    image = _image([(RING, TAN), (HOLE, (0.1, 0.1, 0.1)), (stripe, BLUE)])
    assert not hole_only(RING, _points(image), 2.5, 0.45, 0.95)


def test_the_hole_may_not_exceed_what_the_smallest_object_on_the_face_would_show() -> None:
    # A "hole" at 0.45 of the face with the smallest kind 0.3 of the face's radius: an
    # object lying on the face could show that small, so the face is not judged a ring.
    wide = Ellipse(cx=130, cy=115, a=24, b=20, angle_deg=20)
    image = _image([(RING, TAN), (wide, (0.1, 0.1, 0.1))])
    points = _points(image)
    assert hole_only(RING, points, 2.5, 0.5, 0.95)
    small_kind = MarkingTest(radii=(TAPE, 0.015), rim_radius_of=None, depth_ratio=1.0,
                             min_edge_share=0.75, margin_px=2.5, image=image,
                             params=MarkingParams(ring_hole_scale=0.5))
    found = find_markings([RING], [_whole(150, 320)], small_kind, None, points)
    assert found.marked == frozenset()


def test_a_ring_face_lying_on_a_lid_is_the_top() -> None:
    # The lid (the small kind) lies partly under the roll; a second lid lies apart, whole.
    under = Ellipse(cx=185, cy=150, a=27, b=26, angle_deg=0)
    apart = Ellipse(cx=260, cy=70, a=26, b=25.5, angle_deg=0)
    image = _image([(under, BLUE), (apart, BLUE), (RING, TAN), (HOLE, (0.1, 0.1, 0.1))])
    found = detect(image, CONFIG)
    assert found.top_ellipse is not None, found.reason
    assert mask_iou(found.top_ellipse, RING, SHAPE) > 0.9
    # With no interior edge read as a hole's, the ring fails on its hole and the lid apart
    # is taken.
    no_hole = replace(CONFIG, markings=MarkingParams(ring_hole_share=1.0, ring_hole_scale=0.0))
    found = detect(image, no_hole)
    assert found.top_ellipse is not None and mask_iou(found.top_ellipse, apart, SHAPE) > 0.9


def test_off_rim_share_reads_another_surface_across_the_rim_band() -> None:
    face = Ellipse(cx=160, cy=120, a=40, b=38, angle_deg=0)
    assert off_rim_share(face, _image([(face, BLUE)])) < 0.05
    # Another object's face across about a quarter of the band.
    over = Ellipse(cx=205, cy=120, a=30, b=30, angle_deg=0)
    assert off_rim_share(face, _image([(face, BLUE), (over, TAN)])) > 0.2


def test_a_whole_face_with_markings_and_another_surface_across_its_rim_is_no_candidate(
        ) -> None:
    face = Ellipse(cx=160, cy=120, a=40, b=38, angle_deg=0)
    over = Ellipse(cx=205, cy=120, a=30, b=30, angle_deg=0)
    evidence = [_whole(300, 250)]
    alone = find_markings([face], evidence, _test(_image([(face, BLUE)])), None)
    assert alone.marked == {0}
    across = find_markings([face], evidence, _test(_image([(face, BLUE), (over, TAN)])), None)
    assert across.marked == frozenset()


@pytest.mark.parametrize("seed", [70013, 70025])
def test_realistic_frames_whose_top_is_a_tape_roll(seed: int) -> None:
    # Rendered realistic frames whose top object is a tape roll, its ring face fitted whole:
    # found as a ring round its hole, missed when no interior edge counts as the hole's.
    frame = next(iter_generated(load_scene("realistic"), [seed]))
    assert score_frame(run_ours(frame), frame).success
    without = VisionCfg(markings=MarkingParams(ring_hole_share=1.0, ring_hole_scale=0.0))
    assert not score_frame(run_ours(frame, without), frame).success


@pytest.mark.parametrize("seed", [70037, 70099])
def test_realistic_frames_whose_wrong_candidate_has_another_surface_across_its_rim(
        seed: int) -> None:
    # 70099: a lower printed lid whose fit the small top lid's outline completes, the top lid
    # across its rim band; 70037: a fit round a small lid's face and its wall. Each is a
    # whole face with markings; with any share of its rim band off its colour allowed, it
    # is taken for the top.
    frame = next(iter_generated(load_scene("realistic"), [seed]))
    assert score_frame(run_ours(frame), frame).success
    lenient = VisionCfg(markings=MarkingParams(max_off_rim_share=1.0))
    assert not score_frame(run_ours(frame, lenient), frame).success

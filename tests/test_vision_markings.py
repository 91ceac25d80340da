"""The top rule on faces with markings or relief inside their outline (see vision.markings)."""

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
from stackpick_sim.vision.markings import MarkingTest, find_markings, two_surfaces
from stackpick_sim.vision.occlusion import OcclusionEvidence
from stackpick_sim.vision.params import TopParams

SHAPE = (240, 320)
K = CameraIntrinsics.from_fovy(45.0, 320, 240)
LARGE, SMALL = 0.035, 0.025
ORANGE, BLUE = (0.85, 0.6, 0.25), (0.3, 0.6, 0.85)
CONFIG = DetectorConfig(intrinsics=K, radii_m=(LARGE, SMALL), kind_colours=(ORANGE, BLUE),
                        heights_m=(0.03, 0.025), depth_range_m=(0.15, 0.30))
#: The large face, square on at ~0.25 m (f r / a).
FACE = Ellipse(cx=160, cy=120, a=40, b=40, angle_deg=0)


def _image(layers: list[tuple[Ellipse, tuple[float, float, float], bool]]) -> np.ndarray:
    """RGB frame: dark belt, then each (ellipse, colour, ring) painted in order: a filled
    face, or with ``ring`` a 2 px line (a printed or embossed ring) on what lies under it."""
    return painted(SHAPE, layers, seed=4)


def _top_iou(image: np.ndarray, truth: Ellipse, config: DetectorConfig = CONFIG) -> float:
    found = detect(image, config)
    assert found.top_ellipse is not None, found.reason
    return mask_iou(found.top_ellipse, truth, SHAPE)


def test_a_face_with_a_concentric_ring_is_the_top_not_its_ring() -> None:
    # A ring printed at 0.7 of the radius: a closed inner outline with nothing inside it.
    ring = Ellipse(cx=160, cy=120, a=28, b=28, angle_deg=0)
    dark = tuple(0.45 * c for c in ORANGE)
    image = _image([(FACE, ORANGE, False), (ring, dark, True)])
    assert _top_iou(image, FACE) > 0.9
    # Read as an object on the face (its depth ratio threshold above the ring's, 1 / 0.7),
    # the ring is the top: the setting decides.
    strict = DetectorConfig(intrinsics=K, radii_m=(LARGE, SMALL), kind_colours=(ORANGE, BLUE),
                            heights_m=(0.03, 0.025), depth_range_m=(0.15, 0.30),
                            marking_depth_ratio=2.0)
    assert _top_iou(image, ring, strict) > 0.8


def test_a_small_object_lying_wholly_on_a_large_face_is_still_the_top() -> None:
    # The small kind lying flat on the large face: 2.5 cm nearer, so f r / z = 31.8 px.
    small = Ellipse(cx=163, cy=118, a=31.8, b=31.8, angle_deg=0)
    image = _image([(FACE, ORANGE, False), (small, BLUE, False)])
    assert _top_iou(image, small) > 0.9


def _evidence(support: float, interior: int, perimeter: int) -> OcclusionEvidence:
    return OcclusionEvidence(support=support, longest_gap_px=0, occluded_ends=0,
                             interior_edge_px=interior, perimeter_px=perimeter)


def _marking_test(image: np.ndarray) -> MarkingTest:
    return MarkingTest(radii=(LARGE, SMALL), rim_radius_of=None, depth_ratio=1.0,
                       min_edge_share=0.75, margin_px=2.5, image=image)


#: A tilted face and the ellipse round it and its wall's silhouette: the face's far arc is
#: the outer ellipse's, its near arc (the face-to-wall rim) lies inside it.
TILTED = Ellipse(cx=160, cy=110, a=36, b=24, angle_deg=0)
SILHOUETTE = Ellipse(cx=160, cy=120, a=37, b=34, angle_deg=0)


def test_a_fit_round_a_face_and_its_darker_wall_is_no_face() -> None:
    # Whole both (no T-junction, support 1), both with edges inside (the face's artwork).
    evidence = [_evidence(1.0, 300, 230), _evidence(1.0, 200, 190)]
    wall = tuple(0.55 * c for c in ORANGE)
    image = _image([(SILHOUETTE, wall, False), (TILTED, ORANGE, False)])
    assert two_surfaces(SILHOUETTE, TILTED, image, 2.5)
    found = find_markings([SILHOUETTE, TILTED], evidence, _marking_test(image), None)
    assert 1 not in found.markings and 0 not in found.marked
    # The same outlines on one surface (a fit on the face's artwork and part of its outline
    # inside a whole printed face): the inner one is the face's marking.
    plain = _image([(SILHOUETTE, ORANGE, False)])
    assert not two_surfaces(SILHOUETTE, TILTED, plain, 2.5)
    found = find_markings([SILHOUETTE, TILTED], evidence, _marking_test(plain), None)
    assert found.markings == {1} and found.marked == {0}


def test_a_fit_round_a_face_and_a_lower_face_of_another_colour_is_no_face() -> None:
    evidence = [_evidence(1.0, 300, 230), _evidence(1.0, 200, 190)]
    image = _image([(SILHOUETTE, ORANGE, False), (TILTED, BLUE, False)])
    assert two_surfaces(SILHOUETTE, TILTED, image, 2.5)
    found = find_markings([SILHOUETTE, TILTED], evidence, _marking_test(image), None)
    assert found.markings == frozenset() and 0 not in found.marked


def test_verdicts_kept_for_one_image_do_not_carry_to_another() -> None:
    # The test judges the same pair again when arc-pair faces join the rule: its kept
    # verdicts answer then, and a copy for another image judges afresh.
    evidence = [_evidence(1.0, 300, 230), _evidence(1.0, 200, 190)]
    walled = _image([(SILHOUETTE, tuple(0.55 * c for c in ORANGE), False),
                     (TILTED, ORANGE, False)])
    test = _marking_test(walled)
    first = find_markings([SILHOUETTE, TILTED], evidence, test, None)
    assert test.known and find_markings([SILHOUETTE, TILTED], evidence, test, None) == first
    plain = replace(test, image=_image([(SILHOUETTE, ORANGE, False)]))
    found = find_markings([SILHOUETTE, TILTED], evidence, plain, None)
    assert found != first and found.markings == {1} and found.marked == {0}


def test_of_two_crossing_faces_with_markings_the_one_whose_outline_runs_on_is_above() -> None:
    # Two printed lids of one kind, the upper a little brighter (it faces the ring light
    # squarely): its outline shows across the lower face, the lower one's is hidden under it.
    lower = Ellipse(cx=140, cy=120, a=32, b=30, angle_deg=10)
    upper = Ellipse(cx=180, cy=125, a=33, b=31, angle_deg=0)
    lit = tuple(min(1.0, 1.15 * c) for c in BLUE)
    image = _image([(lower, BLUE, False), (upper, lit, False)])
    # Both whole, both with markings across them (interior edges along their perimeters).
    evidence = [_evidence(1.0, 250, 200), _evidence(1.0, 250, 200)]
    test = replace(_marking_test(image), gradients=edge_image(image))
    found = find_markings([lower, upper], evidence, test, None)
    assert found.marked == {1}
    # Without the gradients no outline is read: each is a whole face with its markings.
    found = find_markings([lower, upper], evidence, _marking_test(image), None)
    assert found.marked == {0, 1}


@pytest.mark.parametrize("seed", [70081, 70087])
def test_realistic_frames_whose_top_face_only_arc_pairs_fit(seed: int) -> None:
    # Rendered realistic frames whose top lid the merge never fits whole (its artwork or
    # rings cut the outline into arcs): found with the marked arc-pair faces, missed without.
    frame = next(iter_generated(load_scene("realistic"), [seed]))
    assert score_frame(run_ours(frame), frame).success
    without = VisionCfg(top=TopParams(marked_arcs=False))
    assert not score_frame(run_ours(frame, without), frame).success

"""The top stage's last step, when every face reads as occluded: a top face inside a lower
face's fit (``vision.inner_face``). A small top object standing nearly concentric on a larger
one of its colour and shade is fitted round the lower face's silhouette, its own wall's
boundary inside that fit as edges; no face passes the rule. Pinned rendered grey frames
(both kinds light grey, PNG and ground-truth JSON as `stackpick dataset` writes them) and a
synthetic stack."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from dev_frames import GREY, GREY_DATA, K, dev_frame

from stackpick_sim.config.loader import load_scene
from stackpick_sim.geometry import Ellipse, mask_iou
from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.detector import DetectorConfig, TopObjectDetector, detect
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.inner_face import enclosing, inner_refit
from stackpick_sim.vision.occlusion import OcclusionEvidence
from stackpick_sim.vision.params import FitParams, InnerFaceParams, TopParams, WholeRefitParams

SHAPE = (240, 320)
OFF = InnerFaceParams(enabled=False)
#: The whole-refit step, which finds some of these top faces too (from a fit of the top face
#: on part of its outline), off.
NO_WHOLE_REFIT = WholeRefitParams(enabled=False)


def _found(frame: BenchFrame, enabled: bool = True) -> Ellipse | None:
    """The detector's top face on ``frame`` (its scene's settings), with the step on or
    off."""
    config = replace(detector_config(frame), whole_refit=NO_WHOLE_REFIT)
    if not enabled:
        config = replace(config, inner_face=OFF)
    return TopObjectDetector(config).detect(frame.image_rgb).top_ellipse


def _top_iou(found: Ellipse | None, frame: BenchFrame) -> float:
    assert found is not None
    return max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)


@pytest.mark.parametrize("seed", [71161, 78240])
def test_a_top_face_inside_a_lower_faces_fit_is_found_when_every_face_reads_occluded(
        seed: int) -> None:
    # Grey frames: a small top object stands on a large one, the fit runs round the large
    # face's silhouette with the top object's wall boundary inside it (and, on 78240, a
    # T-junction where the top object's wall meets the large face's rim). With the step off
    # no top is returned at all.
    frame = dev_frame(seed, GREY_DATA, "paper", GREY)
    assert _found(frame, enabled=False) is None
    assert _top_iou(_found(frame), frame) > 0.9


def test_the_scene_key_switches_the_step() -> None:
    cfg = load_scene("paper", [*GREY, "vision.inner_face.enabled=false"])
    assert cfg.vision.inner_face.enabled is False
    assert load_scene("paper", GREY).vision.inner_face.enabled is True


#: The synthetic stack's lower face and top face (seen square on).
LOWER = Ellipse(cx=162, cy=121, a=44, b=42, angle_deg=0)
TOP = Ellipse(cx=169, cy=121, a=34, b=34, angle_deg=0)


def _stack(wall: float, noise: float, step: float = 2.0) -> np.ndarray:
    """A small grey top face (``TOP``) standing on a larger grey face (``LOWER``) nearly
    concentric with it: slivers of the larger face 8 px wide above and below it, 3 px beyond
    one side; on the other side its own wall, a crescent ``wall`` grey levels darker (the top
    face's outline shifted 6 px along the cylinder's axis), 11 px inside the larger face's
    silhouette. The top face is ``step`` grey levels brighter than the lower face (a faint
    step), on the dark belt, with pixel noise of std ``noise``."""
    rng = np.random.default_rng(5)
    image = np.full((*SHAPE, 3), 35.0)
    image[LOWER.mask(SHAPE)] = 175.0
    image[replace(TOP, cx=TOP.cx - 6).mask(SHAPE)] = 175.0 - wall
    image[TOP.mask(SHAPE)] = 175.0 + step
    image += rng.normal(0.0, noise, image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def test_a_synthetic_top_face_inside_a_lower_faces_fit_is_the_top() -> None:
    # The lower face's fit holds the wall's boundary inside it; the top face's own fit
    # shows its wall side alone. No face passes the rule and no fallback finds one.
    image = _stack(90.0, 1.0)
    config = DetectorConfig(intrinsics=K, whole_refit=NO_WHOLE_REFIT)
    assert detect(image, replace(config, inner_face=OFF)).top_ellipse is None
    found = detect(image, config).top_ellipse
    assert found is not None and mask_iou(found, TOP, SHAPE) > 0.9


@pytest.mark.parametrize(("wall", "noise", "step"),
                         [(90.0, 1.0, 2.0), (60.0, 1.0, 2.0), (120.0, 0.5, 3.0)])
def test_the_inner_refit_of_a_fit_round_a_face_and_a_sliver_is_the_face(
        wall: float, noise: float, step: float) -> None:
    grad = edge_image(_stack(wall, noise, step))
    refit = inner_refit(LOWER, grad, SHAPE, None, TopParams(), FitParams())
    assert refit is not None and mask_iou(refit, TOP, SHAPE) > 0.9
    # The fit reaches 17 px beyond the face on the wall's side (the crescent and the lower
    # face beyond it). A reach short of that, a least inset wider than it, or a gate below
    # the face's size keep no refit.
    assert inner_refit(LOWER, grad, SHAPE, None, TopParams(inner_refit_reach_px=5),
                       FitParams()) is None
    assert inner_refit(LOWER, grad, SHAPE, None, TopParams(inner_refit_min_inset_px=20.0),
                       FitParams()) is None
    assert inner_refit(LOWER, grad, SHAPE, (20.0, 30.0), TopParams(), FitParams()) is None


def test_a_well_fitted_face_has_no_inner_refit() -> None:
    grad = edge_image(_stack(90.0, 1.0))
    assert inner_refit(TOP, grad, SHAPE, None, TopParams(), FitParams()) is None


def test_only_fits_with_edges_inside_and_half_their_outline_can_enclose_a_face() -> None:
    evidence = [OcclusionEvidence(support=0.9, longest_gap_px=10, occluded_ends=1,
                                  interior_edge_px=40, perimeter_px=200),
                OcclusionEvidence(support=0.9, longest_gap_px=10, occluded_ends=0,
                                  interior_edge_px=2, perimeter_px=200),
                OcclusionEvidence(support=0.5, longest_gap_px=90, occluded_ends=0,
                                  interior_edge_px=40, perimeter_px=200),
                OcclusionEvidence(support=1.0, longest_gap_px=0, occluded_ends=0,
                                  interior_edge_px=80, perimeter_px=200)]
    assert enclosing(evidence, 0.6) == [0, 3]
    assert enclosing(evidence, 0.95) == [3]

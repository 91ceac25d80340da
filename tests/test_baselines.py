"""Baseline (RHT) and peer (findEllipses, EdgeDrawing) detectors behind the common interface.

Test images are local on purpose: a bright filled ellipse drawn with ``cv2.ellipse`` on a
dark background plus seeded Gaussian noise. Note that ``cv2.ellipse``'s anti-aliased fill
reaches ~0.6 px beyond the nominal outline, so a perfect detector scores IoU ~0.97 against
the nominal 50 x 30 px ellipse used here, not 1.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

import stackpick_sim.vision.baselines as baselines
from stackpick_sim.exceptions import ConfigError, ImageError, StackpickError
from stackpick_sim.geometry import Ellipse, mask_iou
from stackpick_sim.vision.baselines import (
    EdgeDrawingDetector,
    EllipseDetector,
    FindEllipsesDetector,
    RHTConfig,
    RHTDetector,
    ScoredEllipse,
    detect_ellipses_rht,
    ellipse_from_ed_row,
    ellipse_from_fe_row,
)

SHAPE = (240, 320)
BACKGROUND = 40
NOISE_SIGMA = 4.0
RECOVERY_IOU = 0.95
ANGLES = list(range(0, 180, 15))

DETECTORS: dict[str, EllipseDetector] = {
    "rht": RHTDetector(seed=7),
    "find_ellipses": FindEllipsesDetector(),
    "edge_drawing": EdgeDrawingDetector(),
}

#: Rotations at which findEllipses' top detection falls below IoU 0.95 on these exact images
#: (opencv-contrib 5.0; it scores 0.88-0.98 over the 12). Its estimates are quantised by
#: construction (whole-pixel a, whole-degree angle, b / a in steps of 0.01) and its centre is
#: a median of integer chord midpoints. Which rotations fail depends on the noise draw.
#: Strict, so that an upstream improvement shows up as an unexpected pass.
FE_FAILING_ANGLES = {0, 30, 45, 60, 105, 165}


def draw(ellipses: list[Ellipse], levels: list[int], seed: int) -> NDArray[np.uint8]:
    """(240, 320) uint8 image of filled ellipses (later ones on top) with seeded noise."""
    rng = np.random.default_rng(seed)
    img = np.full(SHAPE, BACKGROUND, np.uint8)
    for e, level in zip(ellipses, levels, strict=True):
        cv2.ellipse(img, ((e.cx, e.cy), (2 * e.a, 2 * e.b), e.angle_deg), level, -1,
                    cv2.LINE_AA)
    noisy = img + rng.normal(0.0, NOISE_SIGMA, SHAPE)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def single(angle: float) -> tuple[NDArray[np.uint8], Ellipse]:
    truth = Ellipse(cx=160.3, cy=118.7, a=50.0, b=30.0, angle_deg=float(angle))
    return draw([truth], [200], seed=int(angle)), truth


def best_iou(found: list[ScoredEllipse], truth: Ellipse) -> float:
    return max((mask_iou(d.ellipse, truth, SHAPE) for d in found), default=0.0)


def test_all_names_exported() -> None:
    for name in baselines.__all__:
        assert hasattr(baselines, name), name


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("name", list(DETECTORS))
def test_recovers_rotated_ellipse(name: str, angle: int, request: pytest.FixtureRequest) -> None:
    if name == "find_ellipses" and angle in FE_FAILING_ANGLES:
        request.applymarker(pytest.mark.xfail(strict=True, reason="findEllipses' quantised "
                                              "estimates miss IoU 0.95 at this rotation"))
    img, truth = single(angle)
    found = DETECTORS[name](img)
    assert found, f"{name} found nothing at {angle} deg"
    assert mask_iou(found[0].ellipse, truth, SHAPE) > RECOVERY_IOU


@pytest.mark.parametrize("name", list(DETECTORS))
def test_results_scored_sorted_and_in_convention(name: str) -> None:
    img, _ = single(30)
    two = draw([Ellipse(cx=90, cy=120, a=40, b=25, angle_deg=30),
                Ellipse(cx=230, cy=110, a=35, b=30, angle_deg=100)], [180, 220], seed=3)
    for found in (DETECTORS[name](img), DETECTORS[name](two)):
        assert found
        scores = [d.score for d in found]
        assert scores == sorted(scores, reverse=True)
        for d in found:
            assert 0.0 <= d.score <= 1.0
            e = d.ellipse
            assert e.a >= e.b > 0.0 and 0.0 <= e.angle_deg < 180.0


@pytest.mark.parametrize("name", list(DETECTORS))
def test_bgr_input_same_as_gray(name: str) -> None:
    img, _ = single(45)
    bgr = np.asarray(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    assert DETECTORS[name](bgr) == DETECTORS[name](img)


def test_fe_row_conversion() -> None:
    row = np.array([100.0, 50.0, 30.0, 10.0, 0.9, math.radians(150.0)], dtype=np.float32)
    e = ellipse_from_fe_row(row)
    assert (e.cx, e.cy, e.a, e.b) == pytest.approx((100.0, 50.0, 30.0, 10.0))
    assert e.angle_deg == pytest.approx(150.0, abs=1e-4)


def test_ed_row_conversion_ellipse_and_circle() -> None:
    # ED puts the semi-axis lying along angle_deg first; here it is the minor one.
    e = ellipse_from_ed_row(np.array([100.0, 50.0, 0.0, 10.0, 30.0, -30.0]))
    assert (e.a, e.b) == (30.0, 10.0)
    assert e.angle_deg == pytest.approx(60.0)
    c = ellipse_from_ed_row(np.array([100.0, 50.0, 12.5, 0.0, 0.0, 0.0]))
    assert (c.cx, c.cy, c.a, c.b) == (100.0, 50.0, 12.5, 12.5)


def test_ed_reports_circles_as_radius() -> None:
    img = draw([Ellipse(cx=150.0, cy=120.0, a=30.0, b=30.0, angle_deg=0.0)], [200], seed=1)
    ed = cv2.ximgproc.createEdgeDrawing()
    ed.detectEdges(img)
    rows = ed.detectEllipses().reshape(-1, 6)
    assert rows[0, 2] > 0.0 and rows[0, 3] == 0.0 and rows[0, 4] == 0.0
    found = EdgeDrawingDetector()(img)
    assert found[0].ellipse.a == found[0].ellipse.b == pytest.approx(rows[0, 2])


def test_rht_same_seed_same_output() -> None:
    img = draw([Ellipse(cx=140, cy=120, a=45, b=28, angle_deg=20),
                Ellipse(cx=185, cy=125, a=38, b=30, angle_deg=110)], [170, 220], seed=11)
    first = detect_ellipses_rht(img, 123)
    assert first
    assert detect_ellipses_rht(img, 123) == first
    assert detect_ellipses_rht(img, np.random.default_rng(123)) == first
    det = RHTDetector(seed=123)
    assert det(img) == det(img) == first


def test_rht_other_seed_still_finds_the_ellipse() -> None:
    img, truth = single(30)
    for seed in (1, 2, 3):
        assert best_iou(detect_ellipses_rht(img, seed), truth) > RECOVERY_IOU


def test_rht_finds_both_of_two_overlapping_ellipses() -> None:
    under = Ellipse(cx=140.0, cy=120.0, a=45.0, b=28.0, angle_deg=20.0)
    top = Ellipse(cx=185.0, cy=125.0, a=38.0, b=30.0, angle_deg=110.0)
    assert mask_iou(under, top, SHAPE) > 0.05  # they do overlap
    img = draw([under, top], [150, 220], seed=5)
    found = RHTDetector(seed=0)(img)
    assert best_iou(found, top) > RECOVERY_IOU
    # The occluded one keeps ~75 % of its outline; IoU 0.9 allows for the hidden arc.
    assert best_iou(found, under) > 0.9


GARBAGE_OK: dict[str, NDArray[np.uint8]] = {
    "black": np.zeros(SHAPE, np.uint8),
    "white": np.full(SHAPE, 255, np.uint8),
    "noise": np.random.default_rng(0).integers(0, 256, SHAPE, dtype=np.uint8),
    "1x1": np.zeros((1, 1), np.uint8),
    "1x300": np.full((1, 300), 9, np.uint8),
    "7x7_bgr": np.zeros((7, 7, 3), np.uint8),
    "fortran_order": np.asfortranarray(np.zeros(SHAPE, np.uint8)),
}
GARBAGE_BAD: dict[str, object] = {
    "float": np.zeros(SHAPE, np.float32),
    "uint16": np.zeros(SHAPE, np.uint16),
    "bool": np.zeros(SHAPE, bool),
    "1d": np.zeros(10, np.uint8),
    "4d": np.zeros((2, 2, 2, 2), np.uint8),
    "2_channels": np.zeros((*SHAPE, 2), np.uint8),
    "empty": np.zeros((0, 5), np.uint8),
    "list": [[0, 1], [2, 3]],
}


@pytest.mark.parametrize("image_name", list(GARBAGE_OK))
@pytest.mark.parametrize("name", list(DETECTORS))
def test_valid_but_empty_images_give_no_detection(name: str, image_name: str) -> None:
    assert DETECTORS[name](GARBAGE_OK[image_name]) == []


@pytest.mark.parametrize("image_name", list(GARBAGE_BAD))
@pytest.mark.parametrize("name", list(DETECTORS))
def test_non_images_raise_image_error(name: str, image_name: str) -> None:
    with pytest.raises(ImageError) as info:
        DETECTORS[name](GARBAGE_BAD[image_name])  # type: ignore[arg-type]
    assert isinstance(info.value, StackpickError)


@pytest.mark.parametrize("kwargs", [
    {"min_semi_axis_px": 50.0, "max_semi_axis_px": 40.0},
    {"vote_threshold": 0},
    {"min_coverage": 1.5},
    {"batch_size": 0},
    {"sobel_magnitude_threshold": -1.0},
    {"edge_source": "canny"},
])
def test_rht_config_validation(kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        RHTConfig(**kwargs)  # type: ignore[arg-type]


def test_scored_ellipse_rejects_score_outside_unit_interval() -> None:
    e = Ellipse(cx=0.0, cy=0.0, a=2.0, b=1.0, angle_deg=0.0)
    with pytest.raises(ValueError, match="outside"):
        ScoredEllipse(ellipse=e, score=1.5)


def test_rht_on_shared_edge_stage_recovers_ellipse() -> None:
    img, truth = single(75)
    found = RHTDetector(seed=0, config=RHTConfig(edge_source="shared"))(img)
    assert best_iou(found, truth) > RECOVERY_IOU

"""Tests of the ellipse pipeline stages on synthetic images of known ellipses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.edges import detect_edges
from stackpick_sim.vision.fitting import fit_ellipse, fit_segment, satisfies_eq2
from stackpick_sim.vision.merging import merge_segments
from stackpick_sim.vision.segments import link_segments, neighbour_count
from stackpick_sim.vision.synthetic import draw_ellipses

SHAPE = (240, 320)


def _angle_error(a: float, b: float) -> float:
    """Smallest difference of two axis directions, degrees (mod 180)."""
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def _detect_ellipses(image: np.ndarray) -> list[Ellipse]:
    from stackpick_sim.vision.detector import detect

    return [d.ellipse for d in detect(image).ellipses]


@pytest.mark.parametrize("angle", range(0, 180, 15))
def test_single_ellipse_recovered_at_every_rotation(angle: int) -> None:
    truth = Ellipse(cx=161.3, cy=118.6, a=34.0, b=21.0, angle_deg=float(angle))
    rng = np.random.default_rng(angle)
    image = draw_ellipses(SHAPE, [truth], noise_sigma=3.0, rng=rng)
    found = _detect_ellipses(image)
    assert found, "no ellipse found"
    best = min(found, key=lambda e: math.hypot(e.cx - truth.cx, e.cy - truth.cy))
    assert math.hypot(best.cx - truth.cx, best.cy - truth.cy) < 0.3
    assert abs(best.a - truth.a) < 0.5 and abs(best.b - truth.b) < 0.5
    assert _angle_error(best.angle_deg, truth.angle_deg) < 1.5


def test_edges_are_one_pixel_wide_closed_curve() -> None:
    image = draw_ellipses(SHAPE, [Ellipse(cx=160, cy=120, a=40, b=25, angle_deg=33)])
    edges = detect_edges(image)
    counts = neighbour_count(edges)[edges > 0]
    assert counts.size > 150
    assert np.all(counts == 2), "a lone ellipse must give a loop without ends or junctions"


def test_edges_adapt_to_contrast_and_noise() -> None:
    truth = Ellipse(cx=150, cy=110, a=30, b=20, angle_deg=70)
    counts = []
    for fg, bg, sigma in ((200, 40, 0.0), (70, 50, 1.0), (220, 30, 5.0)):
        image = draw_ellipses(SHAPE, [truth], foreground=fg, background=bg, noise_sigma=sigma,
                              rng=np.random.default_rng(1))
        counts.append(int(np.count_nonzero(detect_edges(image))))
    perimeter = 2 * math.pi * math.sqrt((30**2 + 20**2) / 2)
    for c in counts:
        assert 0.8 * perimeter < c < 1.3 * perimeter


def test_fit_ellipse_exact_points_and_eq2() -> None:
    truth = Ellipse(cx=100.0, cy=80.0, a=30.0, b=12.0, angle_deg=125.0)
    fit = fit_ellipse(truth.points(50))
    assert fit is not None and satisfies_eq2(fit)
    assert math.hypot(fit.cx - truth.cx, fit.cy - truth.cy) < 1e-3
    assert abs(fit.a - truth.a) < 1e-3 and abs(fit.b - truth.b) < 1e-3
    assert _angle_error(fit.angle_deg, truth.angle_deg) < 1e-3


def test_straight_and_short_segments_rejected() -> None:
    line = np.stack([np.arange(40), np.round(0.3 * np.arange(40))], axis=1).astype(np.int32)
    assert fit_segment(line, SHAPE) is None
    arc = np.rint(Ellipse(cx=50, cy=50, a=20, b=15, angle_deg=0).points(200)[:6]).astype(np.int32)
    assert fit_segment(arc, SHAPE) is None


def test_eq3_merges_split_arcs_of_one_ellipse_only() -> None:
    one = Ellipse(cx=120, cy=120, a=40, b=28, angle_deg=20)
    other = Ellipse(cx=235, cy=110, a=30, b=26, angle_deg=60)
    image = draw_ellipses(SHAPE, [one, other], noise_sigma=1.0, rng=np.random.default_rng(2))
    edges = detect_edges(image)
    # Cut the first outline into three arcs with two gaps, as occluders would.
    for gap in (one.points(8)[1], one.points(8)[5]):
        u, v = round(gap[0]), round(gap[1])
        edges[v - 4:v + 5, u - 4:u + 5] = 0
    segs = link_segments(edges)
    fits = []
    for i, chain in enumerate(segs.chains):
        fit = fit_segment(chain, SHAPE)
        if fit is not None:
            fits.append((i, fit[0]))
    on_one = [i for i, e in fits if math.hypot(e.cx - one.cx, e.cy - one.cy) < 15]
    assert len(on_one) >= 2, "the cut outline must give several arcs"
    merged = merge_segments(segs.chains, fits, edges)
    best = max(merged, key=lambda m: len(m.segments))
    assert set(on_one) <= set(best.segments)
    assert math.hypot(best.ellipse.cx - one.cx, best.ellipse.cy - one.cy) < 0.5
    assert abs(best.ellipse.a - one.a) < 0.7 and abs(best.ellipse.b - one.b) < 0.7
    assert sum(math.hypot(m.ellipse.cx - other.cx, m.ellipse.cy - other.cy) < 1.0
               for m in merged) == 1


def test_segments_split_at_junction() -> None:
    edges = np.zeros((60, 60), np.uint8)
    edges[30, 5:55] = 1  # main stream
    edges[31:55, 30] = 1  # branch ending at it: a T
    segs = link_segments(edges)
    assert segs.junctions.any()
    assert len(segs.chains) == 3
    for chain in segs.chains:
        steps = np.abs(np.diff(chain, axis=0)).max(axis=1)
        assert np.all(steps == 1), "chains must be ordered 8-connected paths"


def test_crop_intrinsics_equal_the_checked_constructors() -> None:
    from stackpick_sim.geometry import CameraIntrinsics
    from stackpick_sim.vision.detector import _crop_intrinsics

    k = CameraIntrinsics(fx=290.5, fy=291.0, cx=159.5, cy=119.5, width=320, height=240,
                         dist=(0.1, -0.05, 0.001, 0.0, 0.0))
    crop = _crop_intrinsics(k, (12, 7))
    # Every field, a new one included: the crop of the undistorted frame has no distortion.
    assert crop == CameraIntrinsics(fx=290.5, fy=291.0, cx=147.5, cy=112.5, width=320,
                                    height=240)
    assert vars(crop) == vars(CameraIntrinsics(fx=290.5, fy=291.0, cx=147.5, cy=112.5,
                                               width=320, height=240))

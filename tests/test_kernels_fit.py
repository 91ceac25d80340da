"""The compiled direct ellipse fit: OpenCV's ``cv2.fitEllipseDirect`` rows on random point
sets, known ellipses recovered, and the same verdict on degenerate inputs."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams
from stackpick_sim.vision import kernels, kernels_fit
from stackpick_sim.vision.fitting import EQ2_CHECKED_RATIO_SQ, fit_ellipse, plausible

SHAPE = (240, 320)


def _arc(rng: np.random.Generator, a: float, b: float, n: int, span: float, noise: float
         ) -> NDArray[np.float64]:
    """(n, 2) points along a random arc of ``span`` rad of a random ellipse of semi-axes
    (a, b) placed in the image, with Gaussian noise of ``noise`` px."""
    t = np.sort(rng.uniform(0.0, span, n)) + rng.uniform(0.0, 2.0 * np.pi)
    r = rng.uniform(0.0, np.pi)
    x, y = a * np.cos(t), b * np.sin(t)
    centre = rng.uniform((0.0, 0.0), (SHAPE[1], SHAPE[0]))
    rotated = np.column_stack([x * np.cos(r) - y * np.sin(r), x * np.sin(r) + y * np.cos(r)])
    return centre + rotated + rng.normal(0.0, noise, (n, 2))


def _random_arc(rng: np.random.Generator) -> NDArray[np.float64]:
    """A random arc: long or short (5 to 10 points), any axis ratio down to 1:7, noisy."""
    a = rng.uniform(8.0, 150.0)
    n = int(rng.integers(5, 11)) if rng.random() < 0.3 else int(rng.integers(11, 400))
    return _arc(rng, a, max(5.0, a * rng.uniform(0.15, 1.0)), n, rng.uniform(0.3, 2 * np.pi),
                rng.uniform(0.0, 1.5))


def _degenerate(points: NDArray) -> bool:
    """Whether ``points`` determine no ellipse: fewer than five distinct points, or pixels
    all in two rows, columns or diagonals (a pair of lines fits them exactly)."""
    if len(np.unique(points, axis=0)) < 5:
        return True
    u, v = points[:, 0], points[:, 1]
    return points.dtype == np.int32 and min(len(np.unique(w)) for w in (u, v, u + v, u - v)) <= 2


def _opencv_row(points: NDArray) -> NDArray[np.float64]:
    """OpenCV's direct fit of ``points`` as a row (cx, cy, w, h, angle); float64 points as
    float32 (OpenCV's input types are int32 and float32)."""
    if points.dtype == np.float64:
        points = points.astype(np.float32)
    (cx, cy), (w, h), angle = cv2.fitEllipseDirect(points)
    return np.array([cx, cy, w, h, angle])


def _accepted(row: NDArray[np.float64]) -> bool:
    """The callers' verdict on a direct fit's row: an ellipse within the default axis
    bounds (fit_ellipse's checks and plausible's, as kernels.fit_checks applies them)."""
    params = FitParams()
    ok = kernels.fit_checks(np.asarray(row, np.float64)[None], params.min_axis_px,
                            params.max_axis_diagonals * math.hypot(*SHAPE),
                            EQ2_CHECKED_RATIO_SQ)[2]
    return bool(ok[0])


def _ulps(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.int64]:
    """Distance in float32 steps between the float32 values of ``a`` and ``b``."""
    ia = np.asarray(a, np.float32).view(np.int32).astype(np.int64)
    ib = np.asarray(b, np.float32).view(np.int32).astype(np.int64)
    return np.abs(ia - ib)


@pytest.mark.parametrize("dtype", [np.int32, np.float32, np.float64])
def test_fits_are_opencvs_rows_on_random_arcs(dtype: type) -> None:
    rng = np.random.default_rng(17)
    exact = total = 0
    for _ in range(600):
        points = _random_arc(rng)
        points = np.round(points).astype(dtype) if dtype == np.int32 else points.astype(dtype)
        if _degenerate(points):  # the verdict on those is tested below
            continue
        total += 1
        got, want = kernels_fit.direct_fit(points), _opencv_row(points)
        assert got.dtype == np.float64 and np.array_equal(got, got.astype(np.float32))
        # w <= h, the angle in [0, 180]: OpenCV's convention.
        assert got[2] <= got[3] and 0.0 <= got[4] <= 180.0
        steps = _ulps(got, want)
        if want[2] == want[3]:  # a circle to float32 precision: no axis to give a direction
            steps[4] = 0
        assert steps.max() <= 4, (points.tolist(), got, want)
        exact += bool(np.array_equal(got, want))
    # Float64 arithmetic rounded to float32 as OpenCV's fields are: the same rows, bar a
    # float32 step where a value lies at a rounding boundary.
    assert exact >= 0.99 * total


def test_fit_ellipse_is_the_ellipse_of_opencvs_fit() -> None:
    rng = np.random.default_rng(5)
    for _ in range(300):
        points = np.round(_random_arc(rng)).astype(np.int32)
        if _degenerate(points):
            continue
        got = fit_ellipse(points)
        params = FitParams()
        want = kernels.fit_checks(_opencv_row(points)[None], params.min_axis_px, 1e9,
                                  EQ2_CHECKED_RATIO_SQ)
        assert got is not None
        assert [got.cx, got.cy, got.a, got.b] == pytest.approx(want[0][0, :4].tolist(),
                                                               rel=1e-6)
        assert got.angle_deg == pytest.approx(want[1][0], abs=1e-4) or got.a == got.b


@pytest.mark.parametrize("span", [2 * np.pi, np.pi, 0.5 * np.pi])
def test_known_ellipses_are_recovered(span: float) -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        cx, cy = rng.uniform(20, 300), rng.uniform(20, 220)
        a = rng.uniform(10, 120)
        b, angle = a * rng.uniform(0.2, 0.9), rng.uniform(0, 180)
        t = np.linspace(0.0, span, 60) + rng.uniform(0, 2 * np.pi)
        r = math.radians(angle)
        x, y = a * np.cos(t), b * np.sin(t)
        points = np.column_stack([cx + x * math.cos(r) - y * math.sin(r),
                                  cy + x * math.sin(r) + y * math.cos(r)])
        e = fit_ellipse(points)
        assert e is not None
        assert [e.cx, e.cy, e.a, e.b] == pytest.approx([cx, cy, a, b], abs=1e-3)
        assert (e.angle_deg - angle + 90.0) % 180.0 - 90.0 == pytest.approx(0.0, abs=1e-3)


def test_batched_rows_are_the_single_fits() -> None:
    rng = np.random.default_rng(11)
    pieces = [np.round(_random_arc(rng)).astype(np.int32) for _ in range(40)]
    sizes = np.array([p.shape[0] for p in pieces])
    stops = np.cumsum(sizes)
    rows = kernels_fit.direct_rows(np.concatenate(pieces), stops - sizes, stops)
    assert rows.tolist() == [kernels_fit.direct_fit(p).tolist() for p in pieces]


def test_input_types_read_as_float32() -> None:
    rng = np.random.default_rng(2)
    for _ in range(50):
        pixels = np.round(_random_arc(rng)).astype(np.int32)
        if _degenerate(pixels):
            continue
        want = kernels_fit.direct_fit(pixels).tolist()
        assert kernels_fit.direct_fit(pixels.astype(np.float32)).tolist() == want
        assert kernels_fit.direct_fit(pixels.astype(np.float64)).tolist() == want
        # fit_ellipse's other types and layouts: converted, the same fit.
        assert fit_ellipse(pixels.astype(np.int64)) == fit_ellipse(pixels)
        assert fit_ellipse(np.asfortranarray(pixels)) == fit_ellipse(pixels)
    points = _arc(rng, 40.0, 25.0, 80, np.pi, 0.3)
    assert (kernels_fit.direct_fit(points).tolist()
            == kernels_fit.direct_fit(points.astype(np.float32)).tolist())


def _lines(rng: np.random.Generator, kind: str) -> NDArray:
    """A degenerate point set of ``kind``: points on a line (float, with or without jitter far
    below a pixel, or rounded to pixels), pixels of two parallel rows or columns,
    coincident points."""
    n = int(rng.integers(5, 120))
    if kind == "coincident":
        return np.repeat(rng.uniform(0, 300, (1, 2)), n, axis=0).astype(np.float32)
    if kind == "two rows":
        u = rng.permutation(np.arange(n) + int(rng.integers(0, 200)))
        rows = np.column_stack([u, int(rng.integers(0, 230)) + (u % 2)]).astype(np.int32)
        return rows if rng.random() < 0.5 else rows[:, ::-1].copy()
    ang = rng.uniform(0, np.pi)
    t = np.arange(n) * rng.uniform(0.5, 1.5)
    line = rng.uniform(20, 220, 2) + t[:, None] * np.array([math.cos(ang), math.sin(ang)])
    if kind == "pixels":
        return np.round(line).astype(np.int32)
    if kind == "jitter":
        line = line + rng.normal(0.0, 1e-3, line.shape)
    return line.astype(np.float32)


@pytest.mark.parametrize("kind", ["coincident", "two rows", "pixels", "jitter", "exact"])
def test_degenerate_inputs_get_opencvs_verdict(kind: str) -> None:
    rng = np.random.default_rng(23)
    for _ in range(300):
        points = _lines(rng, kind)
        if len(np.unique(points, axis=0)) < 5 and kind != "coincident":
            continue  # fewer than five distinct points: no unique conic, any fit is arbitrary
        got = kernels_fit.direct_fit(points)
        assert _accepted(got) == _accepted(_opencv_row(points)), points.tolist()
        ellipse = fit_ellipse(points)
        assert ellipse is None or not plausible(ellipse, SHAPE)


def test_coincident_and_too_few_points_give_no_axes() -> None:
    same = np.full((8, 2), (12.5, 40.0), np.float32)
    assert kernels_fit.direct_fit(same).tolist() == _opencv_row(same).tolist()
    assert kernels_fit.direct_fit(same[:4])[2:4].tolist() == [0.0, 0.0]
    assert fit_ellipse(same) is None and fit_ellipse(same[:4]) is None

"""The compiled passes of the top face's profile refit give the values of the array steps
they chain (bit-identical)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_refine
from stackpick_sim.vision.contrast import outline_columns, unit_circle
from stackpick_sim.vision.fitting import ellipse_distances
from stackpick_sim.vision.wall import column_median


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(17)


def _terms(e: Ellipse) -> np.ndarray:
    t = math.radians(e.angle_deg)
    return np.array([e.cx, e.cy, e.a, e.b, math.cos(t), math.sin(t)])


def _ellipses(rng: np.random.Generator, n: int) -> list[Ellipse]:
    """Random ellipses over an 80 x 60 image, some reaching beyond it."""
    out = []
    for _ in range(n):
        a = rng.uniform(4.0, 30.0)
        out.append(Ellipse.of(rng.uniform(-5, 85), rng.uniform(-5, 65), a,
                              a * rng.uniform(0.3, 1.0), rng.uniform(-180, 180)))
    return out


def test_outline_peaks_match_the_outline_then_the_peaks(rng: np.random.Generator) -> None:
    gx = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    gy = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    steps = np.arange(-2.0, 2.0 + 1e-9, 0.5)
    found = 0
    for e in _ellipses(rng, 30):
        pu, pv, nu, nv = outline_columns(e)
        ct, st = unit_circle(pu.shape[0])
        want = kernels.profile_peaks(gx, gy, pu, pv, nu, nv, steps, 0.5, 200.0)
        got = kernels_refine.outline_peaks(gx, gy, _terms(e), ct, st, steps, 0.5, 200.0)
        assert got.tobytes() == want.tobytes()
        found += want.shape[0]
    assert found > 0  # some samples pass the threshold, some do not


def test_profile_inliers_match_distances_median_and_mask(rng: np.random.Generator) -> None:
    kept_some = dropped_some = False
    for e in _ellipses(rng, 40):
        n = int(rng.integers(1, 200))
        t = rng.uniform(0, 2 * np.pi, n)
        r = 1.0 + rng.normal(0, 0.05, n) * (rng.uniform(size=n) < 0.8) + rng.normal(0, 0.3, n)
        th = math.radians(e.angle_deg)
        x, y = e.a * r * np.cos(t), e.b * r * np.sin(t)
        peaks = np.stack([e.cx + math.cos(th) * x - math.sin(th) * y,
                          e.cy + math.sin(th) * x + math.cos(th) * y], axis=1)
        for least, medians in ((0.3, 3.0), (5.0, 1.0)):
            d = ellipse_distances(e, peaks)
            mask = d <= max(least, medians * float(column_median(d)))
            got = kernels_refine.profile_inliers(peaks, _terms(e), least, medians)
            assert got.dtype == np.float32
            assert got.tobytes() == np.asarray(peaks[mask], np.float32).tobytes()
            kept_some |= 0 < got.shape[0] < n
            dropped_some |= got.shape[0] < n
    assert kept_some and dropped_some


def test_shift_rows_adds_the_offset_to_every_row(rng: np.random.Generator) -> None:
    rows = rng.integers(-500, 500, (40, 2)).astype(np.int32)
    want = rows + np.array([7, -3], np.int32)
    kernels_refine.shift_rows(rows, 7, -3)
    assert rows.dtype == np.int32 and rows.tobytes() == want.tobytes()


def test_subpixel_along_rows_is_subpixel_along_of_the_columns(rng: np.random.Generator) -> None:
    gx = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    gy = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    points = np.stack([rng.uniform(0, 79, 500), rng.uniform(0, 59, 500)])
    angle = rng.uniform(0, 2 * np.pi, 500)
    grads = np.stack([np.cos(angle), np.sin(angle)])
    kept = 0
    for e in _ellipses(rng, 20):
        t = math.radians(e.angle_deg)
        c, s = math.cos(t), math.sin(t)
        ia, ib = 1.0 / (e.a * e.a), 1.0 / (e.b * e.b)
        form = (e.cx, e.cy, c * c * ia + s * s * ib, c * s * (ia - ib), s * s * ia + c * c * ib)
        want = kernels.subpixel_along(points[0].copy(), points[1].copy(), grads[0].copy(),
                                      grads[1].copy(), np.array(form), e.a + 2.2, 5.76, 0.5,
                                      gx, gy, 0.5)
        got = kernels_refine.subpixel_along_rows(points, grads, *form, e.a + 2.2, 5.76, 0.5,
                                                 gx, gy, 0.5)
        assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
        kept += got.shape[0]
    assert kept > 0

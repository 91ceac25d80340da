"""The compiled kernels give bit-identical results to the numpy expressions they stand for."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from stackpick_sim.vision import kernels


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def _bilinear_numpy(gx: NDArray[np.int16], gy: NDArray[np.int16], u: NDArray[np.float64],
                    v: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    h, w = gx.shape
    u = np.minimum(np.maximum(u, 0.0), w - 1.001)
    v = np.minimum(np.maximum(v, 0.0), h - 1.001)
    u0, v0 = u.astype(np.int64), v.astype(np.int64)
    fu, fv = u - u0, v - v0
    i00 = v0 * w + u0
    i01 = i00 + w
    gu, gv = 1 - fu, 1 - fv
    w00, w10, w01, w11 = gu * gv, fu * gv, gu * fv, fu * fv
    return [img.ravel()[i00] * w00 + img.ravel()[i00 + 1] * w10 + img.ravel()[i01] * w01
            + img.ravel()[i01 + 1] * w11 for img in (gx, gy)]


def _gradients(rng: np.random.Generator) -> tuple[NDArray[np.int16], NDArray[np.int16]]:
    return (rng.integers(-2000, 2000, (60, 80)).astype(np.int16),
            rng.integers(-2000, 2000, (60, 80)).astype(np.int16))


def test_bilinear_matches_numpy_including_clamped_points(rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    u, v = rng.uniform(-5, 90, 3000), rng.uniform(-5, 70, 3000)
    got = kernels.bilinear_uv(gx, gy, u, v)
    for a, b in zip(got, _bilinear_numpy(gx, gy, u, v), strict=True):
        assert np.array_equal(a, b)


def test_subpixel_matches_numpy(rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    u, v = rng.uniform(0, 79, 3000), rng.uniform(0, 59, 3000)
    t = rng.uniform(0, 2 * np.pi, 3000)
    gu, gv = np.cos(t), np.sin(t)
    steps = np.array([-1.0, 0.0, 1.0])[:, None]
    mags = np.hypot(*_bilinear_numpy(gx, gy, (u + steps * gu).ravel(),
                                     (v + steps * gv).ravel()))
    before, centre, after = mags.reshape(3, -1)
    curvature = before - 2.0 * centre + after
    ok = curvature < -1e-9
    shift = np.where(ok, 0.5 * (before - after) / np.where(ok, curvature, -1.0), 0.0)
    shift = np.minimum(np.maximum(shift, -0.5), 0.5)
    su, sv = kernels.subpixel_columns(gx, gy, u, v, gu, gv, 0.5)
    assert np.array_equal(su, u + shift * gu)
    assert np.array_equal(sv, v + shift * gv)
    assert np.any(shift != 0.0)


def test_box_pairs_is_nonzero_of_the_box_test(rng: np.random.Generator) -> None:
    pu, pv = rng.uniform(0, 100, 500), rng.uniform(0, 100, 500)
    cx, cy, reach = rng.uniform(0, 100, 7), rng.uniform(0, 100, 7), rng.uniform(1, 30, 7)
    pe, pm = kernels.box_pairs(pu, pv, cx, cy, reach)
    want = np.nonzero((np.abs(pu - cx[:, None]) <= reach[:, None])
                      & (np.abs(pv - cy[:, None]) <= reach[:, None]))
    assert np.array_equal(pe, want[0]) and np.array_equal(pm, want[1])
    assert pe.size > 0


def test_grouped_distances_match_the_broadcast_form(rng: np.random.Generator) -> None:
    params = np.column_stack([rng.uniform(20, 80, 5), rng.uniform(20, 80, 5),
                              rng.uniform(10, 30, 5), rng.uniform(5, 10, 5),
                              rng.uniform(0, np.pi, 5)])
    counts = rng.integers(0, 200, 5)
    pu, pv = rng.uniform(0, 100, counts.sum()), rng.uniform(0, 100, counts.sum())
    rows = np.empty((6, 5))
    rows[:4] = params[:, :4].T
    rows[4], rows[5] = np.cos(params[:, 4]), np.sin(params[:, 4])
    cx, cy, a, b, c, s = rows.repeat(counts, axis=1)
    du, dv = pu - cx, pv - cy
    x = (c * du + s * dv) / a
    y = (c * dv - s * du) / b
    want = np.abs(x * x + y * y - 1.0) / (2.0 * np.sqrt((x / a) ** 2 + (y / b) ** 2) + 1e-12)
    assert np.array_equal(kernels.grouped_distances(rows, counts.astype(np.int64), pu, pv), want)


def test_along_grouped_matches_the_array_test(rng: np.random.Generator) -> None:
    forms = np.column_stack([rng.uniform(20, 80, 4), rng.uniform(20, 80, 4),
                             rng.uniform(1e-3, 1e-2, 4), rng.uniform(-1e-3, 1e-3, 4),
                             rng.uniform(1e-3, 1e-2, 4)])
    counts = rng.integers(50, 300, 4).astype(np.int64)
    n = int(counts.sum())
    u, v = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
    t = rng.uniform(0, 2 * np.pi, n)
    gu, gv = np.cos(t), np.sin(t)
    cx, cy, fa, fh, fb = forms.T.repeat(counts, axis=1)
    du, dv = u - cx, v - cy
    nu, nv = fa * du + fh * dv, fb * dv + fh * du
    f = du * nu + dv * nv - 1.0
    n2 = nu * nu + nv * nv
    dot = nu * gu + nv * gv
    want = (f * f < 4.0 * 2.0 * 2.0 * n2) & (dot * dot >= 0.87 * 0.87 * n2)
    got = kernels.along_grouped(forms, counts, u, v, gu, gv, 4.0 * 2.0 * 2.0, 0.87 * 0.87)
    assert np.array_equal(got, want)

"""The compiled kernels give bit-identical results to the numpy expressions they stand for."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from unittest import mock

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams, RoiParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_fit
from stackpick_sim.vision.fitting import (
    EQ2_CHECKED_RATIO_SQ,
    distance_rows,
    ellipse_params,
    fit_ellipse,
    grouped_distances,
    plausible,
)
from stackpick_sim.vision.refine import _form
from stackpick_sim.vision.roi import Roi, decimate, find_roi


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


def test_box_runs_are_the_box_pairs_points_and_their_bounds(rng: np.random.Generator) -> None:
    pu, pv = rng.uniform(0, 100, 500), rng.uniform(0, 100, 500)
    cx, cy = rng.uniform(0, 100, 6), rng.uniform(0, 100, 6)
    reach = rng.uniform(0, 30, 6)
    reach[2] = 0.0  # an ellipse with no point in its box
    for rows in (pv, np.sort(np.rint(pv))):  # scattered, then in rows as the edge pixels
        pe, pm = kernels.box_pairs(pu, rows, cx, cy, reach)
        at, starts = kernels.box_runs(pu, rows, cx, cy, reach)
        assert np.array_equal(at, pm)
        assert np.array_equal(starts, np.searchsorted(pe, np.arange(7)))


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


def _along_want(forms: NDArray[np.float64], counts: NDArray[np.int64], u: NDArray[np.float64],
                v: NDArray[np.float64], gu: NDArray[np.float64], gv: NDArray[np.float64],
                dist_sq: float, cos_sq: float) -> NDArray[np.bool_]:
    """The along-the-outline test in array form: pixels (u, v) with unit gradients (gu, gv)
    running ellipse by ellipse, ``counts[e]`` against row e of ``forms`` (cx, cy, A, H, B)."""
    cx, cy, fa, fh, fb = forms.T.repeat(counts, axis=1)
    du, dv = u - cx, v - cy
    nu, nv = fa * du + fh * dv, fb * dv + fh * du
    f = du * nu + dv * nv - 1.0
    n2 = nu * nu + nv * nv
    dot = nu * gu + nv * gv
    return np.asarray((f * f < dist_sq * n2) & (dot * dot >= cos_sq * n2))


def _ellipse_rows(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """(6, n) rows cx, cy, a, b, cos, sin of random ellipses in a 100 px square."""
    t = rng.uniform(0, np.pi, n)
    a = rng.uniform(8, 40, n)
    return np.vstack([rng.uniform(0, 100, n), rng.uniform(0, 100, n), a,
                      a * rng.uniform(0.3, 1.0, n), np.cos(t), np.sin(t)])


def _near_pairs(pu: np.ndarray, pv: np.ndarray, rows: np.ndarray, reach: np.ndarray,
                tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The (ellipse, point) pairs of every point: near_pairs_split with none split off."""
    pe, pm, _, _ = kernels.near_pairs_split(pu, pv, rows, reach, tol, pu.shape[0])
    return pe, pm


def _bows(pixels: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The bow of each piece of ``pixels`` (``counts[i]`` pixels each, one after another)."""
    ends = np.cumsum(counts)
    return np.array([kernels._bow(pixels, int(e - n), int(e)) for e, n in zip(ends, counts,
                                                                             strict=True)])


def test_near_pairs_are_the_box_pairs_closer_than_the_tolerance(
        rng: np.random.Generator) -> None:
    rows = _ellipse_rows(rng, 6)
    # Points scattered near the outlines too, so that both sides of the tolerance occur.
    t = rng.uniform(0, 2 * np.pi, 3000)
    e = rng.integers(0, 6, 3000)
    x, y = rows[2, e] * np.cos(t), rows[3, e] * np.sin(t)
    pu = np.rint(rows[0, e] + rows[4, e] * x - rows[5, e] * y + rng.normal(0, 1.5, 3000))
    pv = np.rint(rows[1, e] + rows[5, e] * x + rows[4, e] * y + rng.normal(0, 1.5, 3000))
    reach = rows[2] + 1.5 + 1.0
    be, bm = kernels.box_pairs(pu, pv, rows[0].copy(), rows[1].copy(), reach)
    d = kernels.grouped_distances(rows, np.bincount(be, minlength=6).astype(np.int64),
                                  pu[bm], pv[bm])
    close = d < 1.5
    got = _near_pairs(pu, pv, rows, reach, 1.5)
    assert np.array_equal(got[0], be[close]) and np.array_equal(got[1], bm[close])
    assert 0 < close.sum() < close.size
    first = got[1] < 1200
    split = kernels.near_pairs_split(pu, pv, rows, reach, 1.5, 1200)
    for a, b in zip(split, (got[0][first], got[1][first], got[0][~first], got[1][~first]),
                    strict=True):
        assert np.array_equal(a, b)


def test_near_pairs_decide_points_at_the_tolerance_as_the_distance_does(
        rng: np.random.Generator) -> None:
    # Points placed at Sampson distances within 1e-9 to 1e-3 of the tolerance (inside and
    # outside the outlines), and at the centres: the screen's undecided band and its edges.
    rows = _ellipse_rows(rng, 5)
    tol = 1.5
    pu_all, pv_all = [], []
    for e in range(5):
        cx, cy, a, b, c, s = rows[:, e]
        t = rng.uniform(0, 2 * np.pi, 200)
        x, y = a * np.cos(t), b * np.sin(t)
        nu, nv = b * np.cos(t), a * np.sin(t)  # the outward normal, in the ellipse's frame
        norm = np.hypot(nu, nv)
        for side in (-1.0, 1.0):
            lo, hi = np.zeros(200), np.full(200, 3.0 * tol)
            for _ in range(60):  # bisect the offset to the tolerance's distance
                mid = 0.5 * (lo + hi)
                u = cx + c * (x + side * mid * nu / norm) - s * (y + side * mid * nv / norm)
                v = cy + s * (x + side * mid * nu / norm) + c * (y + side * mid * nv / norm)
                d = kernels.point_distances(np.column_stack([u, v]), cx, cy, a, b, c, s)
                lo, hi = np.where(d < tol, mid, lo), np.where(d < tol, hi, mid)
            for f in (1 - 1e-3, 1 - 1e-7, 1 - 1e-9, 1.0, 1 + 1e-9, 1 + 1e-7, 1 + 1e-3):
                m = lo * f
                pu_all.append(cx + c * (x + side * m * nu / norm) - s * (y + side * m * nv / norm))
                pv_all.append(cy + s * (x + side * m * nu / norm) + c * (y + side * m * nv / norm))
        pu_all.append(np.array([cx]))
        pv_all.append(np.array([cy]))
    pu, pv = np.concatenate(pu_all), np.concatenate(pv_all)
    reach = rows[2] + tol + 1.0
    be, bm = kernels.box_pairs(pu, pv, rows[0].copy(), rows[1].copy(), reach)
    d = kernels.grouped_distances(rows, np.bincount(be, minlength=5).astype(np.int64),
                                  pu[bm], pv[bm])
    close = d < tol
    got = _near_pairs(pu, pv, rows, reach, tol)
    assert np.array_equal(got[0], be[close]) and np.array_equal(got[1], bm[close])
    assert 5 * 2 * 200 * 3 <= close.sum() < close.size  # the three inner offsets at least


def test_bows_match_the_per_piece_sums(rng: np.random.Generator) -> None:
    counts = rng.integers(10, 120, 9).astype(np.int64)
    pixels = rng.integers(0, 300, (int(counts.sum()), 2)).astype(np.float64)
    # The array form: per-piece sums in pixel order (np.bincount's), then the smallest
    # eigenvalue of the 2x2 scatter.
    which = np.arange(counts.size).repeat(counts)
    mu = (np.bincount(which, weights=pixels[:, 0]) / counts).repeat(counts)
    mv = (np.bincount(which, weights=pixels[:, 1]) / counts).repeat(counts)
    cu, cv = pixels[:, 0] - mu, pixels[:, 1] - mv
    sxx, syy, sxy = (np.bincount(which, weights=w) for w in (cu * cu, cv * cv, cu * cv))
    half, det = 0.5 * (sxx + syy) / counts, (sxx * syy - sxy * sxy) / (counts * counts)
    want = np.sqrt(np.maximum(0.0, half - np.sqrt(np.maximum(0.0, half * half - det))))
    got = _bows(pixels, counts)
    assert np.array_equal(got, want)
    # And a straight run has none.
    line = np.column_stack([np.arange(20.0), 2.0 * np.arange(20.0)])
    assert _bows(line, np.array([20], np.int64))[0] < 1e-6


def test_outline_support_is_the_lookup_of_the_rounded_samples(
        rng: np.random.Generator) -> None:
    support = (rng.uniform(0, 1, (70, 90)) < 0.4).astype(np.uint8)
    rows = _ellipse_rows(rng, 5).T.copy()  # ellipses reaching off the map too
    counts = rng.integers(16, 200, 5).astype(np.int64)
    t = np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False) for n in counts])
    ct, st = np.cos(t), np.sin(t)
    cx, cy, a, b, c, s = rows.T.repeat(counts, axis=1)
    x, y = a * ct, b * st
    u, v = np.rint(c * x + cx - s * y), np.rint(s * x + cy + c * y)
    inside = (u >= 0) & (u < 90) & (v >= 0) & (v < 70)
    hit = np.zeros(u.size, bool)
    hit[inside] = support[v[inside].astype(int), u[inside].astype(int)] > 0
    want = np.bincount(np.arange(5).repeat(counts), weights=hit) / counts
    got = kernels.outline_support(support, rows, counts, ct, st, 0)
    assert np.array_equal(got, want)
    assert not inside.all()
    # Within a radius of the (sparser) map's set pixels: the lookup in its dilation.
    sparse = (rng.uniform(0, 1, (70, 90)) < 0.05).astype(np.uint8)
    dilated = cv2.dilate(sparse, np.ones((3, 3), np.uint8))
    assert np.array_equal(kernels.outline_support(sparse, rows, counts, ct, st, 1),
                          kernels.outline_support(dilated, rows, counts, ct, st, 0))


def test_outline_support_of_dense_samples_matches_the_dilated_lookup(
        rng: np.random.Generator) -> None:
    # Several samples a pixel (each rounds to the pixel of the one before it) on a 0/255 map,
    # outlines crossing its border: radius 1 is the lookup in the 3x3 dilation, radius 2 in
    # the 5x5 one.
    edges = np.where(rng.uniform(0, 1, (60, 80)) < 0.04, 255, 0).astype(np.uint8)
    rows = _ellipse_rows(rng, 6).T.copy()
    counts = rng.integers(400, 900, 6).astype(np.int64)
    t = np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False) for n in counts])
    ct, st = np.cos(t), np.sin(t)
    for radius in (1, 2):
        dilated = cv2.dilate(edges, np.ones((2 * radius + 1,) * 2, np.uint8))
        want = kernels.outline_support(dilated, rows, counts, ct, st, 0)
        assert np.array_equal(kernels.outline_support(edges, rows, counts, ct, st, radius),
                              want)
        assert ((0.0 < want) & (want < 1.0)).any()


def test_subpixel_along_is_the_along_test_then_the_subpixel_move(
        rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    cx, cy, a, b, th = 40.0, 30.0, 20.0, 12.0, 0.4
    c, s = np.cos(th), np.sin(th)
    form = np.array([cx, cy, c * c / a**2 + s * s / b**2, c * s * (1 / a**2 - 1 / b**2),
                     s * s / a**2 + c * c / b**2])
    t = rng.uniform(0, 2 * np.pi, 4000)
    pu = np.rint(cx + c * a * np.cos(t) - s * b * np.sin(t) + rng.normal(0, 2, 4000))
    pv = np.rint(cy + s * a * np.cos(t) + c * b * np.sin(t) + rng.normal(0, 2, 4000))
    g = rng.uniform(0, 2 * np.pi, 4000)
    gu, gv = np.cos(g), np.sin(g)
    reach = a + 1.2 + 1
    near = (np.abs(pu - cx) <= reach) & (np.abs(pv - cy) <= reach)
    du, dv = pu - cx, pv - cy
    nu, nv = form[2] * du + form[3] * dv, form[4] * dv + form[3] * du
    f = du * nu + dv * nv - 1.0
    n2 = nu * nu + nv * nv
    dot = nu * gu + nv * gv
    keep = near & (f * f < 4 * 1.2 * 1.2 * n2) & (dot * dot >= 0.87 * 0.87 * n2)
    su, sv = kernels.subpixel_columns(gx, gy, pu[keep], pv[keep], gu[keep], gv[keep], 0.5)
    got = kernels.subpixel_along(pu, pv, gu, gv, form, reach, 4 * 1.2 * 1.2, 0.87 * 0.87,
                                 gx, gy, 0.5)
    assert got.dtype == np.float32 and 0 < got.shape[0] < near.sum()
    assert np.array_equal(got, np.column_stack([su, sv]).astype(np.float32))


def test_profile_peaks_match_the_grid_form(rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    n = 300
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pu, pv = 40 + 25 * np.cos(t), 30 + 20 * np.sin(t)
    nu, nv = np.cos(t), np.sin(t)
    steps = np.arange(-2.0, 2.0 + 1e-9, 0.5)
    k = steps.size
    qu = pu[:, None] + steps * nu[:, None]
    qv = pv[:, None] + steps * nv[:, None]
    bx, by = _bilinear_numpy(gx, gy, qu.ravel(), qv.ravel())
    g = np.abs(bx.reshape(n, k) * nu[:, None] + by.reshape(n, k) * nv[:, None])
    best = g[:, 1:-1].argmax(axis=1) + 1
    rows = np.arange(n)
    before, centre, after = g[rows, best - 1], g[rows, best], g[rows, best + 1]
    curvature = before - 2.0 * centre + after
    peaked = curvature < -1e-9
    shift = np.where(peaked, 0.5 * (before - after) / np.where(peaked, curvature, -1.0), 0.0)
    threshold = float(np.median(centre))
    ok = centre >= threshold
    offset = steps[best] + np.minimum(np.maximum(shift, -0.5), 0.5) * 0.5
    want = np.column_stack([(pu + offset * nu)[ok], (pv + offset * nv)[ok]])
    got = kernels.profile_peaks(gx, gy, pu, pv, nu, nv, steps, 0.5, threshold)
    assert 0 < got.shape[0] < n
    assert np.array_equal(got, want)


#: Run in a fresh interpreter: warm the kernels, then detect on the pinned paper-scene frames
#: (colour and gray) and print every kernel that had to compile for a new argument type.
_COMPILES_AFTER_WARM_UP = r"""
import sys
from pathlib import Path
from numba.core.registry import CPUDispatcher
from stackpick_sim.config.loader import load_scene
from stackpick_sim.vision import (kernels, kernels_fit, kernels_pose, kernels_refine,
                                  kernels_top, under_wall)
from stackpick_sim.vision.benchmark.frames import load_frame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.detector import TopObjectDetector
kernels.warm_up()
compiled = {f"{m.__name__}.{n}": k
            for m in (kernels, kernels_top, kernels_pose, kernels_refine, kernels_fit,
                      under_wall)
            for n, k in vars(m).items() if isinstance(k, CPUDispatcher)}
warm = {n: set(k.signatures) for n, k in compiled.items()}
scene = load_scene("paper")
kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
              for t in scene.object_types.values())
folder = Path(sys.argv[1])
for png in sorted(folder.glob("*.png")):
    frame = load_frame(folder, int(png.stem), scene.conveyor.top_z,
                       scene.objects.max_face_height, kinds)
    detector = TopObjectDetector(detector_config(frame))
    detector.detect(frame.image_rgb)
    detector.detect(frame.image_rgb.mean(axis=2).astype("uint8"))
print(sorted(n for n, k in compiled.items() if set(k.signatures) - warm[n]))
"""


def test_warm_up_compiles_every_argument_type_the_detector_passes() -> None:
    # Every compiled pass of the kernel modules, on colour and grey frames.
    frames = Path(__file__).parent / "data" / "paper_dev_frames"
    out = subprocess.run([sys.executable, "-c", _COMPILES_AFTER_WARM_UP, str(frames)],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_outline_contrasts_match_the_gather_form(rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    sizes = [40, 75]
    t = np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False) for n in sizes])
    # The second outline runs off the image: its samples there read nothing.
    cx, cy = np.repeat([40.0, 70.0], sizes), np.repeat([30.0, 50.0], sizes)
    r = np.repeat([15.0, 20.0], sizes)
    pu, pv = cx + r * np.cos(t), cy + r * np.sin(t)
    nu, nv = np.cos(t), np.sin(t)
    half = 2
    shifts = np.array([0, *range(-half, 0), *range(1, half + 1)])
    window = np.concatenate([(np.arange(n) + shifts[:, None]) % n + start
                             for n, start in zip(sizes, [0, sizes[0]], strict=True)], axis=1)
    offsets = np.array([-1.0, 0.0, 1.0])
    g = []
    for o in offsets:
        u, v = np.rint(pu + o * nu).astype(int), np.rint(pv + o * nv).astype(int)
        inside = (u >= 0) & (u < 80) & (v >= 0) & (v < 60)
        uc, vc = np.clip(u, 0, 79), np.clip(v, 0, 59)
        g.append(np.where(inside, gx[vc, uc] * nu + gy[vc, uc] * nv, 0.0))
    mags = np.abs(g)
    best = np.take_along_axis(np.array(g), mags.argmax(axis=0)[None], axis=0)[0]
    want = np.abs(best[window].sum(axis=0) / window.shape[0]) / 8.0
    got = kernels.outline_contrasts(pu, pv, nu, nv, gx, gy, offsets, window, 8.0)
    assert np.array_equal(got, want)


def test_band_hits_match_the_array_tests(rng: np.random.Generator) -> None:
    image = rng.integers(0, 256, (50, 60, 3)).astype(np.uint8)
    image[10:30, 10:40] = (120, 40, 30)  # a wall of the face's hue
    pu, pv = rng.uniform(-5, 65, (2, 300)), rng.uniform(-5, 55, (2, 300))
    keep = rng.uniform(0, 1, (2, 300)) < 0.8
    colours = np.array([[200.0, 66.0, 50.0], [90.0, 90.0, 95.0]])
    tans = np.array([1.5, 0.4])
    belt = np.array([30.0, 32.0, 35.0])
    qu, qv = np.rint(pu), np.rint(pv)
    take = keep & (qu >= 0) & (qu < 60) & (qv >= 0) & (qv < 50)
    owner = np.nonzero(take)[0]
    cols = image[qv[take].astype(int), qu[take].astype(int)].astype(np.float64)
    face = np.maximum(colours.sum(axis=1), 1.0)
    sums = cols.sum(axis=1)
    chroma = np.abs(cols / np.maximum(sums, 1.0)[:, None] - (colours / face[:, None])[owner])
    ok = ((chroma.sum(axis=1) <= 0.12) & (sums >= 0.12 * face[owner])
          & (sums <= ((tans + 0.3) * face)[owner])
          & (np.abs(cols - belt).max(axis=1) > 14.0))
    counts, hits = kernels.band_hits(pu, pv, keep, image, colours, tans + 0.3, belt, True,
                                     0.12, 0.12, 14.0)
    assert np.array_equal(counts, np.bincount(owner, minlength=2))
    assert np.array_equal(hits, np.bincount(owner, weights=ok, minlength=2))
    assert hits[0] > 0


def _corner_cuts_python(chain: NDArray[np.int32], poly: NDArray[np.int32], closed: bool
                        ) -> list[int]:
    """The turn rule of segments.split_chain on Python floats, vertex by vertex."""
    pl = poly.tolist()
    verts = [pl[-1], *pl, pl[0]] if closed else pl
    count = len(pl) if closed else len(pl) - 2
    mag, sign = [], []
    for (qx, qy), (rx, ry), (sx, sy) in zip(verts, verts[1:], verts[2:], strict=False):
        x0, y0, x1, y1 = rx - qx, ry - qy, sx - rx, sy - ry
        t = math.degrees(math.atan2(x0 * y1 - y0 * x1, x0 * x1 + y0 * y1))
        mag.append(abs(t))
        sign.append(0 if abs(t) < 4.0 else (1 if t > 0 else -1))
    at, last = [], 0
    for k in range(count):
        if closed:
            before, after = mag[k - 1], mag[(k + 1) % count]
        else:
            before = mag[k - 1] if k else 0.0
            after = mag[k + 1] if k + 1 < count else 0.0
        cut = mag[k] > 80.0 or (mag[k] > 30.0 and mag[k] > 2.0 * max(before, after))
        if sign[k]:
            cut = cut or (last != 0 and sign[k] != last)
            last = sign[k]
        if cut:
            at.append(k if closed else k + 1)
    return sorted({next(i for i, p in enumerate(chain.tolist()) if p == pl[a]) for a in at})


@pytest.mark.parametrize("closed", [False, True])
def test_corner_cuts_match_the_turn_rule_vertex_by_vertex(rng: np.random.Generator,
                                                           closed: bool) -> None:
    cut_any = 0
    for _ in range(200):
        # Random walks of a few straight runs: corners, spikes, sign flips and none.
        steps = rng.integers(-1, 2, (int(rng.integers(3, 8)), 2))
        steps[(steps == 0).all(axis=1)] = (1, 0)
        runs = rng.integers(2, 12, steps.shape[0])
        chain = np.cumsum(np.repeat(steps, runs, axis=0), axis=0).astype(np.int32) + 50
        poly = np.asarray(cv2.approxPolyDP(chain.reshape(-1, 1, 2), 1.0, closed).reshape(-1, 2),
                          np.int32)
        if poly.shape[0] < 3:
            continue
        got = kernels.corner_cuts(chain, poly, closed, 80.0, 30.0, 2.0, 4.0).tolist()
        assert got == _corner_cuts_python(chain, poly, closed)
        cut_any += bool(got)
    assert cut_any > 20


def test_outline_near_shares_match_the_grouped_distances(rng: np.random.Generator) -> None:
    rows = _ellipse_rows(rng, 4).T.copy()
    # Each other ellipse a near copy of the first: shares between 0 and 1.
    others = rows.T.copy()
    others[:2] += rng.normal(0, 1.0, (2, 4))
    counts = rng.integers(16, 150, 4).astype(np.int64)
    t = np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False) for n in counts])
    ct, st = np.cos(t), np.sin(t)
    cx, cy, a, b, c, s = rows.T.repeat(counts, axis=1)
    x, y = a * ct, b * st
    d = kernels.grouped_distances(others, counts, cx + c * x - s * y, cy + s * x + c * y)
    want = np.bincount(np.arange(4).repeat(counts), weights=d < 1.0) / counts
    got = kernels.outline_near_shares(rows, counts, ct, st, others, 1.0)
    assert np.array_equal(got, want)
    assert np.any((got > 0) & (got < 1))


def test_interior_counts_match_the_row_intervals(rng: np.random.Generator) -> None:
    keys_uv = np.unique(rng.integers(0, 100, (1500, 2)), axis=0)
    width = 102
    keys = np.sort(keys_uv[:, 1] * width + keys_uv[:, 0]).astype(np.float64)
    params, sizes = [], []
    for _ in range(5):
        cx, cy, a = rng.uniform(0, 100), rng.uniform(0, 100), rng.uniform(3, 40)
        b, t = a * rng.uniform(0.3, 1.0), rng.uniform(0, np.pi)
        c, s, ia, ib = np.cos(t), np.sin(t), 1 / a**2, 1 / b**2
        p, q, r = c * c * ia + s * s * ib, 2 * c * s * (ia - ib), s * s * ia + c * c * ib
        half = np.sqrt(p / (p * r - 0.25 * q * q))
        first = np.ceil(cy - half)
        params.append((cx, cy, p, q, r, first))
        sizes.append(int(max(0, np.floor(cy + half) - first + 1)))
    want = []
    for (cx, cy, p, q, r, first), n in zip(params, sizes, strict=True):
        row = first + np.arange(n)
        dv = row - cy
        qdv = q * dv
        disc = qdv * qdv - 4.0 * p * (r * dv * dv - 1.0)
        root = np.sqrt(np.maximum(disc, 0.0))
        lo = np.maximum((-qdv - root) / (2.0 * p) + cx, -0.5)
        hi = np.minimum((-qdv + root) / (2.0 * p) + cx, width - 1.5)
        hi = np.where(disc > 0.0, np.maximum(hi, lo), lo)
        inside = (keys.searchsorted(row * width + hi)
                  - keys.searchsorted(row * width + lo, side="right"))
        want.append(int(np.maximum(inside, 0).sum()))
    got = kernels.interior_counts(np.array(params), np.array(sizes, np.int64), keys, width)
    assert got.tolist() == want
    assert sum(want) > 0


def test_outline_samples_match_the_array_form(rng: np.random.Generator) -> None:
    rows = _ellipse_rows(rng, 5).T.copy()
    counts = rng.integers(16, 150, 5).astype(np.int64)
    t = np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False) for n in counts])
    ct, st = np.cos(t), np.sin(t)
    cx, cy, a, b, c, s = rows.T.repeat(counts, axis=1)
    x, y = a * ct, b * st
    nx, ny = b * ct, a * st
    norm = np.hypot(nx, ny)
    nx, ny = nx / norm, ny / norm
    pts, normals = kernels.outline_samples(rows, counts, ct, st)
    assert np.array_equal(pts, [cx + c * x - s * y, cy + s * x + c * y])
    assert np.array_equal(normals, [c * nx - s * ny, s * nx + c * ny])


def test_a_division_by_zero_gives_numpys_values_not_an_error() -> None:
    # A degenerate ellipse (zero axes): the array forms give NaN, so do the kernels.
    pts, normals = kernels.outline_samples(np.zeros((1, 6)), np.array([4], np.int64),
                                           np.ones(4), np.zeros(4))
    assert np.isnan(normals).all() and np.array_equal(pts, np.zeros((2, 4)))


def test_along_select_is_the_along_test_of_the_active_ellipses(
        rng: np.random.Generator) -> None:
    forms = np.column_stack([rng.uniform(20, 80, 4), rng.uniform(20, 80, 4),
                             rng.uniform(1e-3, 1e-2, 4), rng.uniform(-1e-3, 1e-3, 4),
                             rng.uniform(1e-3, 1e-2, 4)])
    counts = rng.integers(50, 300, 4).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = int(counts.sum())
    u, v = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
    t = rng.uniform(0, 2 * np.pi, n)
    gu, gv = np.cos(t), np.sin(t)
    active = np.array([True, False, True, True])
    passed = _along_want(forms, counts, u, v, gu, gv, 16.0, 0.87 * 0.87)
    passed &= active.repeat(counts)
    # The pairs given through a pair -> pixel index (here a permutation of the pixels).
    at = rng.permutation(n).astype(np.int64)
    back = np.argsort(at)
    sel, bounds, pts = kernels.along_select(forms, starts, active, at, u[back], v[back],
                                            gu[back], gv[back], 16.0, 0.87 * 0.87)
    assert np.array_equal(sel, passed.nonzero()[0])
    assert np.array_equal(pts, np.column_stack([u, v])[sel].astype(np.float32))
    owner = np.arange(4).repeat(counts)[sel]
    assert np.array_equal(bounds, np.searchsorted(owner, np.arange(5)))
    assert bounds[2] == bounds[1] and sel.size > 0


def test_junction_ends_match_the_pair_form(rng: np.random.Generator) -> None:
    # Edge pixels in row-major order, some on the two ellipses, some crossing them.
    uv = np.unique(rng.integers(0, 100, (150, 2)), axis=0)  # (v, u), sorted by row v
    pu, pv = uv[:, 1].astype(np.float64), uv[:, 0].astype(np.float64)
    params = np.array([[50.0, 50.0, 1.0, 0.0, 20.0, 12.0, 18.5, 10.5],
                       [30.0, 60.0, 0.6, 0.8, 15.0, 9.0, 13.5, 7.5]])
    t = rng.uniform(0, 2 * np.pi, 12)
    owner = rng.integers(0, 2, 12).astype(np.int64)
    cx, cy, c, s, a, b = params[owner, :6].T
    ends = np.column_stack([cx + c * a * np.cos(t) - s * b * np.sin(t),
                            cy + s * a * np.cos(t) + c * b * np.sin(t)])
    # The array form: every (end, pixel) pair of the rows within reach.
    end_k, at = np.nonzero(np.abs(pv[None, :] - ends[:, 1:2]) <= 6.0)
    d2 = (pu[at] - ends[end_k, 0]) ** 2 + (pv[at] - ends[end_k, 1]) ** 2
    near = d2 <= 36.0
    end_k, at, d2 = end_k[near], at[near], d2[near]
    cx, cy, c, s, a, b, a_in, b_in = params[owner[end_k]].T
    du, dv = pu[at] - cx, pv[at] - cy
    xr, yr = c * du + s * dv, -s * du + c * dv
    x, y = xr / a, yr / b
    dist = np.abs(x * x + y * y - 1.0) / (2.0 * np.sqrt((x / a) ** 2 + (y / b) ** 2) + 1e-12)
    off = dist > 1.5
    inner = off & ((xr / a_in) ** 2 + (yr / b_in) ** 2 < 1.0)
    junction = np.bincount(end_k[off & (d2 <= 9.0)], minlength=12) > 0
    crossing = np.bincount(end_k[inner & (d2 <= 36.0)], minlength=12) > 0
    got = kernels.junction_ends(pu, pv, ends, owner, params, 6.0, 9.0, 36.0, 1.5)
    assert np.array_equal(got, junction & crossing)
    assert got.any() and not got.all()


def test_face_median_matches_the_sorted_channels(rng: np.random.Generator) -> None:
    image = rng.integers(0, 256, (40, 50, 3)).astype(np.uint8)
    t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ct, st = np.cos(t), np.sin(t)
    for cx, cy, sa, sb, th in [(25.0, 20.0, 8.0, 5.0, 0.3), (2.0, 38.0, 10.0, 6.0, 2.0)]:
        c, s = np.cos(th), np.sin(th)
        x, y = sa * ct, sb * st
        u = np.clip(np.rint(cx + c * x + -s * y).astype(int), 0, 49)
        v = np.clip(np.rint(cy + s * x + c * y).astype(int), 0, 39)
        ordered = np.sort(image[v, u].T, axis=1)
        want = 0.5 * (ordered[:, 7].astype(np.float64) + ordered[:, 8])
        got = kernels.face_median(image, cx, cy, sa, sb, c, s, ct, st)
        assert np.array_equal(got, want)


def test_project_outside_matches_the_array_form(rng: np.random.Generator) -> None:
    band = np.stack([rng.uniform(-0.05, 0.05, (2, 40)), rng.uniform(-0.05, 0.05, (2, 40)),
                     rng.uniform(0.3, 0.5, (2, 40))])
    terms = np.array([[160.0, 120.0, 1.0, 0.0, 30.0, 20.0], [150.0, 110.0, 0.6, 0.8, 25.0, 25.0]])
    fx, fy, kcx, kcy = 290.0, 290.0, 159.5, 119.5
    pu = fx * band[0] / band[2] + kcx
    pv = fy * band[1] / band[2] + kcy
    cx, cy, c, s, a, b = (terms[:, i:i + 1] for i in range(6))
    du, dv = pu - cx, pv - cy
    x, y = (c * du + s * dv) / a, (-s * du + c * dv) / b
    rho = np.sqrt(x * x + y * y)
    outside = (rho - 1.0) * np.hypot(x * a, y * b) / np.maximum(rho, 1e-9) > 2.0
    got = kernels.project_outside(band, terms, fx, fy, kcx, kcy, 2.0)
    assert np.array_equal(got[0], pu) and np.array_equal(got[1], pv)
    assert np.array_equal(got[2], outside) and outside.any() and not outside.all()


def test_point_distances_match_the_array_form(rng: np.random.Generator) -> None:
    points = rng.uniform(0, 100, (500, 2))
    cx, cy, a, b, t = 50.0, 40.0, 30.0, 12.0, 0.7
    c, s = np.cos(t), np.sin(t)
    du, dv = points[:, 0] - cx, points[:, 1] - cy
    x, y = (c * du + s * dv) / a, (-s * du + c * dv) / b
    want = np.abs(x * x + y * y - 1.0) / (2.0 * np.sqrt((x / a) ** 2 + (y / b) ** 2) + 1e-12)
    assert np.array_equal(kernels.point_distances(points, cx, cy, a, b, c, s), want)


def _pixels_about(rng: np.random.Generator, m: int, cx: float, cy: float, a: float,
                  b: float, t: float) -> np.ndarray:
    """(m, 2) int32 pixels scattered about an ellipse (4 px normal noise on each axis of its
    frame): some within a few pixels' tolerance of it, some not."""
    c, s = np.cos(t), np.sin(t)
    phi = rng.uniform(0, 2 * np.pi, m)
    u, v = a * np.cos(phi) + rng.normal(0, 4, m), b * np.sin(phi) + rng.normal(0, 4, m)
    return np.rint(np.column_stack([cx + c * u - s * v, cy + s * u + c * v])).astype(np.int32)


def test_pair_lies_matches_the_array_form(rng: np.random.Generator) -> None:
    cx, cy, a, b, t = 50.0, 40.0, 30.0, 12.0, 0.7
    c, s = np.cos(t), np.sin(t)
    for m in (5, 7, 8, 9, 64, 129, 300, 1001):
        points = _pixels_about(rng, m, cx, cy, a, b, t)
        n = m // 3
        d = kernels.point_distances(points.astype(np.float64), cx, cy, a, b, c, s)
        want = (float(np.sqrt(np.mean(d * d))), int(np.count_nonzero(d[:n] < 4.0)),
                int(np.count_nonzero(d[n:] < 4.0)))
        got = kernels.pair_lies(points, n, cx, cy, a, b, c, s, 4.0)
        assert got == want and 0 < got[1] + got[2] < m


def test_points_rms_and_chain_hits_match_the_array_forms(rng: np.random.Generator) -> None:
    """rms_residual's and chains_on's compiled passes: numpy's mean of the squared
    distances (pairwise sums, on every block size) and np.bincount of the near pixels'
    chains, on int32 pixels and float64 points alike."""
    cx, cy, a, b, t = 50.0, 40.0, 30.0, 12.0, 0.7
    c, s = np.cos(t), np.sin(t)
    for m in (1, 5, 8, 9, 64, 129, 300, 1001):
        pixels = _pixels_about(rng, m, cx, cy, a, b, t)
        owner = np.sort(rng.integers(0, 5, m)).astype(np.int64)
        for points in (pixels, pixels + rng.uniform(-0.5, 0.5, (m, 2))):
            d = kernels.point_distances(points.astype(np.float64), cx, cy, a, b, c, s)
            assert kernels.points_rms(points, cx, cy, a, b, c, s) == float(
                np.sqrt(np.mean(d * d)))
            assert np.array_equal(kernels.chain_hits(points, owner, 6, cx, cy, a, b, c, s, 4.0),
                                  np.bincount(owner[d < 4.0], minlength=6))


def test_chain_hits_screen_drops_no_near_pixel(rng: np.random.Generator) -> None:
    """chain_hits measures only the pixels in the box of the ellipse scaled to where the
    Sampson distance can reach the tolerance: the counts stay np.bincount's of every pixel's
    test, for pixels anywhere, on thin and round ellipses and small and large tolerances."""
    for a, b, tol in ((40.0, 12.0, 2.0), (60.0, 0.8, 3.0), (25.0, 25.0, 0.5), (9.0, 4.0, 30.0)):
        cx, cy, t = 80.0, 60.0, float(rng.uniform(0, np.pi))
        c, s = np.cos(t), np.sin(t)
        phi, r = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(0.5, 4.0, 3000)
        u, v = a * r * np.cos(phi), b * r * np.sin(phi)
        ring = np.column_stack([cx + c * u - s * v, cy + s * u + c * v])
        points = np.concatenate([ring, rng.uniform(-200, 300, (3000, 2))])
        owner = rng.integers(0, 9, points.shape[0]).astype(np.int64)
        for pts in (np.rint(points).astype(np.int32), points):
            d = kernels.point_distances(pts.astype(np.float64), cx, cy, a, b, c, s)
            assert 0 < np.count_nonzero(d < tol) < d.size
            assert np.array_equal(kernels.chain_hits(pts, owner, 9, cx, cy, a, b, c, s, tol),
                                  np.bincount(owner[d < tol], minlength=9))


def test_stride_magnitudes_match_the_strided_float32_form(rng: np.random.Generator) -> None:
    """The edge statistics' sample: every 4th row and column's float32 magnitude over the
    Sobel gain, as the array expression gives it, on sizes not a multiple of the stride."""
    for h, w in ((1, 1), (3, 7), (60, 80), (61, 83)):
        dx = rng.integers(-4080, 4081, (h, w)).astype(np.int16)
        dy = rng.integers(-4080, 4081, (h, w)).astype(np.int16)
        sx, sy = dx[::4, ::4].astype(np.float32), dy[::4, ::4].astype(np.float32)
        want = np.sqrt(sx * sx + sy * sy).ravel() / 8.0
        got = kernels.stride_magnitudes(dx, dy, 4, 8.0)
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_stride_quantiles_are_the_partitions_order_statistics(rng: np.random.Generator
                                                              ) -> None:
    """The edge thresholds' median and 99th percentile of the magnitude sample: the values a
    partition puts at N // 2 and min(N - 1, int(0.99 N)), on flat, tied, sparse and
    full-range gradients (and 0 for an empty sample)."""
    empty = np.zeros((0, 5), np.int16)
    assert kernels.stride_quantiles(empty, empty, 4, 8.0) == (0.0, 0.0, 0)
    for h, w, scale, sparse in ((1, 1, 9, False), (3, 7, 1, False), (60, 80, 4080, False),
                                (61, 83, 3, True), (90, 90, 32767, False), (40, 50, 0, False)):
        dx = rng.integers(-scale, scale + 1, (h, w)).astype(np.int16)
        dy = rng.integers(-scale, scale + 1, (h, w)).astype(np.int16)
        if sparse:  # mostly flat: most magnitudes tie at zero
            dx[rng.random((h, w)) < 0.9] = 0
            dy[dx == 0] = 0
        mags = kernels.stride_magnitudes(dx, dy, 4, 8.0)
        k50, k99 = mags.size // 2, min(mags.size - 1, int(0.99 * mags.size))
        mags.partition((k50, k99))
        assert kernels.stride_quantiles(dx, dy, 4, 8.0) == (float(mags[k50]), float(mags[k99]),
                                                            mags.size)


def _contrast_peaks_numpy(pts: NDArray[np.float64], normals: NDArray[np.float64],
                          gx: NDArray[np.int16], gy: NDArray[np.int16],
                          offsets: NDArray[np.float64], threshold: float, innermost: bool
                          ) -> NDArray[np.float64]:
    """The contrast refit's round as array expressions (np.convolve's windowed mean)."""
    h, w = gx.shape
    q = pts[:, None, :] + offsets[None, :, None] * normals[:, None, :]
    u = np.clip(np.rint(q[..., 0]).astype(np.int64), 0, w - 1)
    v = np.clip(np.rint(q[..., 1]).astype(np.int64), 0, h - 1)
    g = gx[v, u] * normals[:, None, 0] + gy[v, u] * normals[:, None, 1]
    k = 5
    padded = np.concatenate([g[-(k // 2):], g, g[: k // 2]], axis=0)
    smooth = np.stack([np.convolve(padded[:, j], np.ones(k) / k, mode="valid")
                       for j in range(offsets.size)], axis=1)
    mag = np.abs(smooth) / 8.0
    best = np.argmax(mag, axis=1)
    if innermost:
        padded_mag = np.pad(mag, ((0, 0), (1, 1)))
        peak = (mag >= padded_mag[:, :-2]) & (mag >= padded_mag[:, 2:]) & (mag >= threshold)
        best = np.where(peak.any(axis=1), np.argmax(peak, axis=1), best)
    ok = mag[np.arange(best.size), best] >= threshold
    return q[np.flatnonzero(ok), best[ok]]


@pytest.mark.parametrize("innermost", [False, True])
def test_contrast_peaks_match_the_array_form(rng: np.random.Generator,
                                             innermost: bool) -> None:
    from stackpick_sim.geometry import Ellipse
    from stackpick_sim.vision.contrast import outline

    # Smooth gradients with steps (ties and local peaks), outlines partly off the image.
    base = cv2.GaussianBlur(rng.integers(0, 256, (60, 80)).astype(np.uint8), (5, 5), 1.5)
    base[20:45, 25:60] //= 2
    gx, gy = cv2.spatialGradient(base)
    for cx, cy, a, b, angle in [(40.0, 32.0, 17.0, 11.0, 20.0), (70.0, 50.0, 20.0, 14.0, 100.0),
                                (40.5, 30.2, 9.3, 8.8, 0.0)]:
        pts, normals = outline(Ellipse(cx=cx, cy=cy, a=a, b=b, angle_deg=angle))
        offsets = np.arange(-6 if innermost else -3, 4, dtype=np.float64)
        for threshold in (0.5, 3.0, 8.0):
            want = _contrast_peaks_numpy(pts, normals, gx, gy, offsets, threshold, innermost)
            got = kernels.contrast_peaks(
                np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                np.ascontiguousarray(normals[:, 0]), np.ascontiguousarray(normals[:, 1]),
                gx, gy, offsets, 5, 8.0, threshold, innermost)
            assert np.array_equal(got, want)
            assert 0 < got.shape[0] or threshold == 8.0


def test_band_points_match_the_array_form(rng: np.random.Generator) -> None:
    vectors = rng.normal(size=(4, 3, 3))
    t = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
    ct, st = np.cos(t), np.sin(t)
    depths = np.array([0.2, 0.4, 0.6])
    normal, centre, u, v = vectors.transpose(0, 2, 1)
    rim = centre[:, :, None] + ct * u[:, :, None]
    rim += st * v[:, :, None]
    want = (rim[:, :, None, :] + depths.reshape(1, 1, -1, 1) * normal[:, :, None, None]
            ).reshape(3, 3, -1)
    assert np.array_equal(kernels.band_points(vectors, ct, st, depths), want)


def _circle_solutions_python(q: list[float], evals: list[float], evecs: list[list[float]],
                             ellipse: tuple[float, float, float, float, float],
                             camera: tuple[float, float, float, float]
                             ) -> list[list[float]]:
    """The two unit-radius circle poses on Python floats ((normal, centre) each, flat)."""
    fx, fy, cx, cy = camera
    q00, q01, q02, q11, q12, q22 = q
    l_lo, l_mid, l_hi = evals
    (v00, _, v02), (v10, _, v12), (v20, _, v22) = evecs
    if (l_lo > 0) + (l_mid > 0) + (l_hi > 0) == 1:
        q00, q01, q02, q11, q12, q22 = -q00, -q01, -q02, -q11, -q12, -q22
        l3, l2, l1 = -l_hi, -l_mid, -l_lo
        e3, e1 = [v02, v12, v22], [v00, v10, v20]
    else:
        l3, l2, l1 = l_lo, l_mid, l_hi
        e3, e1 = [v00, v10, v20], [v02, v12, v22]
    g = math.sqrt(max(0.0, (l1 - l2) / (l1 - l3)))
    h = math.sqrt(max(0.0, (l2 - l3) / (l1 - l3)))

    def form(x: tuple[float, float, float]) -> float:
        return (q00 * x[0] * x[0] + q11 * x[1] * x[1] + q22 * x[2] * x[2]
                + 2.0 * (q01 * x[0] * x[1] + q02 * x[0] * x[2] + q12 * x[1] * x[2]))

    ex, ey, a, b, angle = ellipse
    t = math.radians(angle)
    ct, st = math.cos(t), math.sin(t)
    a2, b2 = a ** 2, b ** 2
    w00, w01, w11 = ct * ct * a2 + st * st * b2, ct * st * (a2 - b2), st * st * a2 + ct * ct * b2
    out = []
    for sign in (1.0, -1.0):
        n = [sign * g * e1[i] + h * e3[i] for i in range(3)]
        n = n if n[2] > 0 else [-n[0], -n[1], -n[2]]
        m0, m1 = n[0] / fx, n[1] / fy
        m2 = -cx / fx * n[0] - cy / fy * n[1] + n[2]
        cm = ex * m0 + ey * m1
        p0 = w00 * m0 + w01 * m1 - ex * cm - ex * m2
        p1 = w01 * m0 + w11 * m1 - ey * cm - ey * m2
        p2 = -cm - m2
        ray = ((p0 / p2 - cx) / fx, (p1 / p2 - cy) / fy, 1.0)
        along = n[0] * ray[0] + n[1] * ray[1] + n[2]
        x0 = (ray[0] / along, ray[1] / along, 1.0 / along)
        norm = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        k0, k1, k2 = n[0] / norm, n[1] / norm, n[2] / norm
        u0, u1, u2 = (0.0, k2, -k1) if abs(k0) < 0.9 else (-k2, 0.0, k0)
        un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        s2 = -form(x0) / form((u0 / un, u1 / un, u2 / un))
        scale = 1.0 / math.sqrt(max(s2, 1e-300))
        out.append([*n, x0[0] * scale, x0[1] * scale, x0[2] * scale])
    return out


def test_circle_solutions_match_the_float_arithmetic(rng: np.random.Generator) -> None:
    from stackpick_sim.geometry import CameraIntrinsics, Ellipse
    from stackpick_sim.vision.kernels_pose import cone_of

    k = CameraIntrinsics(fx=277.1, fy=277.1, cx=160.0, cy=120.0, width=320, height=240)
    camera = (k.fx, k.fy, k.cx, k.cy)
    for _ in range(300):
        a = float(rng.uniform(8.0, 80.0))
        e = Ellipse(cx=float(rng.uniform(0, 320)), cy=float(rng.uniform(0, 240)), a=a,
                    b=a * float(rng.uniform(0.3, 1.0)), angle_deg=float(rng.uniform(0, 180)))
        # The cone's entries (cone_of: the float arithmetic, see its test).
        q = cone_of(e.cx, e.cy, e.a ** 2, e.b ** 2, e.angle_deg, *camera)[1][:6].tolist()
        w, v = np.linalg.eigh(np.array([[q[0], q[1], q[2]], [q[1], q[3], q[4]],
                                        [q[2], q[4], q[5]]]))
        t = math.radians(e.angle_deg)
        got, ok = kernels.circle_solutions(
            np.array(q), w, v, np.array([e.cx, e.cy, math.cos(t), math.sin(t), e.a ** 2,
                                         e.b ** 2]), np.array(camera))
        want = _circle_solutions_python(q, w.tolist(), v.tolist(),
                                        (e.cx, e.cy, e.a, e.b, e.angle_deg), camera)
        assert ok
        assert got.reshape(2, 6).tolist() == want
    # A degenerate form (equal eigenvalues) divides by zero: no poses.
    assert not kernels.circle_solutions(np.ones(6), np.ones(3), np.eye(3), np.ones(6),
                                        np.ones(4))[1]


def test_stairs_removed_match_the_whole_image_passes(rng: np.random.Generator) -> None:
    from stackpick_sim.vision.edges import STAIR_LUTS, neighbour_codes

    for k in range(6):
        image = cv2.GaussianBlur(rng.integers(0, 256, (50, 70)).astype(np.uint8), (5, 5),
                                 1.0 + k * 0.3)
        canny = cv2.Canny(image, 20, 60)
        canny[0, :] = canny[-1, :] = canny[:, 0] = canny[:, -1] = 255  # the borders too
        b = (canny > 0).astype(np.uint8)
        for lut in STAIR_LUTS:
            b = b - np.minimum(b, lut[neighbour_codes(b)])
        got = kernels.stairs_removed(canny, *STAIR_LUTS)
        assert np.array_equal(got, b)
        assert np.count_nonzero(got) < np.count_nonzero(canny)  # some stairs were removed


def test_edge_pixels_match_the_array_form(rng: np.random.Generator) -> None:
    gx, gy = _gradients(rng)
    gx[5, :] = gy[5, :] = 0  # zero gradients: the 1e-9 floor
    edges = (rng.random((60, 80)) < 0.1).astype(np.uint8)
    edges[5, ::3] = 1
    at = np.flatnonzero(edges)
    u, v = (at % 80).astype(np.float64), (at // 80).astype(np.float64)
    fx, fy = gx.ravel()[at].astype(np.float64), gy.ravel()[at].astype(np.float64)
    norm = np.maximum(np.hypot(fx, fy), 1e-9)
    pts, g = kernels.edge_pixels(edges, gx, gy)
    assert np.array_equal(pts, np.stack([u, v]))
    assert np.array_equal(g, np.stack([fx / norm, fy / norm]))


def test_row_keys_match_the_array_form(rng: np.random.Generator) -> None:
    at = np.flatnonzero(rng.random((40, 70)) < 0.2)
    for order in (np.arange(at.size), rng.permutation(at.size)):  # np.nonzero's order, shuffled
        u, v = (at % 70).astype(np.float64)[order], (at // 70).astype(np.float64)[order]
        width = int(u.max(initial=0.0)) + 2
        want = v * width + u
        keys, got_width, ascending = kernels.row_keys(u, v)
        assert np.array_equal(keys, want) and got_width == width
        assert ascending == bool(np.all(want[1:] >= want[:-1]))
    assert kernels.row_keys(np.zeros(0), np.zeros(0))[1:] == (2, True)


def test_outline_columns_match_the_array_form(rng: np.random.Generator) -> None:
    for n in (16, 101, 640):
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ct, st = np.cos(t), np.sin(t)
        cx, cy, a, b, th = rng.uniform(0, 320), rng.uniform(0, 240), 60.0, 4.5, 1.234
        c, s = math.cos(th), math.sin(th)
        x, y = a * ct, b * st
        pu, pv = cx + c * x, cy + s * x
        pu -= s * y
        pv += c * y
        nx, ny = b * ct, a * st
        norm = np.hypot(nx, ny)
        nx, ny = nx / norm, ny / norm
        got = kernels.outline_columns(cx, cy, a, b, c, s, ct, st)
        for column, want in zip(got, (pu, pv, c * nx - s * ny, s * nx + c * ny), strict=True):
            np.testing.assert_array_equal(column, want)


def _find_roi_reference(image: NDArray[np.uint8], params: RoiParams) -> Roi:
    """The region of interest by OpenCV's and numpy's whole-array calls (the form the
    compiled passes stand for)."""
    h, w = image.shape[:2]
    small = decimate(image, params.decimation)
    level = (np.maximum(np.maximum(small[:, :, 0], small[:, :, 1]), small[:, :, 2])
             if small.ndim == 3 else small)
    counts = cv2.calcHist([level], [0], None, [256], [0, 256]).ravel()
    window = np.asarray(np.bartlett(params.belt_mode_window + 2)[1:-1], np.float64)
    belt = int(np.argmax(np.convolve(counts, window, mode="same")))
    spread = params.belt_colour_levels
    near = cv2.inRange(level, max(0, belt - spread), min(255, belt + spread))
    channels = 1 if small.ndim == 2 else int(small.shape[2])
    colour = ((float(belt),) * channels if cv2.countNonZero(near) == 0
              else tuple(float(c) for c in cv2.mean(small, mask=near)[:channels]))
    fg = cv2.absdiff(level, np.full_like(level, belt)) > params.foreground_delta
    bu, bv, bw, bh = cv2.boundingRect(fg.view(np.uint8))
    if bw == 0 or bh == 0:
        return Roi(u0=0, v0=0, u1=w, v1=h, belt=colour)
    step, margin = params.decimation, params.margin_px
    return Roi(u0=max(0, bu * step - margin), v0=max(0, bv * step - margin),
               u1=min(w, (bu + bw) * step + margin), v1=min(h, (bv + bh) * step + margin),
               belt=colour)


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("window", [1, 4, 9])
def test_find_roi_matches_the_whole_array_calls(rng: np.random.Generator, channels: int,
                                                window: int) -> None:
    for trial in range(20):
        h, w = (int(x) for x in rng.integers(12, 90, 2))
        belt = int(rng.integers(0, 256))
        image = np.clip(belt + rng.normal(0, 3, (h, w, channels)), 0, 255).astype(np.uint8)
        if trial % 4:  # a few objects of other levels, some near the belt's
            for _ in range(int(rng.integers(1, 4))):
                v, u = int(rng.integers(0, h)), int(rng.integers(0, w))
                image[v:v + int(rng.integers(2, 30)), u:u + int(rng.integers(2, 30))] = (
                    rng.integers(0, 256, channels))
        image = image.squeeze(axis=2) if channels == 1 else image
        params = RoiParams(belt_mode_window=window, decimation=int(rng.choice([1, 2, 4])),
                           belt_colour_levels=int(rng.integers(0, 4)))
        assert find_roi(image, params) == _find_roi_reference(image, params)


def test_fit_checks_match_fit_ellipse_and_plausible(rng: np.random.Generator) -> None:
    raw = np.column_stack([rng.uniform(-50, 300, 400), rng.uniform(-50, 300, 400),
                           rng.uniform(-5, 200, 400), rng.uniform(-5, 200, 400),
                           rng.uniform(-180, 360, 400)])
    raw[::7, 3] = raw[::7, 2] * 1e-4  # extreme axis ratios: Eq. 2 evaluated
    raw[::11, 0], raw[::13, 4], raw[::17, 2] = np.nan, np.inf, 0.0
    shape = (240, 320)
    params = FitParams()
    top = params.max_axis_diagonals * math.hypot(*shape)
    rows, degrees, ok = kernels.fit_checks(raw, params.min_axis_px, top, EQ2_CHECKED_RATIO_SQ)
    for k, (cx, cy, w, h, angle) in enumerate(raw.tolist()):
        with mock.patch.object(kernels_fit, "direct_fit",
                               return_value=np.array([cx, cy, w, h, angle])):
            e = fit_ellipse(np.zeros((5, 2), np.int32))
        assert bool(ok[k]) == (e is not None and plausible(e, shape, params))
        if e is not None:
            assert (rows[k, :4].tolist(), degrees[k]) == ([e.cx, e.cy, e.a, e.b], e.angle_deg)
            assert rows[k, 4] == math.radians(e.angle_deg)


def test_ellipse_forms_match_the_form_of_each_ellipse(rng: np.random.Generator) -> None:
    rows = np.column_stack([rng.uniform(0, 300, 300), rng.uniform(0, 300, 300),
                            rng.uniform(5, 150, 300), rng.uniform(1, 100, 300),
                            rng.uniform(0, 180, 300)])
    want = [_form(Ellipse.of(*r)) for r in rows.tolist()]
    assert kernels.ellipse_forms(rows).tolist() == [list(f) for f in want]


def test_refit_checks_are_fit_checks_then_the_forms_and_stops(rng: np.random.Generator
                                                              ) -> None:
    raw = np.column_stack([rng.uniform(-50, 300, 60), rng.uniform(-50, 300, 60),
                           rng.uniform(-5, 200, 60), rng.uniform(-5, 200, 60),
                           rng.uniform(-180, 360, 60)])
    raw[::11, 0] = np.nan
    which = rng.permutation(80)[:60].astype(np.int64)
    forms = rng.uniform(0, 1, (80, 5))
    active = np.ones(80, np.bool_)
    want_forms, want_active = forms.copy(), active.copy()
    rows, degrees, ok = kernels.fit_checks(raw, 2.0, 250.0, EQ2_CHECKED_RATIO_SQ)
    for k, e in enumerate(which.tolist()):
        if ok[k]:
            fit = Ellipse.of(*rows[k, :4].tolist(), float(degrees[k]))
            want_forms[e] = _form(fit)
        else:
            want_active[e] = False
    got = kernels.refit_checks(raw, which, forms, active, 2.0, 250.0, EQ2_CHECKED_RATIO_SQ)
    for a, b in zip(got, (rows, degrees, ok), strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(forms, want_forms) and np.array_equal(active, want_active)
    assert 0 < int(ok.sum()) < 60


@pytest.mark.parametrize("dtype", [np.int32, np.float64])
def test_level_fits_are_the_fit_checks_then_their_residuals(rng: np.random.Generator,
                                                       dtype: type) -> None:
    pixels = rng.integers(0, 300, (500, 2)).astype(dtype)
    raw = np.column_stack([rng.uniform(50, 250, 40), rng.uniform(50, 250, 40),
                           rng.uniform(-5, 200, 40), rng.uniform(1, 200, 40),
                           rng.uniform(0, 360, 40)])
    starts = rng.integers(0, 400, 40)
    stops = starts + rng.integers(1, 100, 40)
    rows, degrees, ok = kernels.fit_checks(raw, 2.0, 150.0, EQ2_CHECKED_RATIO_SQ)
    # Each checked fit's residual on its range (the squares summed in order).
    rms = np.zeros(40)
    for e in ok.nonzero()[0]:
        lo, hi = starts[e], stops[e]
        d = grouped_distances(rows[e:e + 1], np.array([hi - lo]),
                              pixels[lo:hi, 0].astype(float), pixels[lo:hi, 1].astype(float))
        rms[e] = math.sqrt(float(np.bincount(np.zeros(hi - lo, np.int64), weights=d * d)[0])
                           / (hi - lo))
    got = kernels.level_fits(raw, pixels, starts, stops, 2.0, 150.0, EQ2_CHECKED_RATIO_SQ, 60.0)
    assert np.array_equal(got[0], rows) and np.array_equal(got[1], degrees)
    assert np.array_equal(got[2], ok & (rms <= 60.0)) and np.array_equal(got[3], rms)
    assert 0 < int(got[2].sum()) < int(ok.sum())


@pytest.mark.parametrize("dtype", [np.int32, np.float64])
def test_level_step_is_level_fits_then_the_halves_screened(rng: np.random.Generator,
                                                          dtype: type) -> None:
    counts = rng.integers(1, 60, 30).astype(np.int64)
    pixels = rng.integers(0, 300, (int(counts.sum()), 2)).astype(dtype)
    pixels[:counts[0], 1] = 7  # a straight piece
    pieces, tried = kernels.chain_pieces(pixels, counts, 10, 2.0)
    # The long bowed chains.
    bows = _bows(pixels, counts)
    want = np.array([i for i in range(30) if counts[i] >= 10 and bows[i] >= 2.0], np.int64)
    ends = np.cumsum(counts)
    starts, stops = (ends - counts)[want], ends[want]
    assert 0 not in want
    assert np.array_equal(pieces, np.stack([ends - counts, ends, np.arange(30)]))
    assert np.array_equal(tried, np.column_stack([want, starts, stops, want]))
    k = want.shape[0]
    raw = np.column_stack([rng.uniform(50, 250, k), rng.uniform(50, 250, k),
                           rng.uniform(-5, 200, k), rng.uniform(1, 200, k),
                           rng.uniform(0, 360, k)])
    limits = (2.0, 150.0, EQ2_CHECKED_RATIO_SQ, 60.0)
    rows, good, nxt, nxt_tried = kernels.level_step(raw, pixels, pieces, tried, *limits, 20,
                                                    10, 2.0)
    fits, degrees, ok, rms = kernels.level_fits(raw, pixels, starts, stops, *limits)
    assert np.array_equal(good, ok) and 0 < int(ok.sum()) < k
    assert np.array_equal(rows, np.column_stack([fits[:, :4], degrees, rms]))
    # The halves of the pieces not accepted of at least 20 pixels, in order, then screened.
    accepted = set(want[ok].tolist())
    halves = [h for i in range(30) if i not in accepted and counts[i] >= 20
              for h in ((ends[i] - counts[i], ends[i] - counts[i] + counts[i] // 2, i),
                        (ends[i] - counts[i] + counts[i] // 2, ends[i], i))]
    assert nxt.T.tolist() == [list(h) for h in halves]
    sizes = nxt[1] - nxt[0]
    bows = _bows(np.concatenate([pixels[lo:hi] for lo, hi, _ in halves]), sizes)
    screened = [i for i in range(len(halves)) if sizes[i] >= 10 and bows[i] >= 2.0]
    assert nxt_tried.tolist() == [[i, *halves[i]] for i in screened] and screened
    assert kernels.level_step(raw, pixels, pieces, tried, *limits, 0, 10, 2.0)[2].size == 0


def test_stairs_removed_pixels_are_the_map_then_its_edge_pixels(
        rng: np.random.Generator) -> None:
    from stackpick_sim.vision.edges import STAIR_LUTS

    for density in (0.05, 0.3, 0.7):
        edges = (rng.uniform(0, 1, (41, 57)) < density).astype(np.uint8)
        gx, gy = _gradients(rng)
        gx, gy = np.ascontiguousarray(gx[:41, :57]), np.ascontiguousarray(gy[:41, :57])
        gx[::5, ::3] = gy[::5, ::3] = 0  # zero gradients: the floor of the norm
        thin, pts, g = kernels.stairs_removed_pixels(edges, *STAIR_LUTS, gx, gy)
        want = kernels.stairs_removed(edges, *STAIR_LUTS)
        np.testing.assert_array_equal(thin, want)
        want_pts, want_g = kernels.edge_pixels(want, gx, gy)
        np.testing.assert_array_equal(pts, want_pts)
        np.testing.assert_array_equal(g, want_g)


def test_junctions_cut_matches_the_box_filters(rng: np.random.Generator) -> None:
    for density in (0.0, 0.1, 0.4, 0.9):
        edges = (rng.uniform(0, 1, (37, 53)) < density).astype(np.uint8)
        box = cv2.boxFilter(edges, cv2.CV_8U, (3, 3), normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        cut = ((box <= 3) & (edges > 0)).astype(np.uint8)
        box = cv2.boxFilter(cut, cv2.CV_8U, (3, 3), normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        rows, cols = np.nonzero(edges)
        for got, want in zip(kernels.set_pixels(edges), (rows, cols), strict=True):
            np.testing.assert_array_equal(got, want)
        got_cut, got_end, valid = kernels.junctions_cut(edges, rows, cols)
        assert valid
        np.testing.assert_array_equal(got_cut, cut)
        np.testing.assert_array_equal(got_end, ((box <= 2) & (cut > 0)).astype(np.uint8))
        if rows.size > 1:  # pixels out of order, or not set: told, not used
            assert not kernels.junctions_cut(edges, rows[::-1].copy(), cols[::-1].copy())[2]
            assert not kernels.junctions_cut(1 - edges, rows, cols)[2]


def test_near_pairs_beyond_one_per_point_are_all_listed(rng: np.random.Generator) -> None:
    rows = np.repeat(_ellipse_rows(rng, 1), 5, axis=1)  # one outline, five times over
    t = rng.uniform(0, 2 * np.pi, 40)
    pu = rows[0, 0] + rows[4, 0] * rows[2, 0] * np.cos(t) - rows[5, 0] * rows[3, 0] * np.sin(t)
    pv = rows[1, 0] + rows[5, 0] * rows[2, 0] * np.cos(t) + rows[4, 0] * rows[3, 0] * np.sin(t)
    got_e, got_m = _near_pairs(pu, pv, rows, rows[2] + 3.0, 1.0)
    assert np.array_equal(got_e, np.arange(5).repeat(40))
    assert np.array_equal(got_m, np.tile(np.arange(40), 5))


def test_lying_pairs_match_the_share_matrix(rng: np.random.Generator) -> None:
    sizes = rng.integers(1, 40, 15)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    for fraction in (0.3, 0.5, 1.0):
        pair_g = rng.integers(0, 4, 600).astype(np.int64)
        pair_p = rng.integers(0, int(starts[-1]), 600).astype(np.int64)
        seg = np.arange(15).repeat(sizes)
        hits = np.bincount(pair_g * 15 + seg[pair_p], minlength=60).reshape(4, 15)
        want = (hits / sizes.astype(np.float64)[None, :] >= fraction).nonzero()
        got = kernels.lying_pairs(pair_g, pair_p, starts, 4, fraction)
        assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
        assert 0 < want[0].size


def test_pair_products_match_the_share_matrix(rng: np.random.Generator) -> None:
    # Pixels of random groups (the last one empty, of two or more), random pairs.
    for groups in (1, 2, 5, 9):
        owner = rng.integers(0, max(1, groups - 1), 300).astype(np.int64)  # the last empty
        pair_g = rng.integers(0, groups, 500).astype(np.int64)
        pair_p = rng.integers(0, 300, 500).astype(np.int64)
        hits = np.bincount(pair_g * groups + owner[pair_p],
                           minlength=groups * groups).reshape(groups, groups)
        share = hits / np.maximum(np.bincount(owner, minlength=groups).astype(np.float64), 1.0)
        want = share * share.T
        want.flat[:: groups + 1] = 0.0
        got = kernels.pair_products(pair_g, pair_p, owner, groups)
        assert np.array_equal(got, want)
        assert groups < 3 or want.max() > 0.0


def test_segments_rms_match_the_gathered_distances(rng: np.random.Generator) -> None:
    sizes = rng.integers(1, 30, 12)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    points = rng.integers(0, 200, (int(starts[-1]), 2)).astype(np.float64)
    ellipses = [Ellipse.of(*rng.uniform(50, 150, 2), *np.sort(rng.uniform(5, 60, 2))[::-1],
                           float(rng.uniform(0, 180))) for _ in range(6)]
    chosen = [sorted(rng.choice(12, int(rng.integers(1, 6)), replace=False).tolist())
              for _ in ellipses]
    got = kernels.segments_rms(distance_rows(ellipse_params(ellipses)), points, starts,
                               np.array([s for segs in chosen for s in segs], np.int64),
                               np.array([len(segs) for segs in chosen], np.int64))
    for e, segs, r in zip(ellipses, chosen, got, strict=True):
        at = np.concatenate([np.arange(starts[s], starts[s + 1]) for s in segs])
        d = grouped_distances(ellipse_params([e]), np.array([at.size]), points[at, 0],
                              points[at, 1])
        assert r == np.sqrt(np.bincount(np.zeros(at.size, np.int64), weights=d * d)[0]
                            / at.size)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_strongest_gradients_take_the_first_channel_of_largest_l1(
        rng: np.random.Generator, channels: int) -> None:
    stacked = rng.integers(-1020, 1021, (channels, 2, 30, 41)).astype(np.int16)
    stacked[:, :, :5] //= 200  # small values: many ties between channels
    l1 = np.abs(stacked[:, 0].astype(np.int32)) + np.abs(stacked[:, 1].astype(np.int32))
    first = np.argmax(l1, axis=0)[None]  # the first of equals
    got_x, got_y = kernels.strongest_gradients(stacked)
    assert np.array_equal(got_x, np.take_along_axis(stacked[:, 0], first, 0)[0])
    assert np.array_equal(got_y, np.take_along_axis(stacked[:, 1], first, 0)[0])


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_level_histogram_and_belt_box_match_the_array_forms(rng: np.random.Generator,
                                                            channels: int) -> None:
    for h, w in ((7, 9), (12, 16), (1, 1)):
        small = rng.integers(90, 140, (h, w, channels)).astype(np.uint8)
        small[h // 3:, w // 2:] = 200  # a block of foreground
        level, counts = kernels.level_histogram(small)
        assert np.array_equal(level, small.max(axis=2))
        assert np.array_equal(counts, np.bincount(level.ravel(), minlength=256).astype(float))
        belt = int(np.median(level))
        mean, near, box = kernels.belt_box(small, level, belt, 8, 20.0)
        on = np.abs(level.astype(int) - belt) <= 8
        assert near == on.sum()
        want = (small[on].astype(np.int64).sum(axis=0) * (1.0 / on.sum()) if on.any()
                else np.zeros(channels))
        assert np.array_equal(mean, want)
        fore = (np.abs(level.astype(int) - belt) > 20.0).astype(np.uint8)
        assert tuple(box.tolist()) == cv2.boundingRect(fore)


def test_uv_rows_cols_are_the_whole_pixels(rng: np.random.Generator) -> None:
    edges = (rng.random((40, 50)) < 0.3).astype(np.uint8)
    rows, cols = kernels.set_pixels(edges)
    uv = np.vstack([cols, rows]).astype(np.float64)
    got_rows, got_cols, whole = kernels.uv_rows_cols(uv)
    assert whole
    assert np.array_equal(got_rows, rows) and np.array_equal(got_cols, cols)
    uv[0, 3] += 0.5  # not a pixel
    assert not kernels.uv_rows_cols(uv)[2]


def test_outline_rows_match_the_perimeter_and_the_angle(rng: np.random.Generator) -> None:
    from stackpick_sim.vision.contrast import perimeter_px

    ellipses = [Ellipse.of(*rng.uniform(0, 300, 2), *np.sort(rng.uniform(0.5, 200, 2))[::-1],
                           float(rng.uniform(0, 180))) for _ in range(200)]
    counts, rows = kernels.outline_rows(
        np.array([(e.cx, e.cy, e.a, e.b, e.angle_deg) for e in ellipses]))
    assert counts.tolist() == [max(16, math.ceil(perimeter_px(e))) for e in ellipses]
    t = [math.radians(e.angle_deg) for e in ellipses]
    assert rows.tolist() == [[e.cx, e.cy, e.a, e.b, math.cos(x), math.sin(x)]
                             for e, x in zip(ellipses, t, strict=True)]


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (7, 8), (31, 33), (240, 320)])
def test_set_indices_are_the_flat_nonzero_pixels(rng: np.random.Generator,
                                                 shape: tuple[int, int]) -> None:
    for density in (0.0, 0.03, 0.5, 1.0):
        image = (rng.random(shape) < density).astype(np.uint8) * np.uint8(255)
        assert np.array_equal(kernels._set_indices(image), np.flatnonzero(image))


def _pixel_curves(rng: np.random.Generator) -> list[NDArray[np.int32]]:
    """Pixel curves of the kinds the segments stage approximates: rasterised ellipse arcs
    (distinct pixels, open or whole), 8-connected random walks (revisits and straight runs)
    and short pieces."""
    curves = []
    steps = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)])
    for _ in range(600):
        a, b = rng.uniform(3.0, 60.0, 2)
        t0 = rng.uniform(0.0, 2 * np.pi)
        t = np.linspace(t0, t0 + rng.uniform(0.3, 2 * np.pi), 400)
        pts = np.rint(np.column_stack([100 + a * np.cos(t), 100 + b * np.sin(t)]))
        moved = np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]
        curves.append(np.ascontiguousarray(pts[moved], np.int32))
        walk = steps[rng.integers(0, 8, int(rng.integers(1, 90)))]
        curves.append(np.ascontiguousarray(np.cumsum(walk, axis=0) + 50, np.int32))
    return curves


def test_poly_dp_is_opencvs_polygonal_approximation(rng: np.random.Generator) -> None:
    for curve in _pixel_curves(rng):
        for closed in (False, True):
            for eps in (0.5, 1.0, 2.5):
                out = np.empty((curve.shape[0] + 1, 2), np.int32)
                stack = np.empty((curve.shape[0] + 2, 2), np.int64)
                count = kernels.poly_dp(curve, closed, eps, out, stack)
                want = cv2.approxPolyDP(curve, eps, closed).reshape(-1, 2)
                assert np.array_equal(out[:count], want), (curve.tolist(), closed, eps)


def test_chain_polys_are_each_chains_polygon(rng: np.random.Generator) -> None:
    curves = _pixel_curves(rng)[:200]
    closed = rng.uniform(0, 1, len(curves)) < 0.5
    bounds = np.array([0, *np.cumsum([c.shape[0] for c in curves])], np.int64)
    polys, poly_bounds = kernels.chain_polys(np.concatenate(curves), bounds, closed, 1.0)
    assert poly_bounds[-1] == polys.shape[0]
    for c, curve in enumerate(curves):
        want = cv2.approxPolyDP(curve, 1.0, bool(closed[c])).reshape(-1, 2)
        assert np.array_equal(polys[poly_bounds[c]:poly_bounds[c + 1]], want)


def _outer_contours_opencv(binary: NDArray[np.uint8]) -> tuple[list[list[int]], list[int]]:
    """cv2.findContours' contours without a parent (RETR_CCOMP, every pixel), concatenated,
    and their lengths."""
    contours, hierarchy = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return [], []
    outer = [c.reshape(-1, 2) for c, h in zip(contours, hierarchy[0], strict=True) if h[3] == -1]
    return [p for c in outer for p in c.tolist()], [c.shape[0] for c in outer]


@pytest.mark.parametrize("kind", ["blobs", "arcs", "cut arcs"])
def test_outer_contours_are_opencvs_contours_without_a_parent(rng: np.random.Generator,
                                                              kind: str) -> None:
    for _ in range(300):
        h, w = (int(n) for n in rng.integers(1, 90, 2))
        if kind == "blobs":  # random blobs, with holes, nested pieces and single pixels
            binary = (rng.uniform(0, 1, (h, w)) < rng.uniform(0.05, 0.6)).astype(np.uint8)
        else:
            binary = np.zeros((h, w), np.uint8)
            for _ in range(int(rng.integers(1, 5))):
                centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
                axes = (int(rng.integers(1, 30)), int(rng.integers(1, 30)))
                cv2.ellipse(binary, centre, axes, float(rng.uniform(0, 180)),
                            float(rng.uniform(0, 360)), float(rng.uniform(0, 360)), 1, 1)
            if kind == "cut arcs":  # the segments stage's input: junctions cut out
                binary = kernels.junctions_cut(binary, *kernels.set_pixels(binary))[0]
        want_pixels, want_lengths = _outer_contours_opencv(binary)
        pixels, lengths = kernels.outer_contours(binary)
        assert pixels.tolist() == want_pixels
        assert lengths.tolist() == want_lengths
        # Given more pixels than the set ones (row-major), the same.
        more = binary | (rng.uniform(0, 1, binary.shape) < 0.2)
        pixels, lengths = kernels.contours_at(binary, *kernels.set_pixels(more))
        assert pixels.tolist() == want_pixels
        assert lengths.tolist() == want_lengths


def test_longest_contours_keep_the_longest_in_their_order(rng: np.random.Generator) -> None:
    for _ in range(200):
        lengths = rng.integers(1, 12, int(rng.integers(0, 30))).astype(np.int64)  # many ties
        contours = rng.integers(0, 100, (int(lengths.sum()), 2)).astype(np.int32)
        starts = np.concatenate([[0], np.cumsum(lengths)])
        shortest, cap = int(rng.integers(1, 6)), int(rng.integers(0, 10))
        long = [i for i in range(lengths.shape[0]) if lengths[i] >= shortest]
        kept = (sorted(sorted(long, key=lambda i: (-lengths[i], i))[:cap])
                if len(long) > cap else list(range(lengths.shape[0])))
        got, got_lengths = kernels.longest_contours(contours, lengths, shortest, cap)
        assert got_lengths.tolist() == lengths[kept].tolist()
        want = [contours[starts[i]:starts[i + 1]] for i in kept]
        assert np.array_equal(got, np.concatenate(want) if want else np.zeros((0, 2)))

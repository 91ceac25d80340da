"""The compiled passes of the top rule's evidence and the pose give the values of the steps
they chain (bit-identical)."""

from __future__ import annotations

import bisect
import itertools
import math

import numpy as np
import pytest

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.contrast import (
    _OFFSETS,
    _SHIFTS,
    contrast_profiles,
    outline_rows,
    outlines,
    supported_samples,
)
from stackpick_sim.vision.edges import SOBEL_GAIN, EdgeImage
from stackpick_sim.vision.occlusion import _support_along
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.wall import (
    band_evidences,
    plane_basis,
    solution_bands,
    tan_tilt,
    wall_evidences,
)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(11)


def _ellipses(rng: np.random.Generator, n: int, w: float = 80.0, h: float = 60.0
              ) -> list[Ellipse]:
    """Random ellipses over a w x h image, some reaching beyond it."""
    out = []
    for _ in range(n):
        a = rng.uniform(4.0, 30.0)
        out.append(Ellipse.of(rng.uniform(-5, w + 5), rng.uniform(-5, h + 5), a,
                              a * rng.uniform(0.3, 1.0), rng.uniform(-180, 180)))
    return out


def _image(rng: np.random.Generator) -> EdgeImage:
    gx = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    gy = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    return EdgeImage(edges=np.zeros((60, 80), np.uint8), gx=gx, gy=gy, noise=4.0)


def _gap_form(ok: np.ndarray, offsets: list[int], min_gap: int
              ) -> tuple[list[int], list[int], list[int]]:
    """Per outline the longest gap, and the ends of the gaps of at least ``min_gap`` samples
    with their outlines: the runs' first and last samples from the array form, paired by
    binary search."""
    n = len(offsets) - 1
    window = np.concatenate([(np.arange(b - a) + _SHIFTS[:, None]) % (b - a) + a
                             for a, b in itertools.pairwise(offsets)], axis=1)
    firsts = (~ok & ok[window[2]]).nonzero()[0].tolist()
    lasts = (~ok & ok[window[3]]).nonzero()[0].tolist()
    longest = [0 if ok[offsets[e]] else offsets[e + 1] - offsets[e] for e in range(n)]
    ends, owners = [], []
    runs: dict[int, int] = {}
    for first in firsts:
        e = bisect.bisect_right(offsets, first) - 1
        start, stop = offsets[e], offsets[e + 1]
        j = bisect.bisect_left(lasts, first)
        last = (lasts[j] if j < len(lasts) and lasts[j] < stop
                else lasts[bisect.bisect_left(lasts, start)])
        length = (last - first) % (stop - start) + 1
        runs[e] = max(runs.get(e, 0), length)
        if length >= min_gap:
            ends += [first - 1 if first > start else stop - 1,
                     last + 1 if last + 1 < stop else start]
            owners += [e, e]
    for e, length in runs.items():
        longest[e] = length
    return longest, ends, owners


def test_contrast_ok_is_the_profile_over_its_threshold(rng: np.random.Generator) -> None:
    image = _image(rng)
    ellipses = _ellipses(rng, 7)
    lines = outlines(ellipses)
    profile = contrast_profiles(lines, image)
    threshold = float(np.median(profile))
    table, sizes, ct, st = outline_rows(ellipses)
    pts, ok = kernels_pose.contrast_ok(table, sizes, ct, st, image.gx, image.gy, _OFFSETS,
                                       _SHIFTS, SOBEL_GAIN, threshold)
    assert np.array_equal(pts.T, lines.points)
    assert np.array_equal(ok, profile >= threshold) and 0 < ok.sum() < ok.size


def test_supported_samples_read_the_image_threshold(rng: np.random.Generator) -> None:
    image = _image(rng)
    ellipses = _ellipses(rng, 4)
    _, ok = supported_samples(outline_rows(ellipses), image)
    want = contrast_profiles(outlines(ellipses), image) >= max(
        image.params.support_min_contrast, image.params.support_noise_multiple * 4.0)
    assert np.array_equal(ok, want)


def _sampled_outlines(rng: np.random.Generator, n: int, share: float
                      ) -> tuple[list[Ellipse], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random ellipses, their outline rows and sample counts, their (2, N) outline
    samples and which of them are supported (about ``share`` of them, at random)."""
    ellipses = _ellipses(rng, n)
    table, sizes, ct, st = outline_rows(ellipses)
    pts, _ = kernels.outline_samples(table, sizes, ct, st)
    return ellipses, table, sizes, pts, rng.random(int(sizes.sum())) < share


@pytest.mark.parametrize("min_gap", [1, 3, 6])
def test_gap_evidence_is_the_runs_then_the_junction_test(rng: np.random.Generator,
                                                         min_gap: int) -> None:
    ellipses, table, sizes, pts, ok = _sampled_outlines(rng, 6, 0.75)
    ok[: sizes[0]] = True  # one outline wholly supported, one not
    ok[sizes[0]: sizes[0] + sizes[1]] = False
    ok[int(sizes[:3].sum()) - 2:int(sizes[:3].sum()) + 3] = False  # a run over an outline end
    offsets = [0, *np.cumsum(sizes).tolist()]
    edges = np.unique(rng.integers(0, 80, (900, 2)), axis=0).astype(np.float64)[:, ::-1]
    pu, pv = np.ascontiguousarray(edges[:, 0]), np.ascontiguousarray(edges[:, 1])
    tol, reach, junction, crossing = 0.8, 4.0, 2.0, 4.0
    supported, longest, occluded = kernels_pose.gap_evidence(
        ok, sizes, pts, table, pu, pv, min_gap, reach, junction ** 2, crossing ** 2, tol)
    want_longest, ends, owners = _gap_form(ok, offsets, min_gap)
    rows = [(cx, cy, c, s, a, b, max(a - tol, 1e-6), max(b - tol, 1e-6))
            for cx, cy, a, b, c, s in table.tolist()]
    both = kernels.junction_ends(pu, pv, np.ascontiguousarray(pts.T[ends]),
                                 np.array(owners, np.int64), np.array(rows).reshape(-1, 8),
                                 reach, junction ** 2, crossing ** 2, tol)
    want_occluded = np.bincount(np.array(owners, np.int64)[both], minlength=len(ellipses))
    assert supported.tolist() == np.add.reduceat(ok, offsets[:-1]).tolist()
    assert longest.tolist() == want_longest and (ends or min_gap > 3)
    assert occluded.tolist() == want_occluded.tolist()
    assert min_gap > 1 or want_occluded.sum() > 0


def test_the_support_map_path_reads_the_rounded_samples(rng: np.random.Generator) -> None:
    support = (rng.random((60, 80)) < 0.5).astype(np.uint8)
    ellipses = _ellipses(rng, 5)
    lines = outlines(ellipses)
    pix = np.rint(lines.points).astype(np.int64)
    inside = (pix[:, 0] >= 0) & (pix[:, 0] < 80) & (pix[:, 1] >= 0) & (pix[:, 1] < 60)
    want = np.zeros(pix.shape[0], bool)
    want[inside] = support[pix[inside, 1], pix[inside, 0]] > 0
    pts, ok = _support_along(outline_rows(ellipses), support, None)
    assert np.array_equal(pts.T, lines.points) and np.array_equal(ok, want)


def _shrunk_forms(ellipses: list[Ellipse], margin: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """kernels.interior_counts' (E, 6) forms and row counts, on Python floats."""
    params, sizes = [], []
    for e in ellipses:
        t = math.radians(e.angle_deg)
        c, s = math.cos(t), math.sin(t)
        ia = 1.0 / max(e.a - margin, 1e-6) ** 2
        ib = 1.0 / max(e.b - margin, 1e-6) ** 2
        p, q, r = c * c * ia + s * s * ib, 2.0 * c * s * (ia - ib), s * s * ia + c * c * ib
        half = math.sqrt(p / (p * r - 0.25 * q * q))
        first = math.ceil(e.cy - half)
        params.append((e.cx, e.cy, p, q, r, float(first)))
        sizes.append(max(0, math.floor(e.cy + half) - first + 1))
    return np.array(params).reshape(-1, 6), np.array(sizes, np.int64)


@pytest.mark.parametrize("pixels", [0, 1, 40, 1500, 6000])
def test_interior_counts_of_are_the_shrunk_forms_counts(rng: np.random.Generator,
                                                        pixels: int) -> None:
    uv = np.unique(rng.integers(0, 100, (pixels, 2)), axis=0).reshape(-1, 2)
    width = int(uv[:, 0].max()) + 2 if pixels else 0
    keys = np.sort(uv[:, 1] * width + uv[:, 0]).astype(np.float64)
    margin = TopParams().interior_margin_px
    # Random ones, and ones beyond the keys' columns and rows on every side.
    ellipses = _ellipses(rng, 12, 100.0, 100.0) + [
        Ellipse.of(cx, cy, 20.0, 12.0, 30.0)
        for cx, cy in ((300.0, 50.0), (-40.0, 50.0), (50.0, -30.0), (50.0, 130.0))]
    want = kernels.interior_counts(*_shrunk_forms(ellipses, margin), keys, width)
    got = kernels_pose.interior_counts_of(outline_rows(ellipses)[0], margin, keys, width)
    assert np.array_equal(got, want)
    assert want.sum() > 0 or pixels < 100


@pytest.mark.parametrize("order", ["row-major", "shuffled"])
def test_occlusion_counts_are_the_sorted_pixels_counts(rng: np.random.Generator,
                                                       order: str) -> None:
    # The evidence's counts in one call: the pixels in row-major order (sorted when they are
    # not), then the interior counts and the gap evidence on them.
    _, table, sizes, pts, ok = _sampled_outlines(rng, 6, 0.7)
    uv = np.unique(rng.integers(0, 80, (1200, 2)), axis=0)[:, ::-1].astype(np.float64)
    if order == "shuffled":
        uv = uv[rng.permutation(uv.shape[0])]
    pu, pv = np.ascontiguousarray(uv[:, 0]), np.ascontiguousarray(uv[:, 1])
    margin, tol, reach, junction, crossing = 2.5, 0.8, 4.0, 2.0, 4.0
    got = kernels_pose.occlusion_counts(ok, sizes, pts, table, pu, pv, margin, 3, reach,
                                        junction ** 2, crossing ** 2, tol)
    width = int(pu.max()) + 2
    keys = pv * width + pu
    by_row = np.argsort(keys, kind="stable")
    want = (*kernels_pose.gap_evidence(ok, sizes, pts, table, pu[by_row], pv[by_row], 3,
                                       reach, junction ** 2, crossing ** 2, tol),
            kernels_pose.interior_counts_of(table, margin, keys[by_row], width))
    assert [g.tolist() for g in got] == [w.tolist() for w in want]
    assert want[2].sum() > 0 and want[3].sum() > 0


def _cone_on_floats(e: Ellipse, camera: tuple[float, float, float, float]) -> list[float]:
    """The cone K^T C K's six entries, the ellipse's terms and the camera, on Python floats
    (the ellipse's pixel conic C: M = R diag(1/a^2, 1/b^2) R^T, d = -M c, f = -d.c - 1)."""
    fx, fy, kcx, kcy = camera
    t = math.radians(e.angle_deg)
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0 / e.a ** 2, 1.0 / e.b ** 2
    m00, m01, m11 = c * c * ia + s * s * ib, c * s * (ia - ib), s * s * ia + c * c * ib
    d0 = -(m00 * e.cx + m01 * e.cy)
    d1 = -(m01 * e.cx + m11 * e.cy)
    f = -(d0 * e.cx + d1 * e.cy) - 1.0
    r0, r1 = m00 * kcx + m01 * kcy + d0, m01 * kcx + m11 * kcy + d1
    q = [fx * fx * m00, fx * fy * m01, fx * r0, fy * fy * m11, fy * r1,
         kcx * r0 + kcy * r1 + (d0 * kcx + d1 * kcy + f)]
    return [*q, e.cx, e.cy, math.cos(t), math.sin(t), e.a ** 2, e.b ** 2, *camera]


def test_cone_of_is_the_float_arithmetic(rng: np.random.Generator) -> None:
    camera = (277.1, 276.3, 160.4, 119.8)
    ellipses = [*_ellipses(rng, 300, 320.0, 240.0),
                Ellipse.of(3.0, 4.0, 1e-60, 1e-61, 10.0)]  # entries beyond 1e100
    for e in ellipses:
        cone, packed, moderate = kernels_pose.cone_of(e.cx, e.cy, e.a ** 2, e.b ** 2,
                                                      e.angle_deg, *camera)
        want = _cone_on_floats(e, camera)
        q = want[:6]
        assert packed.tolist() == want
        assert cone.tolist() == [[q[0], q[1], q[2]], [q[1], q[3], q[4]], [q[2], q[4], q[5]]]
        assert moderate == all(abs(x) <= 1e100 for x in q)
    assert not moderate


def _axes(normal: np.ndarray) -> tuple[list[float], list[float]]:
    """The plane basis of a normal on Python floats (u = n x helper, normalised; v = n x u)."""
    norm = math.sqrt(sum(x * x for x in normal.tolist()))
    n0, n1, n2 = (x / norm for x in normal.tolist())
    u0, u1, u2 = (0.0, n2, -n1) if abs(n0) < 0.9 else (-n2, 0.0, n0)
    un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    u0, u1, u2 = u0 / un, u1 / un, u2 / un
    return [u0, u1, u2], [n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0]


def test_band_points_of_take_the_plane_basis_axes(rng: np.random.Generator) -> None:
    solutions = rng.normal(size=(6, 2, 3))
    solutions[:2, 0] = [[0.95, 0.1, 0.2], [0.05, -0.2, 0.97]]  # both helper axes
    ct, st = np.cos(np.arange(8) * 0.7), np.sin(np.arange(8) * 0.7)
    depths = np.array([0.0, 0.3, 1.1])
    axes = [_axes(n) for n, _ in solutions]
    vectors = np.array([[n.tolist() for n, _ in solutions], [c.tolist() for _, c in solutions],
                        [u for u, _ in axes], [v for _, v in axes]])
    assert np.array_equal(kernels_pose.band_points_of(solutions, ct, st, depths),
                          kernels.band_points(vectors, ct, st, depths))
    for (n, _), (u, v) in zip(solutions, axes, strict=True):
        got = plane_basis(n)
        assert got[0].tolist() == u and got[1].tolist() == v


@pytest.mark.parametrize("belt", [None, (90.0, 90.0, 95.0)])
def test_wall_hits_are_the_bands_then_their_colour_test(rng: np.random.Generator,
                                                        belt: tuple[float, ...] | None) -> None:
    k = CameraIntrinsics.from_fovy(45.0, 160, 120)
    image = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    image[rng.random((120, 160)) < 0.5] = (200, 90, 40)  # the face's colour at wall brightness
    face = np.array([240.0, 110.0, 50.0])
    params = PoseParams(band_brightness_margin=0.5)
    shares = []
    for e in _ellipses(rng, 5, 160.0, 120.0):
        unit = unit_circle_poses(e, k)
        solutions = [(s.normal_cam, s.centre_cam) for s in unit]
        pu, pv, keep = solution_bands(solutions, e, k, params.wall_depths,
                                      params.wall_margin_px)
        belt_rgb = None if belt is None else np.array(belt)
        want = band_evidences(pu.reshape(2, -1), pv.reshape(2, -1), keep.reshape(2, -1), image,
                              np.stack([face, face]), [tan_tilt(n, c) for n, c in solutions],
                              belt_rgb, params)
        assert wall_evidences(solutions, e, k, image, face, belt_rgb, params) == want
        shares += [w.share for w in want]
    assert 0.0 < max(shares) < 1.0

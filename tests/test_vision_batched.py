"""The batched stages (all ellipses or segments in one array pass) give what the one-at-a-time
forms give, on synthetic stacks of known ellipses."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from stackpick_sim.config.vision_params import SegmentParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_fit
from stackpick_sim.vision.contrast import contrast_profile, contrast_profiles, outline, outlines
from stackpick_sim.vision.edges import (
    adaptive_thresholds,
    edge_image,
    noise_level,
    remove_stairs,
)
from stackpick_sim.vision.fitting import (
    distances,
    ellipse_params,
    fit_all,
    fit_or_split,
    within,
    within_pairs,
)
from stackpick_sim.vision.merging import (
    SUPPORT_RADIUS_PX,
    MergedEllipse,
    merge_segments,
    support_map,
    support_shares,
)
from stackpick_sim.vision.occlusion import DEFAULT_TOP, OcclusionEvidence, evidence_all
from stackpick_sim.vision.refine import (
    MIN_NORMAL_COS,
    _along,
    _along_mask,
    _form,
    edge_points,
    refine_all,
)
from stackpick_sim.vision.roi import DEFAULT as ROI_DEFAULT
from stackpick_sim.vision.roi import decimate
from stackpick_sim.vision.segments import link_segments, neighbour_count, split_chain
from stackpick_sim.vision.synthetic import draw_ellipses
from stackpick_sim.vision.wall import column_median

SHAPE = (240, 320)
#: A stack of three overlapping faces (each drawn over the one before, in alternating greys)
#: and a small face apart.
STACK = [Ellipse(cx=140, cy=120, a=42, b=33, angle_deg=20),
         Ellipse(cx=185, cy=128, a=38, b=30, angle_deg=110),
         Ellipse(cx=218, cy=100, a=28, b=24, angle_deg=60),
         Ellipse(cx=265, cy=60, a=16, b=11, angle_deg=145)]


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, list[Ellipse]]:
    image = draw_ellipses(SHAPE, STACK, noise_sigma=2.0, rng=np.random.default_rng(3))
    # Probes: the truths, shifted copies (partly off the edges) and one leaving the image.
    probes = [*STACK,
              *(Ellipse(cx=e.cx + 1.7, cy=e.cy - 1.1, a=e.a + 0.8, b=e.b - 0.6,
                        angle_deg=e.angle_deg + 5.0) for e in STACK),
              Ellipse(cx=5.0, cy=8.0, a=20.0, b=12.0, angle_deg=30.0)]
    return image, probes


def test_outlines_are_each_ellipses_outline(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    _, probes = scene
    lines = outlines(probes)
    assert lines.offsets[-1] == lines.points.shape[0]
    for e, ellipse in enumerate(probes):
        pts, normals = outline(ellipse)
        part = slice(lines.offsets[e], lines.offsets[e + 1])
        np.testing.assert_allclose(lines.points[part], pts, atol=1e-9)
        np.testing.assert_allclose(lines.normals[part], normals, atol=1e-9)
        assert np.all(lines.owner[part] == e)


def test_contrast_profiles_match_one_at_a_time(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    grad = edge_image(image)
    lines = outlines(probes)
    batched = contrast_profiles(lines, grad)
    for e, ellipse in enumerate(probes):
        part = slice(lines.offsets[e], lines.offsets[e + 1])
        np.testing.assert_allclose(batched[part], contrast_profile(ellipse, grad), atol=1e-9)


def test_within_matches_full_distances(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    points, _ = edge_points(edge_image(image))
    params = ellipse_params(probes)
    for tol in (1.2, 1.5, 2.5):
        np.testing.assert_array_equal(within(params, points, tol),
                                      distances(params, points) < tol)
        e, n = within_pairs(params, points, tol)
        np.testing.assert_array_equal(np.stack([e, n]), np.stack(np.nonzero(
            distances(params, points) < tol)))


def test_noise_level_is_the_thresholds_noise(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, _ = scene
    grad = edge_image(image)
    assert noise_level(grad.gx, grad.gy) == adaptive_thresholds(grad.gx, grad.gy)[2]
    empty = np.zeros((0, 0), np.int16)
    assert noise_level(empty, empty) == adaptive_thresholds(empty, empty)[2] == 0.0


def test_fit_all_gives_fit_or_split_pieces_in_order(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, _ = scene
    chains = link_segments(edge_image(image).edges).chains
    # Add a line running into an arc: fails whole, fits after splitting.
    t = np.linspace(0.0, np.pi, 60)
    arc = np.stack([200 + 30 * np.cos(t), 150 + 20 * np.sin(t)], axis=1)
    line = np.stack([np.full(40, 230.0), np.linspace(110, 149, 40)], axis=1)
    mixed = np.rint(np.vstack([line, arc])).astype(np.int32)
    chains = (*chains, mixed)
    expected = [(i, pts, e) for i, c in enumerate(chains) for pts, e, _ in fit_or_split(c, SHAPE)]
    got = fit_all(chains, SHAPE)
    assert len(got) == len(expected) > len(STACK)
    for (i, pts, e, _), (j, pts2, e2) in zip(got, expected, strict=True):
        assert i == j
        np.testing.assert_array_equal(pts, pts2)
        assert e == e2


def test_refine_all_is_each_ellipse_refined_alone(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    points, grads = edge_points(edge_image(image))
    together = refine_all(probes, points, grads, SHAPE)
    alone = [refine_all([e], points, grads, SHAPE)[0] for e in probes]
    assert together == alone
    # And the refit pulled the shifted probes of the whole faces onto them.
    for k in (2, 3):
        truth, fit = STACK[k], together[len(STACK) + k]
        assert abs(fit.cx - truth.cx) < 0.3 and abs(fit.cy - truth.cy) < 0.3



def _rounds_one_by_one(given: np.ndarray, columns: tuple[np.ndarray, ...],
                       tolerances: tuple[float, ...], cos_sq: float, least: int,
                       bounds: tuple[float, float, float]) -> list[tuple[float, ...] | None]:
    """The refit rounds one compiled round at a time (kernels_fit.refit_round), the rounds'
    loop in Python: per ellipse its last refit that passed (cx, cy, a, b, angle deg), or
    None."""
    u, v = columns[0], columns[1]
    forms = kernels.ellipse_forms(given)
    reach = given[:, 2] + tolerances[0] + 1
    pm, starts = kernels.box_runs(u, v, forms[:, 0].copy(), forms[:, 1].copy(), reach)
    active = np.ones(given.shape[0], np.bool_)
    before = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    out: list[tuple[float, ...] | None] = [None] * given.shape[0]
    for tol in tolerances:
        sel, at, tried, rows, degrees, ok = kernels_fit.refit_round(
            forms, starts, active, pm, columns, (4.0 * tol * tol, cos_sq), before, least,
            bounds)
        before = (sel, at)
        for e, good, row, deg in zip(tried.tolist(), ok.tolist(), rows.tolist(),
                                     degrees.tolist(), strict=True):
            if good:
                out[e] = (*row[:4], deg)
        if not active.any():
            break
    return out


@pytest.mark.parametrize("tolerances", [(2.5, 1.5, 1.2), (3.0, 0.6), (1.2,)])
def test_refine_rounds_are_the_rounds_one_at_a_time(
        scene: tuple[np.ndarray, list[Ellipse]], tolerances: tuple[float, ...]) -> None:
    image, probes = scene
    points, grads = edge_points(edge_image(image))
    columns = tuple(np.ascontiguousarray(c) for c in (*points.T, *grads.T))
    rng = np.random.default_rng(11)
    # The probes and randomly moved copies of them (some too far off to refit).
    given = np.array([(e.cx, e.cy, e.a, e.b, e.angle_deg) for e in probes] * 4)
    given[len(probes):] += rng.normal(0.0, [2.0, 2.0, 1.5, 1.5, 8.0],
                                      (given.shape[0] - len(probes), 5))
    bounds = (4.0, 1.5 * float(np.hypot(*SHAPE)), 1e6)
    want = _rounds_one_by_one(given, columns, tolerances, 0.5, 20, bounds)
    final, changed = kernels_fit.refine_rounds(given, columns, np.array(tolerances), 0.5, 20,
                                               bounds)
    assert any(w is not None for w in want) and any(w is None for w in want)
    assert changed.tolist() == [w is not None for w in want]
    for e, w in enumerate(want):
        assert final[e].tolist() == (given[e].tolist() if w is None else list(w))


def test_refine_collects_the_pixels_along_each_fit(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, _ = scene
    points, grads = edge_points(edge_image(image))
    kept, _ = _along(STACK[0], points, grads, 1.5)
    # The face's visible outline: many pixels, all within the tolerance.
    assert kept.shape[0] > 100
    assert np.all(distances(ellipse_params([STACK[0]]), kept)[0] < 1.5)


def test_along_select_is_each_ellipses_mask(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    points, grads = edge_points(edge_image(image))
    n = points.shape[0]
    starts = np.arange(len(probes) + 1, dtype=np.int64) * n
    at = np.tile(np.arange(n, dtype=np.int64), len(probes))  # every pixel for each probe
    u, v, gu, gv = (np.ascontiguousarray(c) for c in (*points.T, *grads.T))
    forms = np.array([_form(e) for e in probes])
    for tol in (1.2, 2.5):
        expected = np.concatenate([_along_mask(e, *points.T, *grads.T, tol) for e in probes])
        sel, _, _ = kernels.along_select(forms, starts, np.ones(len(probes), np.bool_), at, u,
                                         v, gu, gv, 4.0 * tol * tol,
                                         MIN_NORMAL_COS * MIN_NORMAL_COS)
        np.testing.assert_array_equal(sel, expected.nonzero()[0])


def test_along_mask_is_the_sampson_distance_and_normal_angle_test() -> None:
    # The quadratic-form test, compared squared, against the distance and the angle written
    # out (Sampson distance as fitting.distances, unit normal of the implicit form).
    rng = np.random.default_rng(3)
    e = STACK[0]
    t = rng.uniform(0.0, 2.0 * np.pi, 4000)
    r = 1.0 + rng.uniform(-0.1, 0.1, t.size)
    th = np.radians(e.angle_deg)
    x, y = e.a * r * np.cos(t), e.b * r * np.sin(t)
    u = e.cx + np.cos(th) * x - np.sin(th) * y
    v = e.cy + np.sin(th) * x + np.cos(th) * y
    phi = rng.uniform(0.0, 2.0 * np.pi, t.size)
    gu, gv = np.cos(phi), np.sin(phi)
    pts = np.stack([u, v], axis=1)
    dist = distances(ellipse_params([e]), pts)[0]
    # The normal: the implicit form's gradient, in the ellipse's frame rotated back.
    xn = (np.cos(th) * (u - e.cx) + np.sin(th) * (v - e.cy)) / e.a ** 2
    yn = (-np.sin(th) * (u - e.cx) + np.cos(th) * (v - e.cy)) / e.b ** 2
    nu, nv = np.cos(th) * xn - np.sin(th) * yn, np.sin(th) * xn + np.cos(th) * yn
    cos = np.abs(nu * gu + nv * gv) / np.hypot(nu, nv)
    for tol in (1.2, 2.5):
        expected = (dist < tol) & (cos >= MIN_NORMAL_COS)
        assert 0 < expected.sum() < expected.size
        np.testing.assert_array_equal(_along_mask(e, u, v, gu, gv, tol), expected)


def test_merged_ellipse_of_equals_the_constructor() -> None:
    args = (STACK[0], (2, 5), 0.3, 0.75)
    made = MergedEllipse.of(*args)
    assert made == MergedEllipse(ellipse=args[0], segments=args[1], residual_px=args[2],
                                 support=args[3])
    assert hash(made) == hash(MergedEllipse(ellipse=args[0], segments=args[1],
                                            residual_px=args[2], support=args[3]))


def test_evidence_all_matches_one_at_a_time(scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    grad = edge_image(image)
    points, _ = edge_points(grad)
    together = evidence_all(probes, points, None, grad)
    alone = [evidence_all([e], points, None, grad)[0] for e in probes]
    assert together == tuple(alone)
    # The top face of the stack passes; the faces under it do not.
    assert not together[2].occluded and not together[3].occluded
    assert together[0].occluded and together[1].occluded


def test_evidence_all_is_the_same_in_any_pixel_order(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    grad = edge_image(image)
    points, _ = edge_points(grad)
    shuffled = points[np.random.default_rng(5).permutation(points.shape[0])]
    assert evidence_all(probes, shuffled, None, grad) == evidence_all(probes, points, None, grad)


def test_interior_edges_are_the_pixels_inside_the_shrunk_axes(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, probes = scene
    grad = edge_image(image)
    points, _ = edge_points(grad)
    # Also: an ellipse too small for its shrunk axes to span a row, and one off the image.
    tiny = Ellipse(cx=100.3, cy=50.4, a=2.6, b=2.55, angle_deg=10.0)
    off = Ellipse(cx=-30.0, cy=250.0, a=40.0, b=25.0, angle_deg=70.0)
    ellipses = [*probes, tiny, off]
    for e, ev in zip(ellipses, evidence_all(ellipses, points, None, grad), strict=True):
        inside = e.inside(points, DEFAULT_TOP.interior_margin_px)
        assert ev.interior_edge_px == np.count_nonzero(inside)


def test_occlusion_evidence_of_equals_the_constructor() -> None:
    for support, ends, inside in ((0.95, 0, 2), (0.95, 1, 0), (0.5, 0, 0), (0.95, 0, 40)):
        made = OcclusionEvidence.of(support, 12, ends, inside, 200)
        plain = OcclusionEvidence(support=support, longest_gap_px=12, occluded_ends=ends,
                                  interior_edge_px=inside, perimeter_px=200)
        assert made == plain and hash(made) == hash(plain) and repr(made) == repr(plain)
        assert made.occluded == bool(made.reason)


def test_neighbour_count_is_the_8_neighbour_sum() -> None:
    rng = np.random.default_rng(0)
    binary = (rng.random((40, 50)) < 0.3).astype(np.uint8)
    kernel = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.float32)
    expected = cv2.filter2D(binary, cv2.CV_8U, kernel, borderType=cv2.BORDER_CONSTANT)
    np.testing.assert_array_equal(neighbour_count(binary), expected)


@pytest.mark.parametrize("n", [1, 2, 5, 16, 251])
def test_column_median_is_numpys_median(n: int) -> None:
    values = np.random.default_rng(n).integers(0, 256, (n, 3)).astype(np.uint8)
    np.testing.assert_array_equal(column_median(values), np.median(values, axis=0))
    np.testing.assert_array_equal(column_median(values[:, 0]), np.median(values[:, 0]))


@pytest.mark.parametrize("channels", [1, 3])
def test_decimate_is_the_block_mean_within_a_grey_level(channels: int) -> None:
    rng = np.random.default_rng(channels)
    image = rng.integers(0, 256, (60, 84, channels)).astype(np.uint8).squeeze()
    small = decimate(image)
    side = ROI_DEFAULT.decimation
    blocks = image.reshape(60 // side, side, 84 // side, side, -1).mean(axis=(1, 3)).squeeze()
    assert small.shape[:2] == (60 // side, 84 // side)
    assert np.abs(small.astype(float) - blocks).max() <= 1.0


def test_merge_with_the_fits_residuals_gives_what_it_computes(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, _ = scene
    edges = edge_image(image).edges
    segs = link_segments(edges)
    found = fit_all(segs.chains, SHAPE)
    pieces = tuple(pts for _, pts, _, _ in found)
    fits = [(k, e) for k, (_, _, e, _) in enumerate(found)]
    chains = pieces + segs.chains
    given = merge_segments(chains, fits, edges, [r for *_, r in found])
    computed = merge_segments(chains, fits, edges)
    assert len(given) == len(computed) >= len(STACK)
    for m, n in zip(given, computed, strict=True):
        assert (m.ellipse, m.segments, m.support) == (n.ellipse, n.segments, n.support)
        assert m.residual_px == pytest.approx(n.residual_px, rel=1e-12)


def test_support_shares_on_the_edge_map_are_those_on_its_dilation(
        scene: tuple[np.ndarray, list[Ellipse]]) -> None:
    image, ellipses = scene
    edges = edge_image(image).edges
    grown = [Ellipse.of(e.cx + 0.7, e.cy - 0.4, e.a * 1.02, e.b, e.angle_deg + 3.0)
             for e in ellipses]
    on_map = support_shares(ellipses + grown, edges, SUPPORT_RADIUS_PX)
    assert np.array_equal(on_map, support_shares(ellipses + grown, support_map(edges)))
    assert on_map.max() > 0.5  # the scene's faces are supported


def _link_segments_reference(edges: np.ndarray, max_contours: int | None,
                             params: SegmentParams) -> list[np.ndarray]:
    """The chains of link_segments by OpenCV's box filters, a Python pass per contour and
    split_chain per chain (the form its compiled passes stand for)."""
    shortest = params.min_chain_px
    box = cv2.boxFilter(edges, cv2.CV_8U, (3, 3), normalize=False,
                        borderType=cv2.BORDER_CONSTANT)
    cut = cv2.threshold(box, 3, 1, cv2.THRESH_BINARY_INV)[1]
    cv2.bitwise_and(cut, edges, cut)
    box = cv2.boxFilter(cut, cv2.CV_8U, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    contours, hierarchy = cv2.findContours(cut, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return []
    kept = [c.reshape(-1, 2) for c, parent in zip(contours, hierarchy[0][:, 3], strict=True)
            if parent == -1 and c.shape[0] >= shortest]
    if max_contours is not None and len(kept) > max_contours:
        longest = sorted(range(len(kept)), key=lambda i: (-kept[i].shape[0], i))
        kept = [kept[i] for i in sorted(longest[:max_contours])]
    chains = []
    for pts in kept:
        ends = (box[pts[:, 1], pts[:, 0]] <= 2).nonzero()[0].tolist()
        if not ends:
            chain = pts
        elif len(ends) > 1:
            chain = pts[ends[0]:ends[1] + 1]
        else:
            chain = np.concatenate([pts[ends[0]:], pts[:ends[0]]])
        if chain.shape[0] >= shortest:
            chains += [arc for arc in split_chain(chain, not ends, params)
                       if arc.shape[0] >= shortest]
    return chains


@pytest.mark.parametrize("density", [0.0, 0.02, 0.15, 0.4])
def test_link_segments_matches_the_per_contour_form(
        scene: tuple[np.ndarray, list[Ellipse]], density: float) -> None:
    image, _ = scene
    edges = edge_image(image).edges.copy()
    rng = np.random.default_rng(int(density * 100))
    # Noise pixels: junctions, short pieces, small loops and closed rings.
    edges |= remove_stairs((rng.uniform(0, 1, edges.shape) < density).astype(np.uint8))
    for params, cap in ((SegmentParams(), None), (SegmentParams(), 7),
                        (SegmentParams(min_chain_px=3, poly_epsilon_px=0.5), None)):
        got = link_segments(edges, cap, params).chains
        want = _link_segments_reference(edges, cap, params)
        assert len(got) == len(want) > 0
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)

"""The top rule's compiled kernels: the arc-pair screen rejects only pairs the exact fit rejects,
its fit is the exact path's, and the inside test gives Ellipse.inside's flags."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels_top, regroup, rings
from stackpick_sim.vision.fitting import fit_ellipse
from stackpick_sim.vision.markings import rim_band
from stackpick_sim.vision.regroup import DEFAULT_SECTIONS, arc_pair_ellipses
from stackpick_sim.vision.wall import column_median

SHAPE = (240, 320)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(11)


def _arcs(rng: np.random.Generator, faces: int, per_face: int) -> list[NDArray[np.int32]]:
    """Noisy integer arcs (N, 2) int32 of a few random ellipses, several per ellipse."""
    arcs = []
    for _ in range(faces):
        cx, cy = rng.uniform(60, 260), rng.uniform(50, 190)
        a = rng.uniform(12, 70)
        b, th = a * rng.uniform(0.4, 1.0), rng.uniform(0, math.pi)
        for _ in range(per_face):
            t = rng.uniform(0, 2 * math.pi) + np.linspace(0, rng.uniform(0.3, 1.6),
                                                          int(rng.integers(8, 70)))
            x = cx + a * np.cos(t) * math.cos(th) - b * np.sin(t) * math.sin(th)
            y = cy + a * np.cos(t) * math.sin(th) + b * np.sin(t) * math.cos(th)
            noisy = np.stack([x, y], 1) + rng.normal(0, rng.uniform(0.0, 0.4), (t.size, 2))
            arcs.append(np.rint(noisy).astype(np.int32))
    return arcs


def _table(arcs: list[NDArray[np.int32]]
           ) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.int64]]:
    pixels = np.ascontiguousarray(np.concatenate(arcs), np.int32)
    starts = np.zeros(len(arcs) + 1, np.int64)
    np.cumsum([c.shape[0] for c in arcs], out=starts[1:])
    pairs = np.array([(i, j) for i in range(len(arcs)) for j in range(i + 1, len(arcs))],
                     np.int64)
    return pixels, starts, pairs


def test_screen_fit_is_the_exact_paths_ellipse(rng: np.random.Generator) -> None:
    arcs = _arcs(rng, 12, 4)
    pixels, starts, pairs = _table(arcs)
    union = np.empty_like(pixels)
    row, sums, work = np.empty((1, 5)), np.empty(15), np.empty((3, 3, 3))
    fitted = 0
    for i, j in pairs.tolist():
        ranges = np.array([starts[i], starts[i + 1], starts[j], starts[j + 1]], np.int64)
        cu, cv, major, minor, angle, ok = kernels_top._pair_fit(pixels, ranges, union, row,
                                                                sums, work)
        exact = fit_ellipse(np.concatenate([arcs[i], arcs[j]]))
        if not ok:
            continue
        assert exact is not None
        fitted += 1
        # The same fit of the same pixels in the same order: the same values.
        assert (cu, cv, major, minor) == (exact.cx, exact.cy, exact.a, exact.b)
        turn = (math.degrees(angle) - exact.angle_deg + 90.0) % 180.0 - 90.0
        assert abs(turn) < 1e-9
    assert fitted > 0.5 * len(pairs)


def test_screen_rejects_only_pairs_the_exact_checks_reject(rng: np.random.Generator) -> None:
    arcs = _arcs(rng, 10, 5)
    pixels, starts, pairs = _table(arcs)
    merge = DEFAULT_SECTIONS.merging
    for axis_range in ((8.0, 60.0), None):
        lo, hi = (0.0, math.inf) if axis_range is None else axis_range
        screen = kernels_top.pair_screen(pixels, starts, pairs, lo, hi, merge.tolerance_px,
                                         merge.max_residual_px, merge.absorb_fraction)
        exact = [regroup._pair_fit(np.concatenate([arcs[i], arcs[j]]), arcs[i].shape[0], SHAPE,
                                   axis_range, DEFAULT_SECTIONS) is not None
                 for i, j in pairs.tolist()]
        assert not any(ok and not kept for ok, kept in zip(exact, screen, strict=True))
        # Not vacuous: pairs pass, and most failing ones are screened out.
        assert sum(exact) > 10
        assert np.count_nonzero(~screen) > 0.5 * (len(exact) - sum(exact))


def test_arc_pair_ellipses_are_the_same_without_the_screen(rng: np.random.Generator,
                                                           monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    arcs = _arcs(rng, 6, 5)
    every = list(range(len(arcs)))
    screened = arc_pair_ellipses(arcs, every, SHAPE, (8.0, 80.0))
    monkeypatch.setattr(regroup, "_screened", lambda chains, arcs, pairs, *_: [True] * len(pairs))
    assert screened and screened == arc_pair_ellipses(arcs, every, SHAPE, (8.0, 80.0))


def test_inside_gives_the_ellipse_flags(rng: np.random.Generator) -> None:
    points = rng.uniform(0, 200, (4000, 2))
    for _ in range(50):
        e = Ellipse(cx=rng.uniform(50, 150), cy=rng.uniform(50, 150), a=rng.uniform(2, 80),
                    b=rng.uniform(1, 40), angle_deg=rng.uniform(0, 180))
        for margin in (0.0, 1.5, -1.5, 100.0):
            assert np.array_equal(kernels_top.inside(e, points, margin), e.inside(points, margin))


def test_bands_inside_matches_the_broadcast_form(rng: np.random.Generator) -> None:
    pu, pv = rng.uniform(0, 320, (12, 300)), rng.uniform(0, 240, (12, 300))
    keep = rng.random((12, 300)) < 0.7
    faces = np.column_stack([rng.uniform(50, 250, 6), rng.uniform(50, 200, 6),
                             *(lambda t: (np.cos(t), np.sin(t)))(rng.uniform(0, np.pi, 6)),
                             rng.uniform(5, 90, 6), rng.uniform(3, 60, 6)])
    cx, cy, c, s, a, b = faces.T[:, None, :, None]
    du, dv = pu[:, None, :] - cx, pv[:, None, :] - cy
    x = (c * du + s * dv) / a
    y = (-s * du + c * dv) / b
    expected = (x * x + y * y < 1.0) & keep[:, None, :]
    got = kernels_top.bands_inside(pu, pv, keep, np.ascontiguousarray(faces))
    assert expected.any() and np.array_equal(got, expected)


def test_two_part_medians_match_the_array_form(rng: np.random.Generator) -> None:
    image = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    both_seen = 0
    for _ in range(200):
        face = Ellipse(cx=rng.uniform(0, 160), cy=rng.uniform(0, 120), a=rng.uniform(8, 60),
                       b=rng.uniform(4, 40), angle_deg=rng.uniform(0, 180))
        inner = Ellipse(cx=face.cx + rng.normal(0, 10), cy=face.cy + rng.normal(0, 10),
                        a=face.a * rng.uniform(0.3, 1.2), b=face.b * rng.uniform(0.3, 1.2),
                        angle_deg=rng.uniform(0, 180))
        band, margin = rim_band(face), 1.5
        within, beyond = inner.inside(band, margin), ~inner.inside(band, -margin)
        t = math.radians(inner.angle_deg)
        both, own, other = kernels_top.two_part_medians(
            band, image, inner.cx, inner.cy, math.cos(t), math.sin(t),
            np.array([max(inner.a - margin, 1e-6), max(inner.b - margin, 1e-6)]),
            np.array([max(inner.a + margin, 1e-6), max(inner.b + margin, 1e-6)]), 4)
        assert both == (min(int(within.sum()), int(beyond.sum())) >= 4)
        if both:
            both_seen += 1
            pix = np.clip(np.rint(band).astype(np.int64), 0, [159, 119])
            colours = image[pix[:, 1], pix[:, 0]].astype(np.float64)
            assert np.array_equal(own, column_median(colours[within]))
            assert np.array_equal(other, column_median(colours[beyond]))
    assert both_seen > 20


def _hole_only_array_form(face: Ellipse, edge_points: NDArray[np.float64], margin_px: float,
                          hole_scale: float, hole_share: float) -> bool:
    """The ring test's array form (the reference of the compiled pass)."""
    u0, v0, u1, v1 = face.bounds()
    near = edge_points[(edge_points[:, 0] >= u0) & (edge_points[:, 0] <= u1)
                       & (edge_points[:, 1] >= v0) & (edge_points[:, 1] <= v1)]
    inside = near[face.inside(near, margin_px)]
    if not len(inside):
        return False
    t = math.radians(face.angle_deg)
    c, s = math.cos(t), math.sin(t)
    du, dv = inside[:, 0] - face.cx, inside[:, 1] - face.cy
    x = (c * du + s * dv) / face.a
    y = (-s * du + c * dv) / face.b
    return float(np.mean(x * x + y * y < hole_scale * hole_scale)) >= hole_share


def test_hole_only_matches_the_array_form(rng: np.random.Generator) -> None:
    # Edge pixels on a grid (integer, as the edge map's) and on hole-like rings.
    points = np.argwhere(rng.random((120, 160)) < 0.08)[:, ::-1].astype(np.float64)
    outcomes = set()
    for _ in range(300):
        face = Ellipse(cx=rng.uniform(0, 160), cy=rng.uniform(0, 120), a=rng.uniform(3, 60),
                       b=rng.uniform(2, 40), angle_deg=rng.uniform(0, 180))
        ring = Ellipse(cx=face.cx, cy=face.cy, a=face.a * 0.2, b=face.b * 0.2,
                       angle_deg=face.angle_deg).points(40)
        pts = np.rint(np.concatenate([points, ring]))
        for margin, scale, share in ((1.5, 0.3, 0.8), (0.0, 0.5, 0.1), (3.0, 0.25, 0.5)):
            got = rings.hole_only(face, np.asfortranarray(pts), margin, scale, share)
            assert got == _hole_only_array_form(face, pts, margin, scale, share)
            outcomes.add(got)
    assert outcomes == {True, False}

"""Compiled loops of the top rule (numba; see :mod:`~stackpick_sim.vision.kernels` for how
kernels are compiled and cached): the screen of its arc pairs, its inside tests (of
markings and of the wall bands' cover) and the two-surface test's colours.

:func:`~stackpick_sim.vision.regroup.arc_pair_ellipses` fits an ellipse to each pair of arcs
with the direct fit and keeps it only when both arcs lie on it (the merge's residual and
share checks). Most pairs fail those checks, which the exact path reads in Python.
:func:`pair_screen` makes the same fit (:mod:`~stackpick_sim.vision.kernels_fit`'s, on the
pair's pixels in the same order, so the same ellipse) for every pair in one compiled pass and
marks the pairs that clearly fail the checks: the checks are read with
:data:`SCREEN_MARGIN_PX` of slack on distances and axes, so a pair marked failing is one the
exact path rejects too. A fit that is not an ellipse leaves its pair to the exact path.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels_fit
from stackpick_sim.vision.kernels import _compiled

#: Slack (px) on the screen's distances, residual and axis bounds: far beyond the rounding
#: differences between the screen's Sampson distances (by reciprocals) and the exact checks'
#: (~1e-9 px), far below the checks' own scales (tenths of a pixel).
SCREEN_MARGIN_PX = 1e-3
#: Relative slack on the screen's axis bounds.
SCREEN_REL = 1e-6


@_compiled
def _pair_fit(pixels: NDArray[np.int32], ranges: NDArray[np.int64], union: NDArray[np.int32],
              row: NDArray[np.float64], sums: NDArray[np.float64], work: NDArray[np.float64]
              ) -> tuple[float, float, float, float, float, bool]:  # pragma: no cover
    """The direct fit (:mod:`~stackpick_sim.vision.kernels_fit`'s, the one the exact path
    makes) of the pixels in the index ranges (lo0, hi0, lo1, hi1) of (N, 2) ``pixels``, in
    that order, copied into the scratch ``union``: (cu, cv, major semi-axis, minor semi-axis,
    angle of the major axis rad), and whether it is an ellipse (otherwise the values are not
    to be used); ``row`` (1, 5), ``sums`` and ``work``: kernels_fit's scratch space."""
    m = 0
    for r in range(2):
        for k in range(ranges[2 * r], ranges[2 * r + 1]):
            union[m, 0], union[m, 1] = pixels[k, 0], pixels[k, 1]
            m += 1
    kernels_fit._fit_into(union, 0, m, row, 0, sums, work)
    cu, cv, w, h, angle = row[0, 0], row[0, 1], row[0, 2], row[0, 3], row[0, 4]
    ok = (math.isfinite(cu) and math.isfinite(cv) and math.isfinite(h) and math.isfinite(w)
          and w > 0.0 and math.isfinite(angle))
    return cu, cv, h / 2.0, w / 2.0, math.radians(angle + 90.0), ok


@_compiled
def pair_screen(pixels: NDArray[np.int32], starts: NDArray[np.int64],
                pairs: NDArray[np.int64], axis_lo: float, axis_hi: float, tol_px: float,
                max_residual_px: float, share: float
                ) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    """For each pair (i, j) of ``pairs`` (P, 2), of arcs given as the rows starts[i] to
    starts[i + 1] of (N, 2) ``pixels``: False when the pair's direct fit clearly fails the
    checks of :func:`~stackpick_sim.vision.regroup._pair_fit` (semi-major axis within
    [``axis_lo``, ``axis_hi``], RMS Sampson distance at most ``max_residual_px``, a ``share``
    of each arc's pixels closer than ``tol_px``), True when it may pass (see the module
    docstring)."""
    out = np.ones(pairs.shape[0], np.bool_)
    ranges = np.empty(4, np.int64)
    union = np.empty_like(pixels)
    row, sums, work = np.empty((1, 5)), np.empty(15), np.empty((3, 3, 3))
    slack = SCREEN_MARGIN_PX
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        ranges[0], ranges[1], ranges[2], ranges[3] = starts[i], starts[i + 1], starts[j], \
            starts[j + 1]
        n_first, n_second = ranges[1] - ranges[0], ranges[3] - ranges[2]
        if n_first + n_second < 5:
            continue
        cu, cv, major, minor, angle, ok = _pair_fit(pixels, ranges, union, row, sums, work)
        if not ok:
            continue
        if (major < axis_lo * (1.0 - SCREEN_REL) - slack
                or major > axis_hi * (1.0 + SCREEN_REL) + slack):
            out[p] = False
            continue
        # The Sampson distances (kernels._sampson's, by reciprocals: a screen's precision),
        # stopping once the residual alone fails.
        c, s = math.cos(angle), math.sin(angle)
        ia, ib = 1.0 / major, 1.0 / minor
        m = n_first + n_second
        limit = (max_residual_px + slack) ** 2 * m
        total = 0.0
        near = np.zeros(2, np.int64)
        for r in range(2):
            for k in range(ranges[2 * r], ranges[2 * r + 1]):
                du, dv = pixels[k, 0] - cu, pixels[k, 1] - cv
                x, y = (c * du + s * dv) * ia, (c * dv - s * du) * ib
                xa, yb = x * ia, y * ib
                grad = 2.0 * math.sqrt(xa * xa + yb * yb) + 1e-12
                q = abs(x * x + y * y - 1.0)
                total += (q / grad) ** 2
                if total > limit:
                    break
                if q < (tol_px + slack) * grad:
                    near[r] += 1
        near_first, near_second = near[0], near[1]
        out[p] = not (total > limit or near_first < share * n_first
                      or near_second < share * n_second)
    return out


@_compiled
def inside_mask(points: NDArray[np.float64], cx: float, cy: float, c: float, s: float,
                a_shrunk: float, b_shrunk: float) -> NDArray[np.bool_]:  # pragma: no cover
    """:meth:`~stackpick_sim.geometry.Ellipse.inside` of (M, 2) ``points`` for the ellipse
    centred at (cx, cy) of angle cosine and sine (c, s) and axes already shrunk by the margin
    (and floored as there): the same arithmetic, point by point."""
    out = np.empty(points.shape[0], np.bool_)
    for k in range(points.shape[0]):
        du, dv = points[k, 0] - cx, points[k, 1] - cy
        x = (c * du + s * dv) / a_shrunk
        y = (-s * du + c * dv) / b_shrunk
        out[k] = x * x + y * y < 1.0
    return out


@_compiled
def hole_counts(pu: NDArray[np.float64], pv: NDArray[np.float64],
                box: tuple[float, float, float, float], cx: float, cy: float, c: float,
                s: float, shrunk: tuple[float, float], axes: tuple[float, float],
                hole_sq: float) -> tuple[int, int]:  # pragma: no cover - compiled
    """Of the points (``pu``, ``pv``) within the ``box`` (u0, v0, u1, v1; bounds included):
    how many lie inside the ellipse centred at (cx, cy) of angle cosine and sine (c, s) with
    the ``shrunk`` axes (:meth:`~stackpick_sim.geometry.Ellipse.inside`'s arithmetic, the
    margin already taken off and floored), and how many of those lie inside its concentric
    ellipse of squared scale ``hole_sq`` (x^2 + y^2 < hole_sq in its unshrunk ``axes``); see
    :func:`~stackpick_sim.vision.rings.hole_only` (the same tests, point by point)."""
    u0, v0, u1, v1 = box
    inside = in_hole = 0
    for k in range(pu.shape[0]):
        u, v = pu[k], pv[k]
        if not (u >= u0 and u <= u1 and v >= v0 and v <= v1):
            continue
        du, dv = u - cx, v - cy
        x = (c * du + s * dv) / shrunk[0]
        y = (-s * du + c * dv) / shrunk[1]
        if not x * x + y * y < 1.0:
            continue
        inside += 1
        x = (c * du + s * dv) / axes[0]
        y = (-s * du + c * dv) / axes[1]
        if x * x + y * y < hole_sq:
            in_hole += 1
    return inside, in_hole


@_compiled
def bands_inside(pu: NDArray[np.float64], pv: NDArray[np.float64], keep: NDArray[np.bool_],
                 faces: NDArray[np.float64]) -> NDArray[np.bool_]:  # pragma: no cover
    """(S, n, P): whether band point p of row s (pixels ``pu``, ``pv`` (S, P), kept where
    ``keep``) lies inside face j, of rows (cx, cy, cos, sin, shrunk a, shrunk b) (n, 6), by
    :meth:`~stackpick_sim.geometry.Ellipse.inside`'s arithmetic (the broadcast form of
    :func:`~stackpick_sim.vision.wall_cover.solution_shares`, without its temporaries)."""
    n_rows, n_pts = pu.shape
    out = np.zeros((n_rows, faces.shape[0], n_pts), np.bool_)
    for j in range(faces.shape[0]):
        cx, cy, c, s, a, b = (faces[j, 0], faces[j, 1], faces[j, 2], faces[j, 3], faces[j, 4],
                              faces[j, 5])
        for r in range(n_rows):
            for k in range(n_pts):
                if keep[r, k]:
                    du, dv = pu[r, k] - cx, pv[r, k] - cy
                    x = (c * du + s * dv) / a
                    y = (-s * du + c * dv) / b
                    out[r, j, k] = x * x + y * y < 1.0
    return out


@_compiled
def _channel_medians(colours: NDArray[np.float64], take: NDArray[np.bool_]
                     ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.wall.column_median` of the rows ``take`` of (N, C)
    ``colours`` (at least one): each column sorted, the mean of its middle two."""
    n = int(np.count_nonzero(take))
    out = np.empty(colours.shape[1])
    column = np.empty(n)
    for ch in range(colours.shape[1]):
        k = 0
        for r in range(colours.shape[0]):
            if take[r]:
                column[k] = colours[r, ch]
                k += 1
        column.sort()
        out[ch] = 0.5 * (column[(n - 1) // 2] + column[n // 2])
    return out


@_compiled
def two_part_medians(band: NDArray[np.float64], image: NDArray[np.uint8], cx: float, cy: float,
                     c: float, s: float, within_axes: NDArray[np.float64],
                     beyond_axes: NDArray[np.float64], least: int
                     ) -> tuple[bool, NDArray[np.float64], NDArray[np.float64]]:  # pragma: no cover
    """The two parts of :func:`~stackpick_sim.vision.markings.two_surfaces`: of the (N, 2)
    ``band`` points, those inside the ellipse (centre, angle cosine and sine, shrunk axes
    ``within_axes``) and those not inside it at ``beyond_axes`` (Ellipse.inside's
    arithmetic); when both number at least ``least``, True and each part's median colour in
    the (H, W, C) ``image`` at the points rounded and clamped into it (column_median's
    values)."""
    n = band.shape[0]
    within = np.empty(n, np.bool_)
    beyond = np.empty(n, np.bool_)
    for k in range(n):
        du, dv = band[k, 0] - cx, band[k, 1] - cy
        xc, yc = c * du + s * dv, -s * du + c * dv
        x, y = xc / within_axes[0], yc / within_axes[1]
        within[k] = x * x + y * y < 1.0
        x, y = xc / beyond_axes[0], yc / beyond_axes[1]
        beyond[k] = not x * x + y * y < 1.0
    empty = np.zeros(image.shape[2])
    if min(np.count_nonzero(within), np.count_nonzero(beyond)) < least:
        return False, empty, empty
    h, w = image.shape[0], image.shape[1]
    colours = np.empty((n, image.shape[2]))
    for k in range(n):
        u = min(max(int(np.rint(band[k, 0])), 0), w - 1)
        v = min(max(int(np.rint(band[k, 1])), 0), h - 1)
        for ch in range(image.shape[2]):
            colours[k, ch] = float(image[v, u, ch])
    return True, _channel_medians(colours, within), _channel_medians(colours, beyond)


def inside(ellipse: Ellipse, points: NDArray[np.float64], margin_px: float = 0.0
           ) -> NDArray[np.bool_]:
    """``ellipse.inside(points, margin_px)`` (the same flags) in one compiled pass, for the
    top rule's many tests on a few dozen outline points."""
    t = math.radians(ellipse.angle_deg)
    return inside_mask(np.ascontiguousarray(points, np.float64), ellipse.cx, ellipse.cy,
                       math.cos(t), math.sin(t), max(ellipse.a - margin_px, 1e-6),
                       max(ellipse.b - margin_px, 1e-6))


def warm_up() -> None:
    """Compile (or load from the cache) the kernels for the argument types the detector
    passes."""
    pixels = np.array([[0, 0], [4, 1], [6, 4], [4, 7], [0, 8], [-4, 7]], np.int32)
    pair_screen(pixels, np.array([0, 3, 6], np.int64), np.array([[0, 1]], np.int64), 0.0,
                math.inf, 1.0, 1.0, 0.5)
    shared = np.zeros((1, 2))  # the cached outlines and rim bands are read-only
    shared.setflags(write=False)
    for points in (np.zeros((1, 2)), shared):
        inside_mask(points, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0)
    bands_inside(np.zeros((1, 1)), np.zeros((1, 1)), np.ones((1, 1), np.bool_),
                 np.ones((1, 6)))
    hole_counts(np.zeros(1), np.zeros(1), (0.0, 0.0, 1.0, 1.0), 0.0, 0.0, 1.0, 0.0,
                (1.0, 1.0), (1.0, 1.0), 1.0)
    two_part_medians(shared, np.zeros((2, 2, 3), np.uint8), 0.0, 0.0, 1.0, 0.0, np.ones(2),
                     np.ones(2), 1)

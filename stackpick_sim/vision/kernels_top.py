"""Compiled loops of the top rule (numba; see :mod:`~stackpick_sim.vision.kernels` for how
kernels are compiled and cached): the screen of its arc pairs, its inside tests (of
markings and of the wall bands' cover) and the two-surface test's colours.

:func:`~stackpick_sim.vision.regroup.arc_pair_ellipses` fits an ellipse to each pair of arcs
with OpenCV's direct fit and keeps it only when both arcs lie on it (the merge's residual and
share checks). Most pairs fail those checks, and the OpenCV call costs more than everything
else done per pair. :func:`pair_screen` solves the same least-squares problem (Fitzgibbon's
direct fit, as Halir and Flusser's reduced 3x3 eigenproblem, on OpenCV's centred and scaled
coordinates) for every pair in one compiled pass and marks the pairs that clearly fail the
checks: their ellipse, up to rounding, is the one OpenCV fits, and the checks are read with
:data:`SCREEN_MARGIN_PX` of slack on distances and axes, so a pair marked failing is one the
exact path rejects too. Wherever the problem is near-singular (the cases OpenCV perturbs or
hands to another fit), its eigenvalues or the choice of its ellipse solution are not clearly
apart, or the conic is not a real ellipse, the pair is left to the exact path.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.kernels import _compiled

#: Slack (px) on the screen's distances, residual and axis bounds: far beyond the rounding
#: differences between the screen's fit and OpenCV's (float32 results, ~1e-5 px on these
#: images), far below the checks' own scales (tenths of a pixel).
SCREEN_MARGIN_PX = 1e-3
#: Relative slack on the axis bounds and least relative gap between the eigenvalues (and
#: between the two best ellipse solutions) for the screen to decide a pair.
SCREEN_REL = 1e-6
#: OpenCV takes the fit as singular at |det M| <= 1e-10 (and then perturbs the points or
#: fits otherwise); the screen leaves pairs below twice that to the exact path.
SINGULAR_DET = 2e-10


@_compiled
def _scatter(pixels: NDArray[np.int32], ranges: NDArray[np.int64]
             ) -> tuple[NDArray[np.float64], float, float, float]:  # pragma: no cover
    """The 6x6 scatter matrix (over the point count) of the design rows (x^2, xy, y^2, x, y, 1)
    of the pixels in the two index ranges ``ranges`` = (lo0, hi0, lo1, hi1), on OpenCV's
    coordinates (centred on the mean, scaled to a mean absolute deviation of 100 / n); and
    the centre (cu, cv) and the scale."""
    n = 0
    su = sv = 0.0
    for r in range(2):
        for k in range(ranges[2 * r], ranges[2 * r + 1]):
            su += float(pixels[k, 0])
            sv += float(pixels[k, 1])
            n += 1
    cu, cv = su / n, sv / n
    spread = 0.0
    for r in range(2):
        for k in range(ranges[2 * r], ranges[2 * r + 1]):
            spread += abs(pixels[k, 0] - cu) + abs(pixels[k, 1] - cv)
    scale = 100.0 / max(spread, 1.1920928955078125e-07)
    # The entries are the moments x^p y^q (p + q <= 4) of the scaled points: 14 sums.
    m40 = m31 = m22 = m13 = m04 = m30 = m21 = m12 = m03 = m20 = m11 = m02 = m10 = m01 = 0.0
    for r in range(2):
        for k in range(ranges[2 * r], ranges[2 * r + 1]):
            x, y = (pixels[k, 0] - cu) * scale, (pixels[k, 1] - cv) * scale
            xx, xy, yy = x * x, x * y, y * y
            m40 += xx * xx
            m31 += xx * xy
            m22 += xx * yy
            m13 += xy * yy
            m04 += yy * yy
            m30 += xx * x
            m21 += xx * y
            m12 += x * yy
            m03 += yy * y
            m20 += xx
            m11 += xy
            m02 += yy
            m10 += x
            m01 += y
    dm = np.empty((6, 6))
    entries = ((m40, m31, m22, m30, m21, m20), (m31, m22, m13, m21, m12, m11),
               (m22, m13, m04, m12, m03, m02), (m30, m21, m12, m20, m11, m10),
               (m21, m12, m03, m11, m02, m01), (m20, m11, m02, m10, m01, float(n)))
    for i in range(6):
        for j in range(6):
            dm[i, j] = entries[i][j] / n
    return dm, cu, cv, scale


@_compiled
def _inverse3(m: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:  # pragma: no cover
    """The inverse of a 3x3 matrix (by its adjugate) and its determinant."""
    inv = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r0, r1 = (j + 1) % 3, (j + 2) % 3
            c0, c1 = (i + 1) % 3, (i + 2) % 3
            inv[i, j] = m[r0, c0] * m[r1, c1] - m[r0, c1] * m[r1, c0]
    det = m[0, 0] * inv[0, 0] + m[0, 1] * inv[1, 0] + m[0, 2] * inv[2, 0]
    return inv / det, det


@_compiled
def _reduced(dm: NDArray[np.float64]
             ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:  # pragma: no cover
    """Halir and Flusser's reduction of the direct fit: the 3x3 matrix M whose eigenvector
    (A, B, C) with 4AC - B^2 > 0 is the quadratic part of the conic, and T giving its linear
    part (D, E, F) = T (A, B, C); False when the linear block is singular. (Loops rather than
    ``@``: on 3x3 blocks the BLAS call costs more than the arithmetic.)"""
    s3 = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s3[i, j] = dm[3 + i, 3 + j]
    inv3, det3 = _inverse3(s3)
    m = np.zeros((3, 3))
    t = np.zeros((3, 3))
    if not (math.isfinite(det3) and det3 != 0.0):
        return m, t, False
    for i in range(3):  # T = -S3^-1 S2^T, S2 = dm[:3, 3:]
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += inv3[i, k] * dm[j, 3 + k]
            t[i, j] = -acc
    full = np.empty((3, 3))
    for i in range(3):  # S1 + S2 T
        for j in range(3):
            acc = dm[i, j]
            for k in range(3):
                acc += dm[i, 3 + k] * t[k, j]
            full[i, j] = acc
    for j in range(3):  # C1^-1 (S1 + S2 T) with C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]
        m[0, j], m[1, j], m[2, j] = full[2, j] / 2.0, -full[1, j], full[0, j] / 2.0
    return m, t, True


@_compiled
def _real_roots(m: NDArray[np.float64]) -> tuple[NDArray[np.float64], bool]:  # pragma: no cover
    """The eigenvalues of a 3x3 matrix, ascending, when all three are real and clearly apart
    (relative gaps above :data:`SCREEN_REL`, each refined by Newton steps); else False."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    c1 = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0] + m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]
          + m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    roots = np.zeros(3)
    # lambda^3 - tr lambda^2 + c1 lambda - det, shifted by tr / 3: t^3 + p t + q.
    shift = tr / 3.0
    p = c1 - tr * tr / 3.0
    q = -2.0 * tr ** 3 / 27.0 + tr * c1 / 3.0 - det
    if not (p < 0.0 and math.isfinite(q)):
        return roots, False
    r = math.sqrt(-p / 3.0)
    arg = 3.0 * q / (2.0 * p * r)
    if not -1.0 < arg < 1.0:
        return roots, False
    phi = math.acos(arg) / 3.0
    for k in range(3):
        x = 2.0 * r * math.cos(phi - 2.0 * math.pi * k / 3.0) + shift
        for _ in range(2):
            f = ((x - tr) * x + c1) * x - det
            g = (3.0 * x - 2.0 * tr) * x + c1
            if g != 0.0:
                x -= f / g
        roots[k] = x
    roots.sort()
    size = max(abs(roots[0]), abs(roots[2]))
    ok = (roots[1] - roots[0] > SCREEN_REL * size and roots[2] - roots[1] > SCREEN_REL * size)
    return roots, ok


@_compiled
def _null_vector(m: NDArray[np.float64], lam: float
                 ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The unit vector spanning the null space of M - lam I (the largest cross product of two
    of its rows)."""
    best = (0.0, 0.0, 0.0)
    best_norm = 0.0
    for i, j in ((0, 1), (0, 2), (1, 2)):
        a0, a1, a2 = m[i, 0], m[i, 1], m[i, 2]
        b0, b1, b2 = m[j, 0], m[j, 1], m[j, 2]
        if i == 0:
            a0 -= lam
        else:
            a1 -= lam
        if j == 1:
            b1 -= lam
        else:
            b2 -= lam
        v = (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
        norm = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if norm > best_norm:
            best, best_norm = v, norm
    if best_norm == 0.0:
        return best
    return best[0] / best_norm, best[1] / best_norm, best[2] / best_norm


@_compiled
def _conic(m: NDArray[np.float64]
           ) -> tuple[float, float, float, bool]:  # pragma: no cover - compiled
    """The eigenvector (A, B, C) of M with the largest 4AC - B^2 (unit length), as OpenCV
    chooses it, when the choice is clear (all eigenvalues real and apart, the best value
    positive and clearly above the next); else False."""
    roots, ok = _real_roots(m)
    if not ok:
        return 0.0, 0.0, 0.0, False
    best = second = -np.inf
    out = (0.0, 0.0, 0.0)
    for k in range(3):
        v = _null_vector(m, roots[k])
        cond = 4.0 * v[0] * v[2] - v[1] * v[1]
        if cond > best:
            best, second, out = cond, best, v
        elif cond > second:
            second = cond
    return out[0], out[1], out[2], best > 0.0 and best - second > SCREEN_REL


@_compiled
def direct_fit(pixels: NDArray[np.int32], ranges: NDArray[np.int64]
               ) -> tuple[float, float, float, float, float, bool]:  # pragma: no cover
    """Fitzgibbon's direct ellipse fit of the pixels in the index ranges (lo0, hi0, lo1, hi1)
    of (N, 2) ``pixels``: (cu, cv, major semi-axis, minor semi-axis, angle of the major axis
    rad), and whether it is decided clearly (see the module docstring; otherwise the values
    are not to be used)."""
    dm, cu, cv, scale = _scatter(pixels, ranges)
    m, t, ok = _reduced(dm)
    if not ok:
        return 0.0, 0.0, 0.0, 0.0, 0.0, False
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    if not abs(det) > SINGULAR_DET:
        return 0.0, 0.0, 0.0, 0.0, 0.0, False
    big_a, big_b, big_c, ok = _conic(m)
    if not ok:
        return 0.0, 0.0, 0.0, 0.0, 0.0, False
    if big_a + big_c < 0.0:
        big_a, big_b, big_c = -big_a, -big_b, -big_c
    big_d = t[0, 0] * big_a + t[0, 1] * big_b + t[0, 2] * big_c
    big_e = t[1, 0] * big_a + t[1, 1] * big_b + t[1, 2] * big_c
    big_f = t[2, 0] * big_a + t[2, 1] * big_b + t[2, 2] * big_c
    disc = 4.0 * big_a * big_c - big_b * big_b
    x0 = (big_b * big_e - 2.0 * big_c * big_d) / disc
    y0 = (big_b * big_d - 2.0 * big_a * big_e) / disc
    f0 = (big_a * x0 * x0 + big_b * x0 * y0 + big_c * y0 * y0 + big_d * x0 + big_e * y0
          + big_f)
    half = math.sqrt(((big_a - big_c) / 2.0) ** 2 + (big_b / 2.0) ** 2)
    mu_lo, mu_hi = (big_a + big_c) / 2.0 - half, (big_a + big_c) / 2.0 + half
    if not (mu_lo > 0.0 and f0 < 0.0):
        return 0.0, 0.0, 0.0, 0.0, 0.0, False
    major, minor = math.sqrt(-f0 / mu_lo) / scale, math.sqrt(-f0 / mu_hi) / scale
    angle = 0.5 * math.atan2(big_b, big_a - big_c) + math.pi / 2.0
    out_ok = math.isfinite(major) and math.isfinite(minor) and minor > 0.0
    return x0 / scale + cu, y0 / scale + cv, major, minor, angle, out_ok


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
    slack = SCREEN_MARGIN_PX
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        ranges[0], ranges[1], ranges[2], ranges[3] = starts[i], starts[i + 1], starts[j], \
            starts[j + 1]
        n_first, n_second = ranges[1] - ranges[0], ranges[3] - ranges[2]
        if n_first + n_second < 5:
            continue
        cu, cv, major, minor, angle, ok = direct_fit(pixels, ranges)
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

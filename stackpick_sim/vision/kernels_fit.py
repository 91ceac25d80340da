"""Compiled direct least-squares ellipse fit (numba; see :mod:`~stackpick_sim.vision.kernels`
for how kernels are compiled and cached).

Fitzgibbon, Pilu and Fisher's direct fit ("Direct least square fitting of ellipses", 1999)
minimises the algebraic error of the conic ``A x^2 + B x y + C y^2 + D x + E y + F = 0`` over
the points under the constraint ``4 A C - B^2 = 1``, so what it returns is always an ellipse:
the condition ``A B - H^2 > 0`` of Eq. 2 of "Pose Estimation of Top Object on Stack of
Elliptical Objects Based on Ellipse Fitting and Kalman Estimator" (with B = 2H). It is
computed here in Halir and Flusser's numerically stable form ("Numerically stable direct least
squares fitting of ellipses", 1998): the points are centred on their mean and scaled into
[-1, 1], the scatter matrix is split into its quadratic and linear blocks, the linear part is
eliminated (a 3x3 solve), and the quadratic part is the eigenvector of the reduced 3x3 problem
whose ``4 A C - B^2`` is positive (its characteristic cubic solved in closed form, each root
polished, the eigenvector a cross product of two rows). The conic's centre, full axes and
angle follow in closed form.

The result is given as ``cv2.fitEllipseDirect`` gives it (a ``cv2.RotatedRect``): centre
(u, v), full axes (w, h) with w the minor one (w <= h), and the angle in degrees of the w axis
from the u axis in [0, 180] (180 where a float64 angle just below it rounds up), each computed
in float64 and rounded to float32 as OpenCV's fields are: the same rows as OpenCV's, bar a
float32 step where a value lies on a rounding boundary. The points are read as float32 (the
values OpenCV fits: int32 pixels exactly, float64 points rounded); many point sets are fitted
in one call (:func:`direct_rows`), which is where the time goes: a call of OpenCV's costs
several microseconds before the first point.

A fit that is not an ellipse gives a row that :func:`~stackpick_sim.vision.kernels.fit_checks`
rejects: zero axes when fewer than five points are given or they all coincide (OpenCV's own
answer to coincident points: their centre, zero axes, angle 0), NaN where the reduced problem
has no ellipse-specific eigenvector (points on a line, or pixels in two rows or columns: a
pair of lines fits them exactly) or the conic is an imaginary ellipse, extreme axis ratios
where rounding leaves a sliver. OpenCV gives other values on those inputs (a sliver about a
pixel wide for pixels in two rows), rejected as well by the fits' checks and axis bounds.
Fewer than five distinct points determine no conic: what either fit gives them is arbitrary
(the detector's point sets are chains of distinct pixels, ten or more).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.vision import kernels
from stackpick_sim.vision.kernels import _compiled

#: Newton steps that polish each root of the reduced problem's characteristic cubic (the
#: closed form's roots are within a few rounding errors; two steps reach float64's limit).
_POLISH_STEPS = 2


@_compiled
def _moments(points: NDArray, lo: int, hi: int, out: NDArray[np.float64]
             ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The mean (mu, mv) and scale (largest absolute offset from it) of ``points[lo:hi]``
    (at least one point) read as float32; ``out`` (15,) receives the sums over the centred,
    scaled points (x, y) of x^4, x^3 y, x^2 y^2, x y^3, y^4, x^3, x^2 y, x y^2, y^3, x^2,
    x y, y^2, x, y, 1."""
    su, sv = 0.0, 0.0
    u0, u1 = np.inf, -np.inf
    v0, v1 = np.inf, -np.inf
    for j in range(lo, hi):
        u, v = np.float64(np.float32(points[j, 0])), np.float64(np.float32(points[j, 1]))
        su += u
        sv += v
        u0, u1, v0, v1 = min(u0, u), max(u1, u), min(v0, v), max(v1, v)
    n = hi - lo
    mu, mv = su / n, sv / n
    scale = max(u1 - mu, mu - u0, v1 - mv, mv - v0)
    out[:] = 0.0
    if scale == 0.0:
        return mu, mv, scale
    inv = 1.0 / scale
    m0 = m1 = m2 = m3 = m4 = m5 = m6 = m7 = m8 = m9 = m10 = m11 = m12 = m13 = 0.0
    for j in range(lo, hi):
        x = (np.float64(np.float32(points[j, 0])) - mu) * inv
        y = (np.float64(np.float32(points[j, 1])) - mv) * inv
        xx, xy, yy = x * x, x * y, y * y
        m0 += xx * xx
        m1 += xx * xy
        m2 += xx * yy
        m3 += xy * yy
        m4 += yy * yy
        m5 += xx * x
        m6 += xx * y
        m7 += xy * y
        m8 += yy * y
        m9 += xx
        m10 += xy
        m11 += yy
        m12 += x
        m13 += y
    out[0], out[1], out[2], out[3], out[4] = m0, m1, m2, m3, m4
    out[5], out[6], out[7], out[8], out[9] = m5, m6, m7, m8, m9
    out[10], out[11], out[12], out[13], out[14] = m10, m11, m12, m13, n
    return mu, mv, scale


@_compiled
def _reduced(m: NDArray[np.float64], work: NDArray[np.float64]
             ) -> None:  # pragma: no cover - compiled
    """From the sums ``m`` (:func:`_moments`), into ``work`` (3, 3, 3): ``work[0]`` the
    reduced 3x3 problem (the inverse of the constraint's block times S1 + S2 T) and
    ``work[1]`` T = -S3^-1 S2^T, which gives the linear part (D, E, F) of the conic from its
    quadratic part (A, B, C); ``work[2]`` is scratch."""
    # S3 = [[x2, xy, x], [xy, y2, y], [x, y, n]] (symmetric): its inverse from cofactors.
    s00, s01, s02, s11, s12, s22 = m[9], m[10], m[12], m[11], m[13], m[14]
    c00 = s11 * s22 - s12 * s12
    c01 = s12 * s02 - s01 * s22
    c02 = s01 * s12 - s11 * s02
    c11 = s00 * s22 - s02 * s02
    c12 = s01 * s02 - s00 * s12
    c22 = s00 * s11 - s01 * s01
    det = s00 * c00 + s01 * c01 + s02 * c02
    inv = work[2]
    inv[0, 0], inv[0, 1], inv[0, 2] = c00 / det, c01 / det, c02 / det
    inv[1, 0], inv[1, 1], inv[1, 2] = c01 / det, c11 / det, c12 / det
    inv[2, 0], inv[2, 1], inv[2, 2] = c02 / det, c12 / det, c22 / det
    # S2's rows (x^2, xy, y^2) times columns (x, y, 1); S1's (x^2, xy, y^2) times themselves.
    t = work[1]
    for c in range(3):
        r0, r1, r2 = _s2(m, c)
        for r in range(3):
            t[r, c] = -(inv[r, 0] * r0 + inv[r, 1] * r1 + inv[r, 2] * r2)
    red = work[2]  # the inverse is no longer needed
    for r in range(3):
        r0, r1, r2 = _s2(m, r)
        for c in range(3):
            red[r, c] = m[r + c] + r0 * t[0, c] + r1 * t[1, c] + r2 * t[2, c]
    # The constraint's block [[0, 0, 2], [0, -1, 0], [2, 0, 0]] inverted, applied on the left.
    out = work[0]
    for c in range(3):
        out[0, c] = 0.5 * red[2, c]
        out[1, c] = -red[1, c]
        out[2, c] = 0.5 * red[0, c]


@_compiled
def _s2(m: NDArray[np.float64], r: int) -> tuple[float, float, float]:  # pragma: no cover
    """Row ``r`` of S2 (the sums of x^2, x y or y^2 times x, y and 1) from the sums ``m``."""
    if r == 0:
        return m[5], m[6], m[9]
    if r == 1:
        return m[6], m[7], m[10]
    return m[7], m[8], m[11]


@_compiled
def _cubic_roots(c2: float, c1: float, c0: float
                 ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The real roots of l^3 - c2 l^2 + c1 l - c0 (a matrix's characteristic polynomial:
    trace, sum of principal minors, determinant), each polished by Newton steps: three by the
    trigonometric form, or the one real root (Cardano's) and NaN twice where the other two
    are a complex pair."""
    q = (c2 * c2 - 3.0 * c1) / 9.0
    r = (-2.0 * c2 * c2 * c2 + 9.0 * c2 * c1 - 27.0 * c0) / 54.0
    if r * r >= q * q * q:  # one real root (or a triple one, up to rounding)
        big = -math.copysign((abs(r) + math.sqrt(r * r - q * q * q)) ** (1.0 / 3.0), r)
        x = _polished(c2, c1, c0, big + (q / big if big != 0.0 else 0.0) + c2 / 3.0)
        return x, np.nan, np.nan
    sq = math.sqrt(q)
    theta = math.acos(r / (q * sq))
    return (_polished(c2, c1, c0, -2.0 * sq * math.cos(theta / 3.0) + c2 / 3.0),
            _polished(c2, c1, c0, -2.0 * sq * math.cos((theta + 2.0 * math.pi) / 3.0)
                      + c2 / 3.0),
            _polished(c2, c1, c0, -2.0 * sq * math.cos((theta + 4.0 * math.pi) / 3.0)
                      + c2 / 3.0))


@_compiled
def _polished(c2: float, c1: float, c0: float, x: float) -> float:  # pragma: no cover
    """The root ``x`` of l^3 - c2 l^2 + c1 l - c0 after :data:`_POLISH_STEPS` Newton
    steps."""
    for _ in range(_POLISH_STEPS):
        df = (3.0 * x - 2.0 * c2) * x + c1
        if df == 0.0:
            break
        x -= (((x - c2) * x + c1) * x - c0) / df
    return x


@_compiled
def _null_vector(m: NDArray[np.float64], lam: float
                 ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """A vector spanning the null space of ``m - lam I`` (3x3): the largest cross product of
    two of its rows (zeros where all vanish)."""
    a00, a01, a02 = m[0, 0] - lam, m[0, 1], m[0, 2]
    a10, a11, a12 = m[1, 0], m[1, 1] - lam, m[1, 2]
    a20, a21, a22 = m[2, 0], m[2, 1], m[2, 2] - lam
    best = (0.0, 0.0, 0.0)
    size = 0.0
    for v in ((a01 * a12 - a02 * a11, a02 * a10 - a00 * a12, a00 * a11 - a01 * a10),
              (a01 * a22 - a02 * a21, a02 * a20 - a00 * a22, a00 * a21 - a01 * a20),
              (a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20)):
        n = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        if n > size:
            best, size = v, n
    return best


@_compiled
def _ellipse_part(m: NDArray[np.float64]
                  ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The quadratic part (A, B, C) of the fit: the eigenvector of the reduced problem ``m``
    with 4 A C - B^2 > 0 (the largest such, unit length, when rounding leaves several; NaN
    when none)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    minors = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0] + m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]
              + m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    best = (np.nan, np.nan, np.nan)
    margin = 0.0
    for lam in _cubic_roots(tr, minors, det):
        v0, v1, v2 = _null_vector(m, lam)
        size = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if size == 0.0:
            continue
        v0, v1, v2 = v0 / size, v1 / size, v2 / size
        cond = 4.0 * v0 * v2 - v1 * v1
        if cond > margin:
            best, margin = (v0, v1, v2), cond
    return best


@_compiled
def _fit_into(points: NDArray, lo: int, hi: int, out: NDArray[np.float64], k: int,
              sums: NDArray[np.float64], work: NDArray[np.float64]
              ) -> None:  # pragma: no cover - compiled
    """Row ``k`` of ``out`` (K, 5): the direct fit of ``points[lo:hi]`` as centre u, v, full
    axes w <= h and angle (deg) of the w axis, float32-rounded (see the module's notes for
    what a fit that is not an ellipse gives); ``sums`` (15,) and ``work`` (3, 3, 3) are
    scratch space."""
    out[k, :] = 0.0
    if hi - lo < 5:
        return
    mu, mv, scale = _moments(points, lo, hi, sums)
    out[k, 0], out[k, 1] = np.float32(mu), np.float32(mv)
    if scale == 0.0:  # coincident points: their centre, zero axes
        return
    _reduced(sums, work)
    m, t = work[0], work[1]
    a, b, c = _ellipse_part(m)
    if a + c < 0.0:  # the sign that makes the quadratic part positive definite
        a, b, c = -a, -b, -c
    d = t[0, 0] * a + t[0, 1] * b + t[0, 2] * c
    e = t[1, 0] * a + t[1, 1] * b + t[1, 2] * c
    f = t[2, 0] * a + t[2, 1] * b + t[2, 2] * c
    det = 4.0 * a * c - b * b
    x0 = (b * e - 2.0 * c * d) / det
    y0 = (b * d - 2.0 * a * e) / det
    at_centre = f + 0.5 * (d * x0 + e * y0)  # the conic's value at its centre (< 0)
    # The quadratic part's eigenvalues: the larger one (the minor axis') directly, the
    # smaller one from their product (no cancellation on elongated ellipses).
    big = 0.5 * (a + c) + math.hypot(0.5 * (a - c), 0.5 * b)
    small = 0.25 * det / big
    out[k, 0] = np.float32(mu + scale * x0)
    out[k, 1] = np.float32(mv + scale * y0)
    out[k, 2] = np.float32(2.0 * scale * math.sqrt(-at_centre / big))
    out[k, 3] = np.float32(2.0 * scale * math.sqrt(-at_centre / small))
    # The direction where the quadratic part peaks (its larger eigenvalue's): the w axis.
    out[k, 4] = np.float32(math.degrees(0.5 * math.atan2(b, a - c)) % 180.0)


@_compiled
def direct_rows(points: NDArray, starts: NDArray[np.int64], stops: NDArray[np.int64]
                ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """(K, 5) rows centre u, v, full axes w, h and angle (deg), as ``cv2.fitEllipseDirect``
    gives them, of the direct fits of the pieces ``points[starts[k]:stops[k]]`` of (N, 2)
    ``points`` (int32, float32 or float64; read as float32)."""
    out = np.empty((starts.shape[0], 5))
    sums, work = np.empty(15), np.empty((3, 3, 3))
    for k in range(starts.shape[0]):
        _fit_into(points, starts[k], stops[k], out, k, sums, work)
    return out


@_compiled
def direct_fit(points: NDArray) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """(5,) :func:`direct_rows` row of all the (N, 2) ``points``."""
    out = np.empty((1, 5))
    _fit_into(points, 0, points.shape[0], out, 0, np.empty(15), np.empty((3, 3, 3)))
    return out[0]


@_compiled
def level_step(pixels: NDArray, pieces: NDArray[np.int64], tried: NDArray[np.int64],
               min_axis: float, max_axis: float, ratio_sq: float, max_residual: float,
               split_px: int, shortest: int, min_bow: float
               ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.int64],
                          NDArray[np.int64]]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.level_step` on the direct fits (:func:`direct_rows`)
    of the ``tried`` pieces (K, 4) (index, start, stop in ``pixels`` and chain of each): one
    level of :func:`~stackpick_sim.vision.fitting.fit_all` in one call."""
    raw = direct_rows(pixels, tried[:, 1].copy(), tried[:, 2].copy())
    return kernels.level_step(raw, pixels, pieces, tried, min_axis, max_axis, ratio_sq,
                              max_residual, split_px, shortest, min_bow)


@_compiled
def _same_run(sel: NDArray[np.int64], lo: int, hi: int, before: NDArray[np.int64], at: int
              ) -> bool:  # pragma: no cover - compiled
    """Whether ``sel[lo:hi]`` equals the run of ``before`` of the same length from ``at``."""
    for j in range(hi - lo):
        if sel[lo + j] != before[at + j]:
            return False
    return True


@_compiled
def refit_round(forms: NDArray[np.float64], starts: NDArray[np.int64],
                active: NDArray[np.bool_], pm: NDArray[np.int64],
                columns: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.float64]],
                tests: tuple[float, float], before: tuple[NDArray[np.int64], NDArray[np.int64]],
                least: int, bounds: tuple[float, float, float]
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                           NDArray[np.float64], NDArray[np.float64],
                           NDArray[np.bool_]]:  # pragma: no cover - compiled
    """One round of :func:`~stackpick_sim.vision.refine.refine_all`: the pixels along each
    ``active`` ellipse (:func:`~stackpick_sim.vision.kernels.along_select` of the pairs
    ``pm`` with the runs ``starts``, the pixel columns (N,) u, v, gu, gv and the squared
    distance and cosine bounds ``tests``); an ellipse whose selection repeats the previous
    round's (``before``: its selection and bounds, empty bounds on the first round) keeps its
    fit, one with fewer than ``least`` pixels stops, the others are refitted
    (:func:`direct_rows`) and checked (:func:`~stackpick_sim.vision.kernels.refit_checks`
    with the ``bounds`` min_axis, max_axis, ratio_sq: ``forms`` and ``active`` updated in
    place). Returns the selection and its bounds (the next round's ``before``), the refitted
    ellipses, their rows cx, cy, a, b, angle (rad), angles (deg) and which passed."""
    sel, at, pixels = kernels.along_select(forms, starts, active, pm, columns[0], columns[1],
                                           columns[2], columns[3], tests[0], tests[1])
    prev_sel, prev_at = before
    tried = np.empty(forms.shape[0], np.int64)
    los, his = np.empty(forms.shape[0], np.int64), np.empty(forms.shape[0], np.int64)
    k = 0
    for e in range(forms.shape[0]):
        if not active[e]:
            continue
        lo, hi = at[e], at[e + 1]
        if (prev_at.shape[0] and hi - lo == prev_at[e + 1] - prev_at[e]
                and _same_run(sel, lo, hi, prev_sel, prev_at[e])):
            continue  # the same pixels as the fit in hand: the same fit
        if hi - lo < least:
            active[e] = False
            continue
        tried[k], los[k], his[k] = e, lo, hi
        k += 1
    which = tried[:k].copy()
    raw = direct_rows(pixels, los[:k].copy(), his[:k].copy())
    rows, degrees, ok = kernels.refit_checks(raw, which, forms, active, bounds[0], bounds[1],
                                             bounds[2])
    return sel, at, which, rows, degrees, ok



@_compiled
def refine_rounds(given: NDArray[np.float64],
                  columns: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                 NDArray[np.float64]],
                  tolerances: NDArray[np.float64], cos_sq: float, least: int,
                  bounds: tuple[float, float, float]
                  ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:  # pragma: no cover
    """Every round of :func:`~stackpick_sim.vision.refine.refine_all` in one call: the
    ellipses (E, 5) ``given`` (cx, cy, a, b, angle deg), their forms
    (:func:`~stackpick_sim.vision.kernels.ellipse_forms`) and the (ellipse, pixel) pairs in
    each one's box grown by the first tolerance and a pixel
    (:func:`~stackpick_sim.vision.kernels.box_runs` of the pixel ``columns`` u, v, gu, gv),
    then one :func:`refit_round` per tolerance of ``tolerances`` (px; the cosine bound
    ``cos_sq``, the least pixels ``least`` and the fit ``bounds``) until no ellipse is
    active. Returns per ellipse the (cx, cy, a, b, angle deg) of its last refit that passed
    and whether one did (the others keep ``given``)."""
    u, v = columns[0], columns[1]
    n_e = given.shape[0]
    forms = kernels.ellipse_forms(given)
    reach = np.empty(n_e)
    for e in range(n_e):
        reach[e] = given[e, 2] + tolerances[0] + 1.0
    pm, starts = kernels.box_runs(u, v, forms[:, 0].copy(), forms[:, 1].copy(), reach)
    active = np.ones(n_e, np.bool_)
    final = given.copy()
    changed = np.zeros(n_e, np.bool_)
    prev_sel, prev_at = np.zeros(0, np.int64), np.zeros(0, np.int64)
    for r in range(tolerances.shape[0]):
        tol = tolerances[r]
        sel, at, which, rows, degrees, ok = refit_round(
            forms, starts, active, pm, columns, (4.0 * tol * tol, cos_sq), (prev_sel, prev_at),
            least, bounds)
        prev_sel, prev_at = sel, at
        for k in range(which.shape[0]):
            if ok[k]:
                e = which[k]
                final[e, 0], final[e, 1], final[e, 2], final[e, 3] = (rows[k, 0], rows[k, 1],
                                                                      rows[k, 2], rows[k, 3])
                final[e, 4] = degrees[k]
                changed[e] = True
        if not active.any():
            break
    return final, changed


def warm_up() -> None:
    """Compile (or load from the cache) these kernels for the argument types the detector
    passes (see :func:`~stackpick_sim.vision.kernels.warm_up`, which calls this)."""
    bounds = np.zeros(1, np.int64)
    for dtype in (np.int32, np.float32, np.float64):
        points = np.zeros((5, 2), dtype)
        direct_rows(points, bounds, bounds + 5)
        direct_fit(points)
    for pixels in (np.zeros((1, 2), np.int32), np.zeros((1, 2))):
        pieces, tried = kernels.chain_pieces(pixels, bounds + 1, 1, 0.0)
        level_step(pixels, pieces, tried, 1.0, 1.0, 1.0, 1.0, 2, 1, 0.0)
    empty, col = np.zeros(0, np.int64), np.zeros(1)
    refit_round(np.ones((1, 5)), np.array([0, 1], np.int64), np.ones(1, np.bool_),
                np.zeros(1, np.int64), (col, col, col, col), (1.0, 1.0), (empty, empty), 5,
                (1.0, 1.0, 1.0))
    refine_rounds(np.ones((1, 5)), (col, col, col, col), np.ones(3), 1.0, 5, (1.0, 1.0, 1.0))

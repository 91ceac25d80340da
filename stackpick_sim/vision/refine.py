"""Stage 4b: refine each merged ellipse on all the edge pixels that lie along it.

An ellipse merged from arcs is fitted on those arcs only; where Canny bridged a T-junction
an arc can carry a few pixels of another outline, or miss a faint stretch of its own. Here
every edge pixel near the ellipse whose gradient is roughly normal to it is collected and the
ellipse refitted, a few times with a shrinking tolerance (an ICP-like loop). Pixels of other
outlines crossing the ellipse are rejected by the gradient test; those running alongside it
by the shrinking tolerance. All ellipses are refined in lockstep (:func:`refine_all`): each
round tests all (ellipse, nearby pixel) pairs in one array pass.

The top face's final fit is sub-pixel twice: Canny's pixels moved to the gradient peak
(:func:`refine_subpixel`), then the gradient peaks read across the whole predicted outline,
faint arcs included, with outliers dropped (:func:`refine_on_profile`).
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams, PoseParams, RefineParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_fit, kernels_refine
from stackpick_sim.vision.contrast import contrast_threshold, perimeter_px, unit_circle
from stackpick_sim.vision.edges import SOBEL_GAIN, EdgeImage
from stackpick_sim.vision.fitting import DEFAULT as FIT_DEFAULT
from stackpick_sim.vision.fitting import (
    EQ2_CHECKED_RATIO_SQ,
    fit_ellipse,
    plausible,
)

#: The default settings of the refine stage (see RefineParams: the reasons for each).
DEFAULT = RefineParams()
#: Collection tolerances (px) of the successive refits, by default.
TOLERANCES_PX: tuple[float, ...] = DEFAULT.tolerances_px
#: Largest angle between an edge pixel's gradient and the ellipse normal, as its cosine,
#: by default.
MIN_NORMAL_COS = DEFAULT.min_normal_cos
#: Fewest collected pixels for a refit (fewer keeps the previous ellipse), by default.
MIN_PIXELS = DEFAULT.min_pixels
#: The default settings of the top face's final fit (see PoseParams: the reasons for each).
POSE_DEFAULT = PoseParams()
#: Largest sub-pixel shift (px) accepted along the gradient: the magnitude peak of a
#: non-maximum-suppressed pixel lies within half a pixel of it. Not a setting: it follows
#: from the edge map's geometry, not from a trade-off.
MAX_SHIFT_PX = 0.5


def _bilinear_pair(gx: NDArray[np.int16], gy: NDArray[np.int16], pts: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bilinear samples (N,) of two (H, W) images of one shape at (N, 2) points (u, v),
    clamped inside; the weights and indices are computed once for both."""
    return _bilinear_uv(gx, gy, pts[:, 0], pts[:, 1])


def _bilinear_uv(gx: NDArray[np.int16], gy: NDArray[np.int16], u: NDArray[np.float64],
                 v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`_bilinear_pair` at points given as (N,) columns ``u``, ``v``."""
    return kernels.bilinear_uv(gx, gy, np.ascontiguousarray(u, np.float64),
                               np.ascontiguousarray(v, np.float64))


def subpixel(image: EdgeImage, pts: NDArray[np.float64], dirs: NDArray[np.float64]
             ) -> NDArray[np.float64]:
    """(N, 2) edge pixels (u, v) moved to the gradient-magnitude peak along (N, 2) unit
    gradient directions: a parabola through the magnitudes one pixel either side
    (Devernay's sub-pixel Canny, with bilinear sampling)."""
    su, sv = _subpixel_columns(image, pts[:, 0], pts[:, 1], dirs[:, 0], dirs[:, 1])
    out = np.empty((su.shape[0], 2))
    out[:, 0], out[:, 1] = su, sv
    return out


def _subpixel_columns(image: EdgeImage, u: NDArray[np.float64], v: NDArray[np.float64],
                      gu: NDArray[np.float64], gv: NDArray[np.float64]
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`subpixel` of points and directions given as (N,) columns; the moved points'
    columns."""
    def col(c: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.ascontiguousarray(c, np.float64)

    return kernels.subpixel_columns(image.gx, image.gy, col(u), col(v), col(gu), col(gv),
                                    MAX_SHIFT_PX)


def refine_subpixel(ellipse: Ellipse, image: EdgeImage, points: NDArray[np.float64],
                    grads: NDArray[np.float64], shape: tuple[int, int],
                    params: PoseParams = POSE_DEFAULT, min_normal_cos: float = MIN_NORMAL_COS,
                    fits_params: FitParams = FIT_DEFAULT, min_pixels: int = MIN_PIXELS
                    ) -> Ellipse:
    """Final refit of ``ellipse`` on the sub-pixel positions of the edge pixels (M, 2) with
    unit gradients (M, 2) along it (within ``params.subpixel_tolerance_px``, gradient within
    the ``min_normal_cos`` cone of its normal, the fit within ``fits_params``' axis
    bounds; fewer than ``min_pixels`` keep ``ellipse``)."""
    tol = params.subpixel_tolerance_px
    # One compiled pass: the pixels near the ellipse (its box grown by the tolerance), those
    # along it, their sub-pixel positions (float32: the fit's input type). The pixels and
    # gradients as (2, M) rows (the edge stage's arrays are their transposes).
    cx, cy, fa, fh, fb = _form(ellipse)
    pts = kernels_refine.subpixel_along_rows(
        _rows(points), _rows(grads), cx, cy, fa, fh, fb, ellipse.a + tol + 1, 4.0 * tol * tol,
        min_normal_cos * min_normal_cos, image.gx, image.gy, MAX_SHIFT_PX)
    if pts.shape[0] < min_pixels:
        return ellipse
    fit = fit_ellipse(pts)
    return fit if fit is not None and plausible(fit, shape, fits_params) else ellipse


def _rows(columns: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 2) values as (2, M) C-ordered float64 rows (the transpose itself where it is
    one)."""
    rows = columns.T
    if rows.dtype == np.float64 and rows.flags.c_contiguous:
        return rows
    return np.ascontiguousarray(rows, np.float64)


def edge_points(image: EdgeImage) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(M, 2) edge pixels (u, v) in row-major order and their (M, 2) unit gradient
    directions (each with contiguous columns)."""
    # One compiled pass over the edge map (kernels.edge_pixels: np.flatnonzero's order and
    # the same unit gradients as the array form).
    pts, g = kernels.edge_pixels(np.ascontiguousarray(image.edges, np.uint8), image.gx,
                                 image.gy)
    return pts.T, g.T


def _along(ellipse: Ellipse, pts: NDArray[np.float64], grads: NDArray[np.float64],
           tol_px: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The edge pixels (M, 2) within ``tol_px`` of ``ellipse`` whose unit gradients (M, 2)
    lie within the MIN_NORMAL_COS cone of its normal, and their gradients.

    Distance (Sampson, as :func:`~stackpick_sim.vision.fitting.distances`) and normal come
    from one evaluation of the implicit form's gradient.
    """
    keep = _along_mask(ellipse, pts[:, 0], pts[:, 1], grads[:, 0], grads[:, 1], tol_px)
    return pts[keep], grads[keep]


def _along_mask(ellipse: Ellipse, u: NDArray[np.float64], v: NDArray[np.float64],
                gu: NDArray[np.float64], gv: NDArray[np.float64], tol_px: float
                ) -> NDArray[np.bool_]:
    """:func:`_along`'s test of pixels and unit gradients given as (M,) columns."""
    cx, cy, fa, fh, fb = _form(ellipse)
    return _along_test(cx, cy, fa, fh, fb, u, v, gu, gv, tol_px)


def _form(ellipse: Ellipse) -> tuple[float, float, float, float, float]:
    """The centre and the quadratic form's entries (cx, cy, A, H, B) of ``ellipse``: a pixel
    (u, v) at (du, dv) from the centre lies on it where A du^2 + 2 H du dv + B dv^2 = 1."""
    t = math.radians(ellipse.angle_deg)
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0 / (ellipse.a * ellipse.a), 1.0 / (ellipse.b * ellipse.b)
    return (ellipse.cx, ellipse.cy, c * c * ia + s * s * ib, c * s * (ia - ib),
            s * s * ia + c * c * ib)


def _along_test(cx: float | NDArray[np.float64], cy: float | NDArray[np.float64],
                fa: float | NDArray[np.float64], fh: float | NDArray[np.float64],
                fb: float | NDArray[np.float64], u: NDArray[np.float64],
                v: NDArray[np.float64], gu: NDArray[np.float64], gv: NDArray[np.float64],
                tol_px: float) -> NDArray[np.bool_]:
    """:func:`_along`'s test of pixels (u, v) with unit gradients (gu, gv), (M,) each,
    against an ellipse's :func:`_form` (scalars, or (M,) per pixel; the same arithmetic, so
    the same results, either way).

    With F = A du^2 + 2 H du dv + B dv^2 - 1 and half its gradient n = (A du + H dv,
    H du + B dv), the Sampson distance is |F| / (2 |n|) and the normal is n / |n|: both
    tests are compared squared, without a square root or a division (few array passes:
    the cost here is their count).
    """
    du = u - cx
    dv = v - cy
    nu = fa * du
    nu += fh * dv
    nv = fb * dv
    nv += fh * du
    f = du * nu
    dv *= nv
    f += dv
    f -= 1.0
    f *= f  # F^2
    n2 = nu * nu
    n2 += nv * nv  # |n|^2
    nu *= gu
    nv *= gv
    nu += nv
    nu *= nu  # (n . gradient)^2
    keep = f < (4.0 * tol_px * tol_px) * n2
    keep &= nu >= (MIN_NORMAL_COS * MIN_NORMAL_COS) * n2
    return cast("NDArray[np.bool_]", keep)


def refine(ellipse: Ellipse, points: NDArray[np.float64], grads: NDArray[np.float64],
           shape: tuple[int, int]) -> Ellipse:
    """Refit ``ellipse`` on the edge pixels (M, 2) with gradients (M, 2) along it."""
    return refine_all([ellipse], points, grads, shape)[0]


def refine_all(ellipses: list[Ellipse], points: NDArray[np.float64],
               grads: NDArray[np.float64], shape: tuple[int, int],
               params: RefineParams = DEFAULT, fits_params: FitParams = FIT_DEFAULT
               ) -> list[Ellipse]:
    """:func:`refine` of every ellipse, in lockstep: each round (one per tolerance of
    ``params``; fits within ``fits_params``' axis bounds) collects the pixels along all
    current fits in one pass over (ellipse, pixel) pairs, then refits each ellipse that
    collected enough (an ellipse stops at its first failed round, as :func:`refine` alone).
    A fit on the same pixels as the fit in hand is not repeated."""
    current = list(ellipses)
    if not current or points.shape[0] == 0:
        return current
    # Pixel columns, contiguous: (u, v) and unit gradient (gu, gv) (no copies of the edge
    # stage's arrays, transposes of (2, M) rows).
    u, v = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
    gu, gv = np.ascontiguousarray(grads[:, 0]), np.ascontiguousarray(grads[:, 1])
    given = np.array([(e.cx, e.cy, e.a, e.b, e.angle_deg) for e in current], np.float64)
    bounds = (fits_params.min_axis_px, fits_params.max_axis_diagonals * math.hypot(*shape),
              EQ2_CHECKED_RATIO_SQ)
    # Every round in one compiled call: the (ellipse, pixel) pairs in each fit's box (grown
    # by the first tolerance), then per tolerance the pixels along each active fit, the
    # refits of those whose pixels changed, fit_ellipse's checks and plausible's bounds on
    # them (a fit that fails stops its ellipse); each ellipse's last refit that passed.
    final, changed = kernels_fit.refine_rounds(
        given, (u, v, gu, gv), np.array(params.tolerances_px, np.float64),
        params.min_normal_cos * params.min_normal_cos, max(5, params.min_pixels), bounds)
    for e, (cx, cy, a, b, deg) in zip(changed.nonzero()[0].tolist(), final[changed].tolist(),
                                      strict=True):
        current[e] = Ellipse.of(cx, cy, a, b, deg)
    return current


def refine_on_profile(ellipse: Ellipse, image: EdgeImage, shape: tuple[int, int],
                      params: PoseParams = POSE_DEFAULT, fits_params: FitParams = FIT_DEFAULT
                      ) -> Ellipse:
    """Refit ``ellipse`` on the sub-pixel gradient peaks across its whole outline (fits
    within ``fits_params``' axis bounds).

    Along each outline sample's normal the normal gradient is read (bilinear) every
    ``params.profile_step_px`` within ``params.profile_reach_px``; the strongest interior
    peak, placed by a parabola through its neighbours, is kept when it reaches the
    consistent-contrast threshold (:func:`~stackpick_sim.vision.contrast.contrast_threshold`,
    per sample). Unlike
    :func:`refine_subpixel` this does not need Canny's edge pixels, so a face whose boundary
    with a same-coloured neighbour is faint is fitted on its whole outline, not on the strong
    arcs only. Returns ``ellipse`` when too little of the outline shows a peak (see
    :class:`~stackpick_sim.config.vision_params.PoseParams` for the rounds and the outliers).
    """
    threshold = contrast_threshold(image) * SOBEL_GAIN
    reach, step, least = params.profile_reach_px, params.profile_step_px, params.profile_min_share
    steps = np.arange(-reach, reach + 1e-9, step)  # the search offsets, px
    current = ellipse
    for round_ in range(params.profile_rounds):
        ct, st = unit_circle(max(16, math.ceil(perimeter_px(current))))
        n = ct.shape[0]
        # The outline samples (contrast.outline_columns'), the (n, k) sample grid across
        # them and each sample's peak, in one compiled pass.
        peaks = kernels_refine.outline_peaks(image.gx, image.gy, _terms(current), ct, st,
                                             steps, step, threshold)
        if peaks.shape[0] < least * n:
            return current
        fit = fit_ellipse(peaks)
        if fit is None or not plausible(fit, shape, fits_params):
            return current
        if round_ == params.profile_rounds - 1:
            # The peaks within outlier_medians median distances of the fit (and
            # outlier_min_px), in one compiled pass: ellipse_distances, column_median and
            # the mask, the kept peaks as float32 (the fit's input).
            inliers = kernels_refine.profile_inliers(peaks, _terms(fit), params.outlier_min_px,
                                                     params.outlier_medians)
            kept = inliers.shape[0]
            # All inliers: the refit would repeat the fit on the same points.
            if least * n <= kept < peaks.shape[0]:
                fit = fit_ellipse(inliers) or fit
        current = fit if plausible(fit, shape, fits_params) else current
    return current


def _terms(ellipse: Ellipse) -> NDArray[np.float64]:
    """(cx, cy, a, b, cos angle, sin angle) of ``ellipse``, as the compiled passes take it."""
    t = math.radians(ellipse.angle_deg)
    return np.array([ellipse.cx, ellipse.cy, ellipse.a, ellipse.b, math.cos(t), math.sin(t)])

"""Stage 3: ellipse-specific least-squares fits of edge segments (paper Eq. 1 and 2).

The paper writes an ellipse about its centre as ``A x^2 + 2 H x y + B y^2 = 1`` and accepts it
only when ``A B - H^2 > 0``. Fitzgibbon's direct fit (compiled in
:mod:`~stackpick_sim.vision.kernels_fit`, the same fits as ``cv2.fitEllipseDirect``) minimises
the algebraic error under exactly that constraint (normalised to ``4AB - (2H)^2 = 1``), so every
fit it returns is an ellipse; the condition is still checked on the returned quadratic form
wherever rounding could break it (axis ratios beyond EQ2_CHECKED_RATIO_SQ; below, it holds by a
wide margin), which also rejects the degenerate fits of points on a line or on two parallel
lines (no axes, zero or extreme ones).

Distances of points to an ellipse use the Sampson approximation (algebraic error over its
gradient), accurate to a few percent within a few pixels of the curve, which is all the
residual tests and the merging counts look at.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_fit

#: The default settings (see FitParams: the reasons for each).
DEFAULT = FitParams()
#: Squared axis ratio above which a fit's Eq. 2 condition is evaluated (below it the
#: condition holds with a margin far beyond float64 rounding: the terms are ~ratio^2 and
#: carry a relative error of ~1e-16, the result is the ratio itself).
EQ2_CHECKED_RATIO_SQ = 1e6


_INT32, _FLOAT32, _FLOAT64 = np.dtype(np.int32), np.dtype(np.float32), np.dtype(np.float64)


def fit_ellipse(points: NDArray) -> Ellipse | None:
    """Ellipse-specific fit of (N, 2) pixels (u, v); None if N < 5 or not an ellipse.

    The direct fit (:func:`~stackpick_sim.vision.kernels_fit.direct_fit`) reads the points as
    float32 (int32 pixels exactly)."""
    if points.shape[0] < 5:
        return None
    cx, cy, w, h, angle = kernels_fit.direct_fit(_fit_input(points)).tolist()
    if not (math.isfinite(cx) and math.isfinite(cy) and w > 0 and h > 0
            and math.isfinite(angle)):
        return None
    if w >= h:
        a, b, ang = w / 2.0, h / 2.0, angle
    else:
        a, b, ang = h / 2.0, w / 2.0, angle + 90.0
    ellipse = Ellipse.of(float(cx), float(cy), float(a), float(b), float(ang % 180.0))
    # Eq. 2's AB - H^2 equals (a / b)^2 > 0 up to rounding of terms of its square's size:
    # it can only fail on extreme axis ratios (the degenerate fits), so only those are checked.
    if (a / b) ** 2 > EQ2_CHECKED_RATIO_SQ and not satisfies_eq2(ellipse):
        return None
    return ellipse


def _fit_input(points: NDArray) -> NDArray:
    """(N, 2) ``points`` as the compiled fit takes them: int32, float32 or float64 as they
    are, other types as float64 (the same float32 values in the fit), C-ordered and
    writable (each other layout would be another compiled version)."""
    dtype = points.dtype
    if dtype is not _INT32 and dtype is not _FLOAT32 and dtype is not _FLOAT64:
        return np.ascontiguousarray(points, np.float64)
    return kernels.kernel_array(points)


def satisfies_eq2(ellipse: Ellipse) -> bool:
    """Paper Eq. 2: the centred quadratic form A x^2 + 2Hxy + B y^2 has AB - H^2 > 0.

    Computed in units of the semi-major axis (so the test is scale-free).
    """
    t = math.radians(ellipse.angle_deg)
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0, (ellipse.a / ellipse.b) ** 2
    big_a, big_b, big_h = c * c * ia + s * s * ib, s * s * ia + c * c * ib, c * s * (ia - ib)
    return big_a * big_b - big_h * big_h > 0.0


def ellipse_params(ellipses: list[Ellipse]) -> NDArray[np.float64]:
    """(E, 5) array of (cx, cy, a, b, angle_rad) rows."""
    return np.array([[e.cx, e.cy, e.a, e.b, math.radians(e.angle_deg)] for e in ellipses],
                    dtype=np.float64).reshape(-1, 5)


def distances(params: NDArray[np.float64], points: NDArray) -> NDArray[np.float64]:
    """(E, N) approximate distances (px) of N points (N, 2) to E ellipses (E, 5) params.

    Sampson distance |Q| / |grad Q| of the normalised implicit form
    Q = (x/a)^2 + (y/b)^2 - 1 in each ellipse's own frame.
    """
    if params.shape[0] == 1:  # one ellipse: scalar parameters, the same values
        cx, cy, a, b, t = params[0].tolist()
        return _scalar_distances(cx, cy, a, b, t, points)[None, :]
    p = np.asarray(points, np.float64)
    cx, cy, a, b, t = (params[:, i : i + 1] for i in range(5))
    du, dv = p[None, :, 0] - cx, p[None, :, 1] - cy
    c, s = np.cos(t), np.sin(t)
    x = (c * du + s * dv) / a
    y = (-s * du + c * dv) / b
    q = x * x + y * y - 1.0
    grad = 2.0 * np.sqrt((x / a) ** 2 + (y / b) ** 2) + 1e-12
    return np.abs(q) / grad


def ellipse_distances(ellipse: Ellipse, points: NDArray) -> NDArray[np.float64]:
    """(N,) :func:`distances` of N points (N, 2) to one ellipse (the same values, on scalar
    parameters: a third less time than the broadcast form on a few hundred points)."""
    return _scalar_distances(ellipse.cx, ellipse.cy, ellipse.a, ellipse.b,
                             math.radians(ellipse.angle_deg), points)


def _scalar_distances(cx: float, cy: float, a: float, b: float, t: float, points: NDArray
                      ) -> NDArray[np.float64]:
    """(N,) :func:`distances` to the ellipse (cx, cy, a, b, angle t rad) of points (N, 2),
    in one compiled pass (the same arithmetic)."""
    return kernels.point_distances(np.ascontiguousarray(points, np.float64), cx, cy, a, b,
                                   math.cos(t), math.sin(t))


def within(params: NDArray[np.float64], points: NDArray, tol_px: float) -> NDArray[np.bool_]:
    """(E, N) bool: :func:`distances` < ``tol_px``, evaluated only for the points inside each
    ellipse's bounding square grown by the tolerance (the others are farther off)."""
    out = np.zeros((params.shape[0], points.shape[0]), bool)
    out[within_pairs(params, points, tol_px)] = True
    return out


def within_pairs(params: NDArray[np.float64], points: NDArray, tol_px: float
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The true entries of :func:`within` as (ellipse, point) index arrays (K,) each, in
    ``np.nonzero`` order, without the (E, N) matrix."""
    pairs = within_pairs_split(params, points, tol_px, points.shape[0])
    return pairs[0], pairs[1]


def within_pairs_split(params: NDArray[np.float64], points: NDArray, tol_px: float,
                       split: int) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                            NDArray[np.int64], NDArray[np.int64]]:
    """:func:`within_pairs` as the pairs of the points before ``split`` and those of the
    others, each in :func:`within_pairs`' order (its pairs split by point)."""
    p = np.asarray(points, np.float64)
    reach = params[:, 2] + tol_px + 1.0
    # The box test and the distances in one compiled pass over (ellipse, point) pairs.
    return kernels.near_pairs_split(np.ascontiguousarray(p[:, 0]),
                                    np.ascontiguousarray(p[:, 1]), distance_rows(params),
                                    reach, tol_px, split)


def pair_distances(params: NDArray[np.float64], points: NDArray[np.float64],
                   which: NDArray[np.int64], at: NDArray[np.int64]) -> NDArray[np.float64]:
    """(K,) :func:`distances` of points ``at`` (K,) of (N, 2) ``points`` to ellipses ``which``
    (K,) of (E, 5) ``params``: one distance per (ellipse, point) pair."""
    cx, cy, a, b = (params[:, i][which] for i in range(4))  # contiguous per column
    du, dv = points[:, 0][at] - cx, points[:, 1][at] - cy
    c, s = np.cos(params[:, 4])[which], np.sin(params[:, 4])[which]
    x = (c * du + s * dv) / a
    y = (-s * du + c * dv) / b
    grad = 2.0 * np.sqrt((x / a) ** 2 + (y / b) ** 2) + 1e-12
    return cast("NDArray[np.float64]", np.abs(x * x + y * y - 1.0) / grad)


def grouped_distances(params: NDArray[np.float64], counts: NDArray[np.int64],
                      pu: NDArray[np.float64], pv: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K,) :func:`pair_distances` of points given as columns ``pu``, ``pv`` (K,) that run
    ellipse by ellipse: the first ``counts[0]`` to ellipse 0 of (E, 5) ``params``, the next
    ``counts[1]`` to ellipse 1, ... (the same values, in one compiled loop)."""
    return kernels.grouped_distances(distance_rows(params), np.asarray(counts, np.int64),
                                     np.ascontiguousarray(pu, np.float64),
                                     np.ascontiguousarray(pv, np.float64))


def distance_rows(params: NDArray[np.float64]) -> NDArray[np.float64]:
    """(6, E) rows cx, cy, a, b, cos angle, sin angle of (E, 5) ``params`` (numpy's cos and
    sin, as :func:`distances`), the compiled distance kernels' input."""
    rows = np.empty((6, params.shape[0]))
    rows[:4] = params[:, :4].T
    np.cos(params[:, 4], out=rows[4])
    np.sin(params[:, 4], out=rows[5])
    return rows


def rms_residual(ellipse: Ellipse, points: NDArray) -> float:
    """RMS Sampson distance (px) of (N, 2) points to ``ellipse``: ``sqrt(mean(d * d))`` of
    :func:`ellipse_distances`, in one compiled pass (kernels.points_rms: the same value;
    int32 pixels read as they are, other points as float64)."""
    if points.shape[0] == 0:  # numpy's mean of nothing (NaN, with its warning)
        d = ellipse_distances(ellipse, points)
        return float(np.sqrt(np.mean(d * d)))
    if points.dtype is not _INT32 or not points.flags.c_contiguous:
        points = np.ascontiguousarray(points, np.float64)
    t = math.radians(ellipse.angle_deg)
    return kernels.points_rms(points, ellipse.cx, ellipse.cy, ellipse.a, ellipse.b,
                              math.cos(t), math.sin(t))


def bow_px(points: NDArray) -> float:
    """RMS spread (px) of (N, 2) points across their principal line; ~0 for a straight run."""
    p = np.asarray(points, np.float64)
    centred = p - p.mean(axis=0)
    sxx, syy = float(centred[:, 0] @ centred[:, 0]), float(centred[:, 1] @ centred[:, 1])
    sxy = float(centred[:, 0] @ centred[:, 1])
    n = max(1, p.shape[0])
    half_trace, det = 0.5 * (sxx + syy) / n, (sxx * syy - sxy * sxy) / (n * n)
    smallest = half_trace - math.sqrt(max(0.0, half_trace * half_trace - det))
    return math.sqrt(max(0.0, smallest))


def plausible(ellipse: Ellipse, shape: tuple[int, int], params: FitParams = DEFAULT) -> bool:
    """True when the axes are within ``params.min_axis_px`` and ``params.max_axis_diagonals``
    of an (H, W) image."""
    diagonal = math.hypot(*shape)
    return params.min_axis_px <= ellipse.b and ellipse.a <= params.max_axis_diagonals * diagonal


def within_gate(ellipse: Ellipse, gate: tuple[float, float] | None) -> bool:
    """Whether the semi-major axis lies in the size ``gate`` (min, max px; any size without
    one)."""
    return gate is None or gate[0] <= ellipse.a <= gate[1]


def fit_segment(points: NDArray, shape: tuple[int, int], params: FitParams = DEFAULT
                ) -> tuple[Ellipse, float] | None:
    """(ellipse, rms residual px) of a segment (N, 2), or None if too short, straight or bad."""
    if points.shape[0] < params.min_fit_px or bow_px(points) < params.min_bow_px:
        return None
    ellipse = fit_ellipse(points)
    if ellipse is None or not plausible(ellipse, shape, params):
        return None
    residual = rms_residual(ellipse, points)
    if residual > params.max_residual_px:
        return None
    return ellipse, residual


def fit_or_split(points: NDArray, shape: tuple[int, int], depth: int = 3,
                 params: FitParams = DEFAULT) -> list[tuple[NDArray, Ellipse, float]]:
    """Fit a segment; if the fit fails on a long segment, split it in halves and retry.

    Returns (points, ellipse, residual) per accepted piece. A wall line that runs smoothly
    (no corner) into a face arc fails as a whole, and its arc half then fits on its own.
    """
    fit = fit_segment(points, shape, params)
    if fit is not None:
        return [(points, fit[0], fit[1])]
    if depth == 0 or points.shape[0] < 2 * params.min_fit_px:
        return []
    half = points.shape[0] // 2
    return (fit_or_split(points[:half], shape, depth - 1, params)
            + fit_or_split(points[half:], shape, depth - 1, params))


def fit_all(chains: Sequence[NDArray], shape: tuple[int, int], depth: int = 3,
            params: FitParams = DEFAULT) -> list[tuple[int, NDArray, Ellipse, float]]:
    """:func:`fit_or_split` of every chain, level by level: the straightness test of the
    chains is one compiled pass, then per level another does the direct fits of all the
    level's pieces, their checks with their residuals, the halves of the pieces that failed
    and their straightness test. Returns (chain index, points, ellipse, residual) per
    accepted piece, in the order :func:`fit_or_split` gives them chain after chain."""
    if not chains:
        return []
    sizes = [c.shape[0] for c in chains]
    pixels = np.concatenate(chains)
    if pixels.dtype != _INT32:  # int32 chains, as the stages pass them, read as they are
        pixels = pixels.astype(np.float64)
    shortest = max(5, params.min_fit_px)
    pieces, tried = kernels.chain_pieces(pixels, np.array(sizes, np.int64), shortest,
                                         params.min_bow_px)
    limits = (params.min_axis_px, params.max_axis_diagonals * math.hypot(*shape),
              EQ2_CHECKED_RATIO_SQ, params.max_residual_px)
    found: list[tuple[int, int, NDArray, Ellipse, float]] = []
    offsets = [0, *itertools.accumulate(sizes)]
    for level in range(depth + 1):
        # The tried pieces' direct fits, their checks and the next level, in one call.
        rows, good, pieces, next_tried = kernels_fit.level_step(
            pixels, pieces, tried, *limits, 0 if level == depth else 2 * params.min_fit_px,
            shortest, params.min_bow_px)
        for k in good.nonzero()[0].tolist():
            _, lo, hi, c = tried[k].tolist()
            # The accepted piece: the chain itself on the first level, else a view of it.
            q = chains[c] if level == 0 else chains[c][lo - offsets[c]:hi - offsets[c]]
            cx, cy, a, b, ang, r = rows[k].tolist()
            found.append((lo, c, q, Ellipse.of(cx, cy, a, b, ang), r))
        tried = next_tried
        if not pieces.shape[1]:
            break
    # The accepted pieces of a chain are disjoint: their order along the concatenated pixels
    # is fit_or_split's (first halves first).
    found.sort(key=lambda f: f[0])
    return [(c, q, e, r) for _, c, q, e, r in found]

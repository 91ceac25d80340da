"""Compiled passes of the top face's final fit on the gradient profile (numba; see
:mod:`~stackpick_sim.vision.kernels` for how kernels are compiled and cached).

Each pass chains the array steps of :func:`~stackpick_sim.vision.refine.refine_on_profile`
into one call, with the same arithmetic in the same order (so the same values): what it
saves is the calls, conversions and temporaries between the steps.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.vision import kernels
from stackpick_sim.vision.kernels import _compiled


@_compiled
def outline_peaks(gx: NDArray[np.int16], gy: NDArray[np.int16], terms: NDArray[np.float64],
                  ct: NDArray[np.float64], st: NDArray[np.float64], steps: NDArray[np.float64],
                  step_px: float, threshold: float
                  ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.profile_peaks` across the outline of the ellipse
    ``terms`` (cx, cy, a, b and the angle's cosine and sine) at the unit-circle samples
    (ct, st) (:func:`~stackpick_sim.vision.kernels.outline_columns`): (K, 2) peaks in sample
    order."""
    pu, pv, nu, nv = kernels.outline_columns(terms[0], terms[1], terms[2], terms[3], terms[4],
                                             terms[5], ct, st)
    return kernels.profile_peaks(gx, gy, pu, pv, nu, nv, steps, step_px, threshold)


@_compiled
def profile_inliers(peaks: NDArray[np.float64], terms: NDArray[np.float64], least_px: float,
                    medians: float) -> NDArray[np.float32]:  # pragma: no cover - compiled
    """The ``peaks`` (K, 2), K >= 1, whose Sampson distance to the ellipse ``terms`` (cx, cy,
    a, b and the angle's cosine and sine) is within ``medians`` times the median distance
    (at least ``least_px``), in order, as float32 rows (the fit's input); see
    :func:`~stackpick_sim.vision.refine.refine_on_profile` (the same test as
    :func:`~stackpick_sim.vision.kernels.point_distances` and
    :func:`~stackpick_sim.vision.wall.column_median`)."""
    cx, cy, a, b, c, s = terms[0], terms[1], terms[2], terms[3], terms[4], terms[5]
    n = peaks.shape[0]
    d = np.empty(n)
    for k in range(n):
        du, dv = peaks[k, 0] - cx, peaks[k, 1] - cy
        x = (c * du + s * dv) / a
        y = (c * dv - s * du) / b
        xa, yb = x / a, y / b
        grad = 2.0 * math.sqrt(xa * xa + yb * yb) + 1e-12
        d[k] = abs(x * x + y * y - 1.0) / grad
    ordered = np.sort(d)
    median = 0.5 * (ordered[(n - 1) // 2] + ordered[n // 2])
    bound = medians * median
    if not bound > least_px:
        bound = least_px
    out = np.empty((n, 2), np.float32)
    kept = 0
    for k in range(n):
        if d[k] <= bound:
            out[kept, 0] = np.float32(peaks[k, 0])
            out[kept, 1] = np.float32(peaks[k, 1])
            kept += 1
    return out[:kept]


@_compiled
def subpixel_along_rows(points: NDArray[np.float64], grads: NDArray[np.float64],
                        cx: float, cy: float, fa: float, fh: float, fb: float, reach: float,
                        dist_sq: float, cos_sq: float, gx: NDArray[np.int16],
                        gy: NDArray[np.int16], max_shift: float
                        ) -> NDArray[np.float32]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.subpixel_along` of the edge pixels (2, M)
    ``points`` (u row, v row) with unit gradients (2, M) ``grads`` and the ellipse's form
    (cx, cy, A, H, B) given as scalars: (K, 2) float32 sub-pixel positions in pixel
    order."""
    form = np.empty(5)
    form[0], form[1], form[2], form[3], form[4] = cx, cy, fa, fh, fb
    return kernels.subpixel_along(points[0], points[1], grads[0], grads[1], form, reach,
                                  dist_sq, cos_sq, gx, gy, max_shift)


@_compiled
def shift_rows(rows: NDArray[np.int32], du: int, dv: int) -> None:  # pragma: no cover
    """(N, 2) int32 ``rows`` (u, v) plus (du, dv), in place (``rows += (du, dv)``: the same
    values without numpy's broadcast over rows of two)."""
    for k in range(rows.shape[0]):
        rows[k, 0] += du
        rows[k, 1] += dv


def warm_up() -> None:
    """Compile (or load from the cache) these kernels for the argument types the detector
    passes (see :func:`~stackpick_sim.vision.kernels.warm_up`, which calls this)."""
    profile_inliers(np.zeros((1, 2)), np.ones(6), 0.3, 3.0)
    shift_rows(np.zeros((1, 2), np.int32), 1, 1)
    grid = np.zeros((4, 4), np.int16)
    subpixel_along_rows(np.zeros((2, 1)), np.zeros((2, 1)), 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0,
                        1.0, grid, grid, 0.5)
    fixed = np.ones(1)  # the cached unit circles are read-only
    fixed.setflags(write=False)
    img = np.zeros((4, 4), np.int16)
    outline_peaks(img, img, np.ones(6), fixed, fixed, np.zeros(3), 0.5, 1.0)

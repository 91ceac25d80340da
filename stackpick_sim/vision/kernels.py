"""Compiled per-pixel, per-sample and per-pair loops of the detector's stages (numba).

Each kernel computes, element by element, the same IEEE operations in the same order as the
numpy expression it stands for (no fast-math: no reassociation, no fused multiply-add), so
its results are bit-identical to the array version; what it saves is numpy's cost per call
and its temporaries on the few hundred to few thousand elements of a frame, and the
(ellipse, pixel) matrices the array versions build (their memory grows with ellipses x edge
pixels).

Compilation happens on a kernel's first call for each combination of argument types and is
cached on disk (``cache=True``) beside this module, or where ``NUMBA_CACHE_DIR`` points;
:func:`warm_up` (the Makefile's install step) compiles every kernel for the types the
detector passes (C-ordered, writable arrays: a read-only or strided array is another type),
so a fresh process with a warm cache only loads them (about 20 ms each). numba writes each
cache file to a temporary name and renames it into place, so workers compiling at the same
time do not corrupt it. A division by zero gives numpy's inf or NaN, as in the array forms.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numba import njit
from numpy.typing import NDArray

_F = TypeVar("_F", bound=Callable[..., Any])


def _compiled(fn: _F) -> _F:
    """``fn`` compiled by numba on its first call (cached on disk), with its own signature
    for the type checker; a division by zero gives what numpy's gives (inf or NaN), as in
    the array expressions, rather than raising."""
    return cast("_F", njit(cache=True, nogil=True, error_model="numpy")(fn))



def kernel_array(a: Any, dtype: Any = None) -> NDArray[Any]:
    """``np.require(a, dtype, ("C", "W"))``, the argument type the kernels are compiled for
    (C-ordered, writable, of ``dtype`` when given): ``a`` itself when it already is one (the
    same test np.require makes, at a fraction of its cost), else np.require's copy."""
    if (isinstance(a, np.ndarray) and (dtype is None or a.dtype == dtype)
            and a.flags.c_contiguous and a.flags.writeable):
        return a
    return np.require(a, dtype, ("C", "W"))


@_compiled
def _box_count(pu: NDArray[np.float64], pv: NDArray[np.float64], cx: NDArray[np.float64],
               cy: NDArray[np.float64], reach: NDArray[np.float64]
               ) -> int:  # pragma: no cover - compiled
    """How many (centre e, point) pairs have |pu - cx[e]| <= reach[e] and |pv - cy[e]| <=
    reach[e]."""
    count = 0
    for e in range(cx.shape[0]):
        x, y, r = cx[e], cy[e], reach[e]
        for m in range(pu.shape[0]):
            if abs(pu[m] - x) <= r and abs(pv[m] - y) <= r:
                count += 1
    return count


@_compiled
def box_pairs(pu: NDArray[np.float64], pv: NDArray[np.float64], cx: NDArray[np.float64],
              cy: NDArray[np.float64], reach: NDArray[np.float64]
              ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """(ellipse, point) index pairs with |pu - cx| <= reach and |pv - cy| <= reach, in
    ``np.nonzero`` order of the (E, N) test matrix (ellipse by ellipse, points ascending),
    without the matrix."""
    n_e, n_p = cx.shape[0], pu.shape[0]
    count = _box_count(pu, pv, cx, cy, reach)
    pe = np.empty(count, np.int64)
    pm = np.empty(count, np.int64)
    k = 0
    for e in range(n_e):
        x, y, r = cx[e], cy[e], reach[e]
        for m in range(n_p):
            if abs(pu[m] - x) <= r and abs(pv[m] - y) <= r:
                pe[k] = e
                pm[k] = m
                k += 1
    return pe, pm


@_compiled
def box_runs(pu: NDArray[np.float64], pv: NDArray[np.float64], cx: NDArray[np.float64],
             cy: NDArray[np.float64], reach: NDArray[np.float64]
             ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """The points of :func:`box_pairs` (ellipse by ellipse, points ascending) and where each
    ellipse's run of them starts and ends ((E + 1,) bounds)."""
    n_e, n_p = cx.shape[0], pu.shape[0]
    ascending = True
    for m in range(n_p - 1):
        ascending &= pv[m] <= pv[m + 1]
    if not ascending:
        pe, pm = box_pairs(pu, pv, cx, cy, reach)
        starts = np.zeros(n_e + 1, np.int64)
        for k in range(pe.shape[0]):
            starts[pe[k] + 1] += 1
        for e in range(n_e):
            starts[e + 1] += starts[e]
        return pm, starts
    # Points in rows ascending (as the edge stage lists them): the rows within reach of an
    # ellipse's centre are one run of them (pv - cy rounds monotonically), found by
    # bisection; only that run is tested.
    runs = np.empty((n_e, 2), np.int64)
    total = 0
    for e in range(n_e):
        runs[e, 0] = _first_past(pv, cy[e], -reach[e], False)
        runs[e, 1] = max(runs[e, 0], _first_past(pv, cy[e], reach[e], True))
        total += runs[e, 1] - runs[e, 0]
    pm = np.empty(total, np.int64)
    starts = np.zeros(n_e + 1, np.int64)
    k = 0
    for e in range(n_e):
        x, y, r = cx[e], cy[e], reach[e]
        for m in range(runs[e, 0], runs[e, 1]):
            if abs(pu[m] - x) <= r and abs(pv[m] - y) <= r:
                pm[k] = m
                k += 1
        starts[e + 1] = k
    return pm[:k], starts


@_compiled
def _first_past(pv: NDArray[np.float64], cy: float, bound: float, strict: bool
                ) -> int:  # pragma: no cover - compiled
    """The first index of ascending ``pv`` with ``pv - cy`` above ``bound`` (``strict``) or
    at least ``bound`` (its length if none)."""
    lo, hi = 0, pv.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        d = pv[mid] - cy
        if d > bound or (not strict and d == bound):
            hi = mid
        else:
            lo = mid + 1
    return lo


@_compiled
def _sampson(du: float, dv: float, a: float, b: float, c: float, s: float
             ) -> float:  # pragma: no cover - compiled
    """Sampson distance of a point at (du, dv) from the centre of the ellipse of semi-axes
    (a, b) and angle cosine and sine (c, s); see :func:`grouped_distances`."""
    x = (c * du + s * dv) / a
    y = (c * dv - s * du) / b
    xa, yb = x / a, y / b
    grad = 2.0 * math.sqrt(xa * xa + yb * yb) + 1e-12
    return abs(x * x + y * y - 1.0) / grad


@_compiled
def point_distances(points: NDArray[np.float64], cx: float, cy: float, a: float, b: float,
                    c: float, s: float) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Sampson distances of (N, 2) ``points`` to the ellipse (cx, cy, a, b) of angle cosine
    and sine (c, s); see :func:`~stackpick_sim.vision.fitting.ellipse_distances`."""
    out = np.empty(points.shape[0])
    for k in range(points.shape[0]):
        out[k] = _sampson(points[k, 0] - cx, points[k, 1] - cy, a, b, c, s)
    return out


@_compiled
def points_rms(points: NDArray, cx: float, cy: float, a: float, b: float, c: float, s: float
               ) -> float:  # pragma: no cover - compiled
    """The RMS Sampson distance of (N, 2) ``points`` (N > 0; int32 pixels, or float64) to the
    ellipse (cx, cy, a, b) of angle cosine and sine (c, s), as ``sqrt(mean(d * d))`` of
    :func:`point_distances` (numpy's pairwise sum: the same value); see
    :func:`~stackpick_sim.vision.fitting.rms_residual`."""
    m = points.shape[0]
    sq = np.empty(m)
    for k in range(m):
        d = _sampson(points[k, 0] - cx, points[k, 1] - cy, a, b, c, s)
        sq[k] = d * d
    return math.sqrt(_pairwise_sum(sq) / m)


@_compiled
def chain_hits(pixels: NDArray, owner: NDArray[np.int64], n_chains: int, cx: float,
               cy: float, a: float, b: float, c: float, s: float, tol_px: float
               ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """Per chain (``n_chains``), how many of its pixels (rows of the (N, 2) ``pixels``, int32
    or float64, whose chains ``owner`` (N,) gives) lie closer than ``tol_px`` (Sampson) to the
    ellipse (cx, cy, a, b) of angle cosine and sine (c, s): ``np.bincount`` of the owners of
    the near pixels; see :func:`~stackpick_sim.vision.regroup.chains_on`.

    Only the pixels within the bounding box of the ellipse scaled by :func:`_near_scale`
    (and a pixel more) are measured: the others lie farther off (the Sampson distance of a
    point at scale r >= 1 is at least min(a, b) (r - 1 / r) / 2)."""
    hits = np.zeros(n_chains, np.int64)
    scale = _near_scale(tol_px, min(a, b))
    reach_u = math.hypot(a * c, b * s) * scale + 1.0
    reach_v = math.hypot(a * s, b * c) * scale + 1.0
    for k in range(pixels.shape[0]):
        du, dv = pixels[k, 0] - cx, pixels[k, 1] - cy
        if abs(du) <= reach_u and abs(dv) <= reach_v and _sampson(du, dv, a, b, c, s) < tol_px:
            hits[owner[k]] += 1
    return hits


@_compiled
def _near_scale(tol_px: float, minor: float) -> float:  # pragma: no cover - compiled
    """A scale r of an ellipse of semi-minor axis ``minor`` beyond which no point has a
    Sampson distance below ``tol_px``: the root of min(a, b) (r - 1 / r) / 2 = tol_px, with a
    margin of a millionth (inf for a degenerate axis). The Sampson distance |Q| / |grad Q| of
    Q = x^2 + y^2 - 1 (x, y in units of the axes, r^2 = x^2 + y^2) has |grad Q| <= 2 r /
    min(a, b), so at r >= 1 it is at least min(a, b) (r^2 - 1) / (2 r)."""
    if not minor > 0.0:
        return math.inf
    t = tol_px / minor
    return (t + math.sqrt(t * t + 1.0)) * (1.0 + 1e-6)


@_compiled
def strongest_gradients(stacked: NDArray[np.int16]
                        ) -> tuple[NDArray[np.int16], NDArray[np.int16]]:  # pragma: no cover
    """Per pixel, the (dx, dy) of the channel with the largest |dx| + |dy| (the first of
    equals) of per-channel Sobel gradients ``stacked`` (C, 2, H, W) (channel c's dx and dy
    at [c, 0] and [c, 1]); (H, W) each. Channel by channel, each a pass a later channel
    replaces where it is strictly stronger (Sobel 3x3 terms of uint8 images are at most
    4 x 255, so the L1 sum fits int16); see :func:`~stackpick_sim.vision.edges.
    colour_gradients`."""
    channels, _, h, w = stacked.shape
    n = h * w
    flat = stacked.reshape(channels, 2, n)
    best_x, best_y = np.empty((h, w), np.int16), np.empty((h, w), np.int16)
    out_x, out_y = best_x.ravel(), best_y.ravel()
    best = np.empty(n, np.int16)
    gx, gy = flat[0, 0], flat[0, 1]
    for i in range(n):
        x, y = gx[i], gy[i]
        out_x[i], out_y[i] = x, y
        best[i] = abs(x) + abs(y)
    for c in range(1, channels):
        gx, gy = flat[c, 0], flat[c, 1]
        for i in range(n):  # branch-free selects: the loop vectorises
            x, y = gx[i], gy[i]
            m = np.int16(abs(x) + abs(y))
            stronger = m > best[i]
            out_x[i] = x if stronger else out_x[i]
            out_y[i] = y if stronger else out_y[i]
            best[i] = m if stronger else best[i]
    return best_x, best_y


@_compiled
def stride_magnitudes(dx: NDArray[np.int16], dy: NDArray[np.int16], stride: int, gain: float
                      ) -> NDArray[np.float32]:  # pragma: no cover - compiled
    """The gradient magnitudes over ``gain`` of every ``stride``-th row and column of (H, W)
    Sobel gradients, row-major, in float32: ``np.sqrt(sx * sx + sy * sy).ravel() / gain`` of
    the float32 samples ``sx``, ``sy`` (the same float32 operations); see
    :func:`~stackpick_sim.vision.edges.adaptive_thresholds`."""
    h, w = dx.shape
    cols = (w + stride - 1) // stride
    out = np.empty(((h + stride - 1) // stride) * cols, np.float32)
    g = np.float32(gain)
    k = 0
    for r in range(0, h, stride):
        for c in range(0, w, stride):
            x, y = np.float32(dx[r, c]), np.float32(dy[r, c])
            out[k] = np.sqrt(x * x + y * y) / g
            k += 1
    return out


@_compiled
def _digit_of(hist: NDArray[np.int64], k: int) -> tuple[int, int]:  # pragma: no cover
    """The digit (histogram bin) the ``k``-th smallest key falls in and its rank among the
    keys of that digit."""
    digit = 0
    while k >= hist[digit]:
        k -= hist[digit]
        digit += 1
    return digit, k


@_compiled
def _kth_key(keys: NDArray[np.int32], low: NDArray[np.int64], k_low: int, k_high: int,
             buf: NDArray[np.int32]) -> tuple[int, int]:  # pragma: no cover - compiled
    """The ``k_low``-th and ``k_high``-th smallest (from 0) of non-negative int32 ``keys``
    (any order, unchanged), by radix selection on their bits 20-30, then 10-19 and 0-9: a
    level counts the candidates' digits, keeps those of the digit the rank falls in
    (compacted into ``buf``, scratch of the keys' length) and counts the rank from that
    digit's first; after the last level every candidate is the key sought. The first level's
    counts serve both ranks; ``low``: scratch of 2048. Any selection gives the same values:
    an order statistic is unique."""
    top = np.zeros(2048, np.int64)
    for i in range(keys.shape[0]):
        top[keys[i] >> 20] += 1
    found = np.empty(2, np.int64)
    for t in range(2):
        digit, k = _digit_of(top, k_low if t == 0 else k_high)
        src, m, shift, mask = keys, keys.shape[0], 20, 2047
        for _ in range(3):
            kept = 0
            for i in range(m):
                if (src[i] >> shift) & mask == digit:
                    buf[kept] = src[i]
                    kept += 1
            src, m = buf, kept
            if shift == 0:
                break
            shift -= 10
            mask = 1023
            low[:1024] = 0
            for i in range(m):
                low[(src[i] >> shift) & mask] += 1
            digit, k = _digit_of(low, k)
        found[t] = src[0]
    return found[0], found[1]


@_compiled
def stride_quantiles(dx: NDArray[np.int16], dy: NDArray[np.int16], stride: int, gain: float
                     ) -> tuple[float, float, int]:  # pragma: no cover - compiled
    """The order statistics :func:`~stackpick_sim.vision.edges.adaptive_thresholds` reads of
    the :func:`stride_magnitudes` sample (N values): the ``N // 2``-th and the
    ``min(N - 1, int(0.99 N))``-th smallest (from 0; what ``np.partition`` puts there, as
    float32 values), and N; (0, 0, 0) for an empty sample. The magnitudes are non-negative
    float32, whose bit patterns order as their values, so the selection runs on those
    (:func:`_kth_key`) in place of a partition."""
    mags = stride_magnitudes(dx, dy, stride, gain)
    n = mags.shape[0]
    if n == 0:
        return 0.0, 0.0, 0
    keys = mags.view(np.int32)
    picked = np.empty(2, np.int32)
    picked[0], picked[1] = _kth_key(keys, np.empty(2048, np.int64), n // 2,
                                    min(n - 1, int(0.99 * n)), np.empty(n, np.int32))
    values = picked.view(np.float32)
    return float(values[0]), float(values[1]), n


@_compiled
def _block_sum(x: NDArray[np.float64], lo: int, n: int) -> float:  # pragma: no cover
    """numpy's sum of a block of at most 128 elements ``x[lo:lo + n]``: in order below 8,
    else eight partial sums combined pairwise, then the remainder in order."""
    if n < 8:
        total = 0.0
        for k in range(lo, lo + n):
            total += x[k]
        return total
    r = x[lo:lo + 8].copy()
    k = 8
    while k < n - n % 8:
        for q in range(8):
            r[q] += x[lo + k + q]
        k += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while k < n:
        total += x[lo + k]
        k += 1
    return total


@_compiled
def _pairwise_sum(x: NDArray[np.float64]) -> float:  # pragma: no cover - compiled
    """numpy's pairwise sum of ``x`` (:func:`_block_sum` on blocks of up to 128 elements,
    longer runs halved at a multiple of 8 and the halves' sums added), so the same value as
    ``x.sum()``; the recursion unrolled on a stack."""
    # Frames (lo, n, state): state 0 to split, 1 once the left half's sum is on the stack.
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    states = np.zeros(64, np.int64)
    sums = np.empty(64)
    top, done = 0, 0
    los[0], ns[0] = 0, x.shape[0]
    while top >= 0:
        n = ns[top]
        if n <= 128:
            sums[done] = _block_sum(x, los[top], n)
            done += 1
            top -= 1
            continue
        half = n // 2
        half -= half % 8
        if states[top] == 0:  # the left half first
            states[top] = 1
            top += 1
            los[top], ns[top], states[top] = los[top - 1], half, 0
        elif states[top] == 1:  # then the right half
            states[top] = 2
            top += 1
            los[top], ns[top], states[top] = los[top - 1] + half, n - half, 0
        else:  # both done: their sum replaces them
            sums[done - 2] = sums[done - 2] + sums[done - 1]
            done -= 1
            top -= 1
    return sums[0]


@_compiled
def pair_lies(points: NDArray[np.int32], n: int, cx: float, cy: float, a: float, b: float,
              c: float, s: float, tol_px: float
              ) -> tuple[float, int, int]:  # pragma: no cover - compiled
    """For (N, 2) ``points``, two arcs one after the other (the first ``n``), and the ellipse
    (cx, cy, a, b) of angle cosine and sine (c, s): the RMS Sampson distance of all points
    (as ``sqrt(mean(d * d))``), and how many of the first arc's and of the second's lie
    closer than ``tol_px`` (see :func:`~stackpick_sim.vision.regroup.arc_pair_ellipses`)."""
    m = points.shape[0]
    sq = np.empty(m)
    near_first = near_second = 0
    for k in range(m):
        d = _sampson(points[k, 0] - cx, points[k, 1] - cy, a, b, c, s)
        sq[k] = d * d
        if d < tol_px:
            if k < n:
                near_first += 1
            else:
                near_second += 1
    return math.sqrt(_pairwise_sum(sq) / m), near_first, near_second


@_compiled
def near_pairs_split(pu: NDArray[np.float64], pv: NDArray[np.float64],
                     rows: NDArray[np.float64], reach: NDArray[np.float64], tol_px: float,
                     split: int) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                          NDArray[np.int64],
                                          NDArray[np.int64]]:  # pragma: no cover - compiled
    """(ellipse, point) index pairs, ellipse by ellipse and points ascending, of the points
    (pu, pv) within ``reach[e]`` of ellipse e's centre on both axes (:func:`box_pairs`) and
    closer than ``tol_px`` to it (Sampson distance, :func:`grouped_distances`; ellipse e is
    column e of (6, E) ``rows``): those of the points before ``split``, then those of the
    others; see :func:`~stackpick_sim.vision.fitting.within_pairs_split`."""
    n_e, n_p = rows.shape[1], pu.shape[0]
    count = _box_count(pu, pv, rows[0], rows[1], reach)
    pe, pm = np.empty(count, np.int64), np.empty(count, np.int64)
    re, rm = np.empty(count, np.int64), np.empty(count, np.int64)
    k = j = 0
    for e in range(n_e):
        cx, cy, a, b, c, s = rows[0, e], rows[1, e], rows[2, e], rows[3, e], rows[4, e], rows[5, e]
        r = reach[e]
        ia, ib = 1.0 / a, 1.0 / b
        for m in range(n_p):
            du, dv = pu[m] - cx, pv[m] - cy
            if (abs(du) <= r and abs(dv) <= r
                    and _near_sampson(du, dv, a, b, c, s, ia, ib, tol_px)):
                if m < split:
                    pe[k], pm[k] = e, m
                    k += 1
                else:
                    re[j], rm[j] = e, m
                    j += 1
    return pe[:k], pm[:k], re[:j], rm[:j]


@_compiled
def _near_sampson(du: float, dv: float, a: float, b: float, c: float, s: float, ia: float,
                  ib: float, tol_px: float) -> bool:  # pragma: no cover - compiled
    """``_sampson(du, dv, a, b, c, s) < tol_px`` (``ia``, ``ib``: 1 / a, 1 / b), told
    without a division where a margin allows: the squared distance is Q^2 / (4 G) (Q =
    x^2 + y^2 - 1, G = (x / a)^2 + (y / b)^2, x and y in units of the axes), so Q^2 against
    4 tol^2 G, computed with the reciprocals, decides unless the two lie within a relative
    1e-6 of each other or G is below 1e-8 (their rounding, and the distance's 1e-12 guard
    against G = 0, are then orders of magnitude below the margin); there the distance itself
    is computed."""
    x, y = (c * du + s * dv) * ia, (c * dv - s * du) * ib
    q = x * x + y * y - 1.0
    xa, yb = x * ia, y * ib
    g = xa * xa + yb * yb
    lhs, rhs = q * q, 4.0 * tol_px * tol_px * g
    if g > 1e-8:  # the guard's share of the distance below 1e-8
        if lhs < rhs * (1.0 - 1e-6):
            return True
        if lhs > rhs * (1.0 + 1e-6):
            return False
    return _sampson(du, dv, a, b, c, s) < tol_px


@_compiled
def _bow(pixels: NDArray, start: int, stop: int) -> float:  # pragma: no cover - compiled
    """RMS spread (px) across its principal line of the piece ``pixels[start:stop]`` of
    (N, 2) ``pixels``; see :func:`~stackpick_sim.vision.fitting.bow_px` (the same sums, in
    pixel order)."""
    n = stop - start
    su = 0.0
    sv = 0.0
    for j in range(start, stop):
        su += pixels[j, 0]
        sv += pixels[j, 1]
    mu, mv = su / n, sv / n
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for j in range(start, stop):
        cu, cv = pixels[j, 0] - mu, pixels[j, 1] - mv
        sxx += cu * cu
        syy += cv * cv
        sxy += cu * cv
    k = max(1, n)
    half_trace, det = 0.5 * (sxx + syy) / k, (sxx * syy - sxy * sxy) / (k * k)
    smallest = half_trace - math.sqrt(max(0.0, half_trace * half_trace - det))
    return math.sqrt(max(0.0, smallest))


@_compiled
def _near_set(image: NDArray[np.uint8], r: int, c: int, radius: int
              ) -> bool:  # pragma: no cover - compiled
    """Whether a pixel within ``radius`` (Chebyshev) of (r, c), on the image, is set."""
    h, w = image.shape
    if radius == 1 and 0 < r < h - 1 and 0 < c < w - 1:  # the 3x3 block, on the image
        above, row, below = image[r - 1], image[r], image[r + 1]
        return (above[c - 1] | above[c] | above[c + 1] | row[c - 1] | row[c] | row[c + 1]
                | below[c - 1] | below[c] | below[c + 1]) != 0
    for i in range(max(0, r - radius), min(h, r + radius + 1)):
        for j in range(max(0, c - radius), min(w, c + radius + 1)):
            if image[i, j] > 0:
                return True
    return False


@_compiled
def outline_support(support: NDArray[np.uint8], rows: NDArray[np.float64],
                    counts: NDArray[np.int64], ct: NDArray[np.float64],
                    st: NDArray[np.float64], radius: int
                    ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Per ellipse (row e of (E, 6) ``rows``: cx, cy, a, b and the angle's cosine and sine),
    the share of its ``counts[e]`` outline samples (parameters' cosines ``ct`` and sines
    ``st``, ellipse by ellipse) whose rounded pixel lies within ``radius`` px (Chebyshev)
    of a set pixel of the (H, W) ``support`` map (a sample off the map: not; radius 1 on an
    edge map: the lookup in its 3x3 dilation); see
    :func:`~stackpick_sim.vision.merging.support_shares`."""
    h, w = support.shape
    out = np.empty(counts.shape[0])
    k = 0
    for e in range(counts.shape[0]):
        cx, cy, a, b, c, s = rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3], rows[e, 4], rows[e, 5]
        hits = 0
        # Samples about a pixel apart often round to the pixel before: its answer stands.
        last_u, last_v, hit = -1.0, -1.0, False
        for _ in range(counts[e]):
            x, y = a * ct[k], b * st[k]
            u = np.rint(c * x + cx - s * y)
            v = np.rint(s * x + cy + c * y)
            if u != last_u or v != last_v:
                last_u, last_v = u, v
                hit = (0.0 <= u < w and 0.0 <= v < h
                       and _near_set(support, int(v), int(u), radius))
            hits += hit
            k += 1
        out[e] = hits / counts[e]
    return out


@_compiled
def outline_rows(ellipses: NDArray[np.float64]
                 ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:  # pragma: no cover
    """Per ellipse of (E, 5) ``ellipses`` cx, cy, a, b, angle (deg): its outline's sample
    count, max(16, ceil(perimeter)) with Ramanujan's perimeter (px), and its row cx, cy, a,
    b, cos angle, sin angle ((E, 6)); see :func:`~stackpick_sim.vision.contrast.perimeter_px`
    and :func:`~stackpick_sim.vision.merging.support_shares` (the same arithmetic)."""
    n = ellipses.shape[0]
    counts, rows = np.empty(n, np.int64), np.empty((n, 6))
    for e in range(n):
        a, b = ellipses[e, 2], ellipses[e, 3]
        h = ((a - b) / (a + b)) ** 2
        perimeter = math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))
        counts[e] = max(16, math.ceil(perimeter))
        t = ellipses[e, 4] * (math.pi / 180.0)
        rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3] = ellipses[e, 0], ellipses[e, 1], a, b
        rows[e, 4], rows[e, 5] = math.cos(t), math.sin(t)
    return counts, rows


@_compiled
def grouped_distances(rows: NDArray[np.float64], counts: NDArray[np.int64],
                      pu: NDArray[np.float64], pv: NDArray[np.float64]
                      ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Sampson distances of points (pu, pv) that run ellipse by ellipse (``counts[e]`` of
    them to column e of (6, E) ``rows``: cx, cy, a, b and the angle's cosine and sine, those
    two computed by numpy's own cos and sin); see
    :func:`~stackpick_sim.vision.fitting.grouped_distances`."""
    out = np.empty(pu.shape[0])
    k = 0
    for e in range(rows.shape[1]):
        cx, cy, a, b, c, s = rows[0, e], rows[1, e], rows[2, e], rows[3, e], rows[4, e], rows[5, e]
        for _ in range(counts[e]):
            du, dv = pu[k] - cx, pv[k] - cy
            x = (c * du + s * dv) / a
            y = (c * dv - s * du) / b
            xa, yb = x / a, y / b
            grad = 2.0 * math.sqrt(xa * xa + yb * yb) + 1e-12
            out[k] = abs(x * x + y * y - 1.0) / grad
            k += 1
    return out


@_compiled
def _bilinear(img: NDArray[np.int16], u0: np.int64, v0: np.int64, w00: float, w10: float,
              w01: float, w11: float) -> float:  # pragma: no cover - compiled
    """The four corners from (u0, v0) weighted, summed in the array version's order."""
    return (img[v0, u0] * w00 + img[v0, u0 + 1] * w10 + img[v0 + 1, u0] * w01
            + img[v0 + 1, u0 + 1] * w11)


@_compiled
def bilinear_uv(gx: NDArray[np.int16], gy: NDArray[np.int16], u: NDArray[np.float64],
                v: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # pragma: no cover
    """Bilinear samples of two (H, W) images at points (u, v), clamped inside; see
    :func:`~stackpick_sim.vision.refine._bilinear_uv`."""
    h, w = gx.shape
    ox, oy = np.empty(u.shape[0]), np.empty(u.shape[0])
    for k in range(u.shape[0]):
        uk = min(max(u[k], 0.0), w - 1.001)
        vk = min(max(v[k], 0.0), h - 1.001)
        u0, v0 = np.int64(uk), np.int64(vk)
        fu, fv = uk - u0, vk - v0
        gu, gv = 1 - fu, 1 - fv
        w00, w10, w01, w11 = gu * gv, fu * gv, gu * fv, fu * fv
        ox[k] = _bilinear(gx, u0, v0, w00, w10, w01, w11)
        oy[k] = _bilinear(gy, u0, v0, w00, w10, w01, w11)
    return ox, oy


@_compiled
def subpixel_columns(gx: NDArray[np.int16], gy: NDArray[np.int16], u: NDArray[np.float64],
                     v: NDArray[np.float64], gu: NDArray[np.float64], gv: NDArray[np.float64],
                     max_shift: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # pragma: no cover
    """Edge pixels (u, v) moved to the gradient-magnitude peak along their unit gradients
    (gu, gv): a parabola through the bilinear magnitudes one pixel either side, the shift
    clamped to ``max_shift``; see :func:`~stackpick_sim.vision.refine._subpixel_columns`."""
    n = u.shape[0]
    qu, qv = np.empty(3 * n), np.empty(3 * n)
    for j in range(3):
        step = j - 1.0
        for k in range(n):
            qu[j * n + k] = u[k] + step * gu[k]
            qv[j * n + k] = v[k] + step * gv[k]
    bx, by = bilinear_uv(gx, gy, qu, qv)
    su, sv = np.empty(n), np.empty(n)
    for k in range(n):
        before = np.hypot(bx[k], by[k])
        centre = np.hypot(bx[n + k], by[n + k])
        after = np.hypot(bx[2 * n + k], by[2 * n + k])
        curvature = before - 2.0 * centre + after
        shift = 0.5 * (before - after) / curvature if curvature < -1e-9 else 0.0
        shift = min(max(shift, -max_shift), max_shift)
        su[k] = u[k] + shift * gu[k]
        sv[k] = v[k] + shift * gv[k]
    return su, sv


@_compiled
def _along_one(cx: float, cy: float, fa: float, fh: float, fb: float, u: float, v: float,
               gu: float, gv: float, dist_sq: float, cos_sq: float
               ) -> bool:  # pragma: no cover - compiled
    """The along-the-outline test of one pixel (u, v) with unit gradient (gu, gv) against
    one ellipse's form (cx, cy, A, H, B); ``dist_sq`` = 4 tol^2, ``cos_sq`` = the normal
    cone's cosine squared; see :func:`~stackpick_sim.vision.refine._along_test`."""
    du = u - cx
    dv = v - cy
    nu = fa * du + fh * dv
    nv = fb * dv + fh * du
    f = du * nu + dv * nv - 1.0
    n2 = nu * nu + nv * nv
    dot = nu * gu + nv * gv
    return f * f < dist_sq * n2 and dot * dot >= cos_sq * n2


@_compiled
def along_select(forms: NDArray[np.float64], starts: NDArray[np.int64],
                 active: NDArray[np.bool_], at: NDArray[np.int64], u: NDArray[np.float64],
                 v: NDArray[np.float64], gu: NDArray[np.float64], gv: NDArray[np.float64],
                 dist_sq: float, cos_sq: float
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64],
                            NDArray[np.float32]]:  # pragma: no cover - compiled
    """The (ellipse, pixel) pairs ``starts[e]:starts[e + 1]`` of each ``active`` ellipse e
    (row e of (E, 5) ``forms``) that pass :func:`_along_one`'s test, pair k being pixel
    ``at[k]`` (u, v) with unit gradient (gu, gv) (columns (N,)): their indices (ascending),
    where each ellipse's run of them starts and ends ((E + 1,) bounds), and their pixels
    (u, v) as (K, 2) float32 rows (the fits' input); see
    :func:`~stackpick_sim.vision.refine.refine_all`."""
    n_e = forms.shape[0]
    sel = np.empty(at.shape[0], np.int64)
    bounds = np.zeros(n_e + 1, np.int64)
    count = 0
    for e in range(n_e):
        if active[e]:
            cx, cy, fa, fh, fb = forms[e, 0], forms[e, 1], forms[e, 2], forms[e, 3], forms[e, 4]
            for k in range(starts[e], starts[e + 1]):
                m = at[k]
                if _along_one(cx, cy, fa, fh, fb, u[m], v[m], gu[m], gv[m], dist_sq, cos_sq):
                    sel[count] = k
                    count += 1
        bounds[e + 1] = count
    out = np.empty((count, 2), np.float32)
    for j in range(count):
        m = at[sel[j]]
        out[j, 0] = np.float32(u[m])
        out[j, 1] = np.float32(v[m])
    return sel[:count], bounds, out


@_compiled
def subpixel_along(pu: NDArray[np.float64], pv: NDArray[np.float64], gu: NDArray[np.float64],
                   gv: NDArray[np.float64], form: NDArray[np.float64], reach: float,
                   dist_sq: float, cos_sq: float, gx: NDArray[np.int16],
                   gy: NDArray[np.int16], max_shift: float
                   ) -> NDArray[np.float32]:  # pragma: no cover - compiled
    """The edge pixels (pu, pv) with unit gradients (gu, gv) that lie along one ellipse
    (``form``: its (cx, cy, A, H, B); within ``reach`` of its centre on both axes, then
    :func:`_along_one`'s test) moved to their gradient peaks (:func:`subpixel_columns`),
    as (K, 2) float32 in pixel order; see :func:`~stackpick_sim.vision.refine.
    refine_subpixel`."""
    cx, cy, fa, fh, fb = form[0], form[1], form[2], form[3], form[4]
    keep = np.empty(pu.shape[0], np.int64)
    count = 0
    for k in range(pu.shape[0]):
        if (abs(pu[k] - cx) <= reach and abs(pv[k] - cy) <= reach
                and _along_one(cx, cy, fa, fh, fb, pu[k], pv[k], gu[k], gv[k], dist_sq,
                               cos_sq)):
            keep[count] = k
            count += 1
    at = keep[:count]
    su, sv = subpixel_columns(gx, gy, pu[at], pv[at], gu[at], gv[at], max_shift)
    out = np.empty((count, 2), np.float32)
    for k in range(count):
        out[k, 0] = su[k]
        out[k, 1] = sv[k]
    return out


@_compiled
def _normal_gradient(fx: NDArray[np.int16], fy: NDArray[np.int16], h: int, w: int, u: float,
                     v: float, nu: float, nv: float, step: float) -> float:  # pragma: no cover
    """|(gx, gy) . n| read bilinearly (:func:`bilinear_uv`, clamped inside) at (u, v) plus
    ``step`` times the unit normal (nu, nv), the (H, W) = (``h``, ``w``) gradients given
    flat (row-major: ``fx``, ``fy``; flattened once by the caller, as a view made per read
    costs several times the read)."""
    uk = min(max(u + step * nu, 0.0), w - 1.001)
    vk = min(max(v + step * nv, 0.0), h - 1.001)
    u0, v0 = np.int64(uk), np.int64(vk)
    fu, fv = uk - u0, vk - v0
    gu, gv = 1 - fu, 1 - fv
    w00, w10, w01, w11 = gu * gv, fu * gv, gu * fv, fu * fv
    # The four corners by flat index (both >= 0 once clamped), summed as _bilinear sums.
    at = v0 * w + u0
    bx = fx[at] * w00 + fx[at + 1] * w10 + fx[at + w] * w01 + fx[at + w + 1] * w11
    by = fy[at] * w00 + fy[at + 1] * w10 + fy[at + w] * w01 + fy[at + w + 1] * w11
    return abs(bx * nu + by * nv)


@_compiled
def profile_peaks(gx: NDArray[np.int16], gy: NDArray[np.int16], pu: NDArray[np.float64],
                  pv: NDArray[np.float64], nu: NDArray[np.float64], nv: NDArray[np.float64],
                  steps: NDArray[np.float64], step_px: float, threshold: float
                  ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """The gradient peaks across an outline: at each sample (pu, pv) with unit normal
    (nu, nv), the normal gradient |(gx, gy) . n| read bilinearly at offsets ``steps`` (px,
    ``step_px`` apart), its strongest interior sample (the first of equals) placed by a
    parabola through its neighbours (shift clamped to half a step); the (K, 2) peaks of the
    samples whose strongest value reaches ``threshold``, in sample order (none with fewer
    than three steps: no interior sample); see
    :func:`~stackpick_sim.vision.refine.refine_on_profile`. The two outermost offsets are
    read only for a peak next to them that reaches the threshold."""
    n, k = pu.shape[0], steps.shape[0]
    out = np.empty((n, 2))
    if k < 3:
        return out[:0]
    g = np.empty(k)
    count = 0
    h, w = gx.shape
    fx, fy = gx.ravel(), gy.ravel()
    for i in range(n):
        u, v, du, dv = pu[i], pv[i], nu[i], nv[i]
        for j in range(1, k - 1):
            g[j] = _normal_gradient(fx, fy, h, w, u, v, du, dv, steps[j])
        best, top = 1, g[1]
        for j in range(2, k - 1):
            if g[j] > top:
                best, top = j, g[j]
        if top < threshold:
            continue
        before = (g[best - 1] if best > 1
                  else _normal_gradient(fx, fy, h, w, u, v, du, dv, steps[0]))
        after = (g[best + 1] if best < k - 2
                 else _normal_gradient(fx, fy, h, w, u, v, du, dv, steps[k - 1]))
        curvature = before - 2.0 * top + after
        shift = 0.5 * (before - after) / curvature if curvature < -1e-9 else 0.0
        offset = steps[best] + min(max(shift, -0.5), 0.5) * step_px
        out[count, 0] = u + offset * du
        out[count, 1] = v + offset * dv
        count += 1
    return out[:count]


@_compiled
def outline_contrasts(pu: NDArray[np.float64], pv: NDArray[np.float64],
                      nu: NDArray[np.float64], nv: NDArray[np.float64],
                      gx: NDArray[np.int16], gy: NDArray[np.int16],
                      offsets: NDArray[np.float64], window: NDArray[np.int64], gain: float
                      ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Per outline sample (pu, pv) with unit normal (nu, nv): the normal gradient read at the
    pixel nearest each of the ``offsets`` along the normal (0 off the image), the strongest
    of them (the first of equals), then its signed mean over the sample's ``window`` (rows:
    sample indices, summed row by row), as an absolute value over ``gain``; see
    :func:`~stackpick_sim.vision.contrast.contrast_profiles`."""
    h, w = gx.shape
    n = pu.shape[0]
    best = np.empty(n)
    for i in range(n):
        top = -1.0
        for k in range(offsets.shape[0]):
            o = offsets[k]
            if o == 0.0:
                qu, qv = pu[i], pv[i]
            elif o == 1.0:
                qu, qv = pu[i] + nu[i], pv[i] + nv[i]
            elif o == -1.0:
                qu, qv = pu[i] - nu[i], pv[i] - nv[i]
            else:
                qu, qv = pu[i] + o * nu[i], pv[i] + o * nv[i]
            ru, rv = np.rint(qu), np.rint(qv)
            g = 0.0
            if 0.0 <= ru < w and 0.0 <= rv < h:  # tested as floats: any value is safe
                u, v = np.int64(ru), np.int64(rv)
                g = gx[v, u] * nu[i] + gy[v, u] * nv[i]
            if k == 0 or abs(g) > top:
                best[i], top = g, abs(g)
    out = np.empty(n)
    rows = window.shape[0]
    for i in range(n):
        total = best[window[0, i]]
        for r in range(1, rows):
            total += best[window[r, i]]
        out[i] = abs(total / rows) / gain
    return out


@_compiled
def band_hits(pu: NDArray[np.float64], pv: NDArray[np.float64], keep: NDArray[np.bool_],
              image: NDArray[np.uint8], colours: NDArray[np.float64],
              brightest: NDArray[np.float64], belt: NDArray[np.float64], use_belt: bool,
              chroma_tolerance: float, min_brightness: float, belt_delta: float
              ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:  # pragma: no cover
    """Per row s of the (S, P) band pixels (pu, pv) (those ``keep`` marks, on the (H, W, C)
    ``image``): how many there are and how many show the face's colour ``colours[s]`` (C,):
    its chromaticity within ``chroma_tolerance`` (L1), a channel sum between
    ``min_brightness`` times the face's and ``brightest[s]`` times the face's, and (with
    ``use_belt``) some channel more than ``belt_delta`` off the ``belt`` colour; see
    :func:`~stackpick_sim.vision.wall.band_evidences` (the same sums, left to right)."""
    n_sol, per = keep.shape
    h, w, chans = image.shape
    counts = np.zeros(n_sol, np.int64)
    hits = np.zeros(n_sol)
    for s in range(n_sol):
        face_sum = colours[s, 0]
        for c in range(1, chans):
            face_sum += colours[s, c]
        face_sum = max(face_sum, 1.0)
        for k in range(per):
            if not keep[s, k]:
                continue
            ru, rv = np.rint(pu[s, k]), np.rint(pv[s, k])
            if not (0.0 <= ru < w and 0.0 <= rv < h):  # as floats: inf and NaN are off
                continue
            u, v = np.int64(ru), np.int64(rv)
            counts[s] += 1
            total = float(image[v, u, 0])
            for c in range(1, chans):
                total += float(image[v, u, c])
            scale = max(total, 1.0)
            chroma = abs(image[v, u, 0] / scale - colours[s, 0] / face_sum)
            for c in range(1, chans):
                chroma += abs(image[v, u, c] / scale - colours[s, c] / face_sum)
            ok = (chroma <= chroma_tolerance and total >= min_brightness * face_sum
                  and total <= brightest[s] * face_sum)
            if ok and use_belt:
                off = abs(image[v, u, 0] - belt[0])
                for c in range(1, chans):
                    off = max(off, abs(image[v, u, c] - belt[c]))
                ok = off > belt_delta
            if ok:
                hits[s] += 1.0
    return counts, hits


@_compiled
def _insertion_sort(values: NDArray[Any]) -> None:  # pragma: no cover - compiled
    """Sort a short 1-D array in place, ascending (np.sort's order; compiles in a fraction
    of np.sort's time)."""
    for i in range(1, values.shape[0]):
        x = values[i]
        j = i - 1
        while j >= 0 and values[j] > x:
            values[j + 1] = values[j]
            j -= 1
        values[j + 1] = x


@_compiled
def _turns(poly: NDArray[np.int32], closed: bool, signed_deg: float
           ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """The turn (deg, absolute) at each vertex of a polygon (K, 2) (every vertex when
    ``closed``, the inner ones otherwise) and its sign (0 below ``signed_deg``)."""
    count = poly.shape[0]
    verts = np.empty((count + 2, 2), np.int64)
    shift = 1 if closed else 0
    for k in range(count + 2):  # closed: the last vertex, the polygon, its first vertex
        j = (k - shift) % count
        verts[k, 0], verts[k, 1] = poly[j, 0], poly[j, 1]
    if not closed:
        count -= 2
    mag = np.empty(count)
    sign = np.zeros(count, np.int64)
    for k in range(count):
        x0, y0 = verts[k + 1, 0] - verts[k, 0], verts[k + 1, 1] - verts[k, 1]
        x1, y1 = verts[k + 2, 0] - verts[k + 1, 0], verts[k + 2, 1] - verts[k + 1, 1]
        t = math.degrees(math.atan2(x0 * y1 - y0 * x1, x0 * x1 + y0 * y1))
        mag[k] = abs(t)
        if mag[k] >= signed_deg:
            sign[k] = 1 if t > 0 else -1
    return mag, sign


@_compiled
def _cut_vertices(mag: NDArray[np.float64], sign: NDArray[np.int64], closed: bool,
                  corner_deg: float, spike_deg: float, spike_ratio: float
                  ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """The polygon vertices (indices) where :func:`corner_cuts` cuts, given :func:`_turns`."""
    count = mag.shape[0]
    at = np.empty(count, np.int64)
    n_at = 0
    last = 0
    for k in range(count):
        if closed:
            before, after = mag[k - 1], mag[(k + 1) % count]
        else:
            before = mag[k - 1] if k else 0.0
            after = mag[k + 1] if k + 1 < count else 0.0
        cut = mag[k] > corner_deg or (mag[k] > spike_deg
                                      and mag[k] > spike_ratio * max(before, after))
        if sign[k] != 0:
            cut = cut or (last != 0 and sign[k] != last)
            last = sign[k]
        if cut:
            at[n_at] = k if closed else k + 1
            n_at += 1
    return at[:n_at]


@_compiled
def corner_cuts(chain: NDArray[np.int32], poly: NDArray[np.int32], closed: bool,
                corner_deg: float, spike_deg: float, spike_ratio: float, signed_deg: float
                ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """Where an ordered (N, 2) ``chain`` is cut, ascending chain indices: the first pixel
    equal to each vertex of its polygon ``poly`` (K, 2) (cyclic when ``closed``) that turns
    by more than ``corner_deg``, by more than ``spike_deg`` and ``spike_ratio`` times either
    neighbour, or against the sign of the previous vertex turning by ``signed_deg`` or more;
    see :func:`~stackpick_sim.vision.segments.split_chain`."""
    mag, sign = _turns(poly, closed, signed_deg)
    at = _cut_vertices(mag, sign, closed, corner_deg, spike_deg, spike_ratio)
    cuts = np.empty(at.shape[0], np.int64)
    for j in range(at.shape[0]):
        u, v = poly[at[j], 0], poly[at[j], 1]
        i = 0
        while i < chain.shape[0] and (chain[i, 0] != u or chain[i, 1] != v):
            i += 1
        cuts[j] = i if i < chain.shape[0] else 0  # (a polygon keeps chain pixels)
    _insertion_sort(cuts)
    kept = 0  # each cut once
    for j in range(cuts.shape[0]):
        if kept == 0 or cuts[j] != cuts[kept - 1]:
            cuts[kept] = cuts[j]
            kept += 1
    return cuts[:kept]


@_compiled
def outline_near_shares(rows: NDArray[np.float64], counts: NDArray[np.int64],
                        ct: NDArray[np.float64], st: NDArray[np.float64],
                        others: NDArray[np.float64], tol_px: float
                        ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Per pair e: the share of the ``counts[e]`` outline samples of ellipse e (row e of
    (E, 6) ``rows``: cx, cy, a, b and the angle's cosine and sine; parameters' cosines ``ct``
    and sines ``st``, pair by pair) closer than ``tol_px`` to the other ellipse (column e of
    (6, E) ``others``, as :func:`grouped_distances`); see
    :func:`~stackpick_sim.vision.merging.boundary_shares`."""
    out = np.empty(counts.shape[0])
    k = 0
    for e in range(counts.shape[0]):
        cx, cy, a, b, c, s = rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3], rows[e, 4], rows[e, 5]
        ox, oy, oa, ob = others[0, e], others[1, e], others[2, e], others[3, e]
        oc, os = others[4, e], others[5, e]
        close = 0
        for _ in range(counts[e]):
            x, y = a * ct[k], b * st[k]
            u = cx + c * x - s * y
            v = cy + s * x + c * y
            if _sampson(u - ox, v - oy, oa, ob, oc, os) < tol_px:
                close += 1
            k += 1
        out[e] = close / counts[e]
    return out


@_compiled
def _first_above(keys: NDArray[np.float64], x: float, strict: bool
                 ) -> int:  # pragma: no cover - compiled
    """The first index of ascending ``keys`` whose key is above ``x`` (``strict``) or at
    least ``x``: ``np.searchsorted``'s right or left side."""
    lo, hi = 0, keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] > x or (not strict and keys[mid] == x):
            hi = mid
        else:
            lo = mid + 1
    return lo



@_compiled
def interior_counts(params: NDArray[np.float64], sizes: NDArray[np.int64],
                    keys: NDArray[np.float64], width: int
                    ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """Per ellipse (row e of (E, 6) ``params``: cx, cy, the shrunk form's p, q, r and its
    first row), the pixels inside it on its ``sizes[e]`` rows, the pixels given by ascending
    row-major ``keys`` (v ``width`` + u): on each row the open interval of u between the
    form's roots, two binary searches; see
    :func:`~stackpick_sim.vision.occlusion._interior_counts` (the same arithmetic)."""
    out = np.zeros(sizes.shape[0], np.int64)
    for e in range(sizes.shape[0]):
        cx, cy, p, q, r, first = (params[e, 0], params[e, 1], params[e, 2], params[e, 3],
                                  params[e, 4], params[e, 5])
        total = 0
        for j in range(sizes[e]):
            row = first + j
            dv = row - cy
            qdv = q * dv
            disc = qdv * qdv - 4.0 * p * (r * dv * dv - 1.0)
            root = math.sqrt(max(disc, 0.0))
            lo = max((-qdv - root) / (2.0 * p) + cx, -0.5)
            hi = min((-qdv + root) / (2.0 * p) + cx, width - 1.5)
            hi = max(hi, lo) if disc > 0.0 else lo
            base = row * width
            inside = _first_above(keys, base + hi, False) - _first_above(keys, base + lo, True)
            total += max(inside, 0)
        out[e] = total
    return out


@_compiled
def outline_samples(rows: NDArray[np.float64], counts: NDArray[np.int64],
                    ct: NDArray[np.float64], st: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # pragma: no cover
    """The outline samples of each ellipse (row e of (E, 6) ``rows``: cx, cy, a, b and the
    angle's cosine and sine; ``counts[e]`` samples at parameters of cosines ``ct`` and sines
    ``st``, ellipse by ellipse): (2, N) points and (2, N) unit outward normals (the implicit
    form's gradient); see :func:`~stackpick_sim.vision.contrast.outlines`."""
    n = ct.shape[0]
    pts = np.empty((2, n))
    normals = np.empty((2, n))
    k = 0
    for e in range(counts.shape[0]):
        cx, cy, a, b, c, s = rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3], rows[e, 4], rows[e, 5]
        for _ in range(counts[e]):
            x, nx = a * ct[k], b * ct[k]
            y, ny = b * st[k], a * st[k]
            norm = np.hypot(nx, ny)
            nx /= norm
            ny /= norm
            pts[0, k] = cx + c * x - s * y
            pts[1, k] = cy + s * x + c * y
            normals[0, k] = c * nx - s * ny
            normals[1, k] = s * nx + c * ny
            k += 1
    return pts, normals


@_compiled
def junction_ends(pu: NDArray[np.float64], pv: NDArray[np.float64],
                  ends: NDArray[np.float64], owner: NDArray[np.int64],
                  params: NDArray[np.float64], reach: float, junction_sq: float,
                  crossing_sq: float, tol_px: float
                  ) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    """Per gap end k ((K, 2) ``ends``, of ellipse ``owner[k]``: row of (E, 8) ``params``,
    cx, cy, the angle's cosine and sine, a, b and the axes less the inner margin): whether
    among the edge pixels (pu, pv) (rows ascending) within ``reach`` of it one off the
    ellipse (Sampson distance above ``tol_px``) lies within ``junction_sq`` (px^2) of it and
    one off it and inside the inner axes within ``crossing_sq``; see
    :func:`~stackpick_sim.vision.kernels_pose.gap_evidence` (the same arithmetic)."""
    out = np.zeros(ends.shape[0], np.bool_)
    reach_sq = reach * reach
    for k in range(ends.shape[0]):
        eu, ev = ends[k, 0], ends[k, 1]
        e = owner[k]
        cx, cy, c, s, a, b = (params[e, 0], params[e, 1], params[e, 2], params[e, 3],
                              params[e, 4], params[e, 5])
        a_in, b_in = params[e, 6], params[e, 7]
        junction = crossing = False
        m = _first_above(pv, ev - reach, False)
        stop = _first_above(pv, ev + reach, True)
        while m < stop:
            du_end, dv_end = pu[m] - eu, pv[m] - ev
            d2 = du_end * du_end + dv_end * dv_end
            if d2 <= reach_sq:
                du, dv = pu[m] - cx, pv[m] - cy
                xr, yr = c * du + s * dv, -s * du + c * dv
                x, y = xr / a, yr / b
                xa, yb = x / a, y / b
                dist = abs(x * x + y * y - 1.0) / (2.0 * math.sqrt(xa * xa + yb * yb) + 1e-12)
                if dist > tol_px:
                    if d2 <= junction_sq:
                        junction = True
                    xs, ys = xr / a_in, yr / b_in
                    if xs * xs + ys * ys < 1.0 and d2 <= crossing_sq:
                        crossing = True
            m += 1
        out[k] = junction and crossing
    return out


@_compiled
def face_median(image: NDArray[np.uint8], cx: float, cy: float, sa: float, sb: float,
                c: float, s: float, ct: NDArray[np.float64], st: NDArray[np.float64]
                ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Per channel of the (H, W, C) ``image``, the median of its values at the pixels
    nearest the points (cx + c x - s y, cy + s x + c y), x = ``sa`` ct, y = ``sb`` st
    (clamped into the image): the mean of the two middle values of an even count; see
    :func:`~stackpick_sim.vision.wall.face_colour`."""
    h, w, chans = image.shape
    n = ct.shape[0]
    values = np.empty((chans, n), np.uint8)
    for k in range(n):
        x, y = sa * ct[k], sb * st[k]
        u = min(max(np.int64(np.rint(cx + c * x + -s * y)), 0), w - 1)
        v = min(max(np.int64(np.rint(cy + s * x + c * y)), 0), h - 1)
        for ch in range(chans):
            values[ch, k] = image[v, u, ch]
    out = np.empty(chans)
    for ch in range(chans):
        ordered = values[ch]
        _insertion_sort(ordered)
        out[ch] = 0.5 * (float(ordered[(n - 1) // 2]) + ordered[n // 2])
    return out


@_compiled
def band_points(vectors: NDArray[np.float64], ct: NDArray[np.float64],
                st: NDArray[np.float64], depths: NDArray[np.float64]
                ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """(3, S, D x P) camera-frame points of the wall bands of S solutions, ``vectors`` (4, S,
    3) their normals, centres and rim bases u, v: at depth d (of D) and rim point p (of P,
    at (``ct[p]``, ``st[p]``)), centre + ct u + st v + depth normal, depth by depth; see
    :func:`~stackpick_sim.vision.wall.solution_band_points` (the same arithmetic)."""
    n_s, n_p, n_d = vectors.shape[1], ct.shape[0], depths.shape[0]
    out = np.empty((3, n_s, n_d * n_p))
    for c in range(3):
        for s in range(n_s):
            normal, centre = vectors[0, s, c], vectors[1, s, c]
            u, v = vectors[2, s, c], vectors[3, s, c]
            for p in range(n_p):
                rim = (centre + ct[p] * u) + st[p] * v
                for d in range(n_d):
                    out[c, s, d * n_p + p] = rim + depths[d] * normal
    return out


@_compiled
def _quadric(q: NDArray[np.float64], x0: float, x1: float, x2: float
             ) -> float:  # pragma: no cover - compiled
    """x^T Q x of the symmetric 3x3 form given by its entries ``q`` (Q00, Q01, Q02, Q11,
    Q12, Q22), summed as :func:`~stackpick_sim.vision.pose.unit_circle_poses` does."""
    return (q[0] * x0 * x0 + q[3] * x1 * x1 + q[5] * x2 * x2
            + 2.0 * (q[1] * x0 * x1 + q[2] * x0 * x2 + q[4] * x1 * x2))


@_compiled
def _basis_first(n0: float, n1: float, n2: float
                 ) -> tuple[float, float, float, bool]:  # pragma: no cover - compiled
    """The first vector of :func:`~stackpick_sim.vision.wall.plane_basis` of the normal
    (n0, n1, n2), in its arithmetic, and False where that divides by zero."""
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if norm == 0.0:
        return 0.0, 0.0, 0.0, False
    b0, b1, b2 = n0 / norm, n1 / norm, n2 / norm
    if abs(b0) < 0.9:
        u0, u1, u2 = 0.0, b2, -b1
    else:
        u0, u1, u2 = -b2, 0.0, b0
    un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if un == 0.0:
        return 0.0, 0.0, 0.0, False
    return u0 / un, u1 / un, u2 / un, True


@_compiled
def circle_solutions(q: NDArray[np.float64], evals: NDArray[np.float64],
                     evecs: NDArray[np.float64], terms: NDArray[np.float64],
                     camera: NDArray[np.float64]
                     ) -> tuple[NDArray[np.float64], bool]:  # pragma: no cover - compiled
    """The two unit-radius circle poses of an ellipse from its cone ``q`` (the six entries
    of K^T C K, as :func:`_quadric` reads them) and that form's ascending ``evals`` (3,) and
    ``evecs`` (3, 3, eigenvectors in columns): (2, 2, 3) rows (normal, centre) per solution,
    in the order and with the arithmetic of :func:`~stackpick_sim.vision.pose.
    unit_circle_poses`. ``terms``: the ellipse's centre, the cosine and sine of its angle
    and its squared axes (cx, cy, c, s, a^2, b^2); ``camera``: fx, fy, cx, cy. False (and
    no poses) where that arithmetic divides by zero."""
    out = np.zeros((2, 2, 3))
    fx, fy, kcx, kcy = camera[0], camera[1], camera[2], camera[3]
    form = q.copy()
    if (evals[0] > 0) + (evals[1] > 0) + (evals[2] > 0) == 1:  # one positive: negate
        for i in range(6):
            form[i] = -q[i]
        l3, l2, l1 = -evals[2], -evals[1], -evals[0]
        j3, j1 = 2, 0
    else:
        l3, l2, l1 = evals[0], evals[1], evals[2]
        j3, j1 = 0, 2
    if l1 - l3 == 0.0:
        return out, False
    g = (l1 - l2) / (l1 - l3)
    g = math.sqrt(g if g > 0.0 else 0.0)
    h = (l2 - l3) / (l1 - l3)
    h = math.sqrt(h if h > 0.0 else 0.0)
    ex, ey, ct, st, a2, b2 = terms[0], terms[1], terms[2], terms[3], terms[4], terms[5]
    w00, w01, w11 = ct * ct * a2 + st * st * b2, ct * st * (a2 - b2), st * st * a2 + ct * ct * b2
    for k in range(2):
        sign = 1.0 if k == 0 else -1.0
        n0 = sign * g * evecs[0, j1] + h * evecs[0, j3]
        n1 = sign * g * evecs[1, j1] + h * evecs[1, j3]
        n2 = sign * g * evecs[2, j1] + h * evecs[2, j3]
        if not n2 > 0:
            n0, n1, n2 = -n0, -n1, -n2
        m0, m1 = n0 / fx, n1 / fy
        m2 = -kcx / fx * n0 - kcy / fy * n1 + n2
        cm = ex * m0 + ey * m1
        p0 = w00 * m0 + w01 * m1 - ex * cm - ex * m2
        p1 = w01 * m0 + w11 * m1 - ey * cm - ey * m2
        p2 = -cm - m2
        if p2 == 0.0:
            return out, False
        r0, r1 = (p0 / p2 - kcx) / fx, (p1 / p2 - kcy) / fy
        along = n0 * r0 + n1 * r1 + n2
        if along == 0.0:
            return out, False
        x0, x1, x2 = r0 / along, r1 / along, 1.0 / along
        u0, u1, u2, ok = _basis_first(n0, n1, n2)
        across = _quadric(form, u0, u1, u2)
        if not ok or across == 0.0:
            return out, False
        s2 = -_quadric(form, x0, x1, x2) / across
        scale = 1.0 / math.sqrt(1e-300 if 1e-300 > s2 else s2)
        out[k, 0, 0], out[k, 0, 1], out[k, 0, 2] = n0, n1, n2
        out[k, 1, 0], out[k, 1, 1], out[k, 1, 2] = x0 * scale, x1 * scale, x2 * scale
    return out, True


@_compiled
def _set_indices(image: NDArray[np.uint8]) -> NDArray[np.int64]:  # pragma: no cover
    """The flat indices (ascending) of the nonzero pixels of a C-ordered (H, W) uint8 image,
    read eight bytes at a time (a sparse edge map is mostly zero words)."""
    flat = image.ravel()
    size = flat.shape[0]
    words = size // 8
    packed = flat[:words * 8].view(np.uint64)
    out = np.empty(size, np.int64)
    n = 0
    for j in range(words):
        if packed[j]:
            for i in range(8 * j, 8 * j + 8):
                out[n] = i
                n += flat[i] != 0
    for i in range(words * 8, size):
        out[n] = i
        n += flat[i] != 0
    return out[:n]


@_compiled
def _stair_pass(padded: NDArray[np.uint8], at: NDArray[np.int64], n: int,
                lut: NDArray[np.uint8], gone: NDArray[np.int64]) -> int:  # pragma: no cover
    """One pass of :func:`stairs_removed` over the first ``n`` edge pixels ``at`` (flat
    indices, ascending) of the 0/1 map ``padded`` (a zero border of one pixel round the
    image): every pixel's 8-neighbour code (bit j: ring neighbour j clockwise from
    north-west) read before any is cleared, then those whose ``lut`` entry is 1 cleared;
    returns how many edge pixels are left, compacted at the front of ``at`` (``gone``:
    scratch of at least ``n``)."""
    w = padded.shape[1]
    flat = padded.ravel()
    removed = 0
    for k in range(n):
        i = at[k]
        code = (flat[i - w - 1] | flat[i - w] << 1 | flat[i - w + 1] << 2 | flat[i + 1] << 3
                | flat[i + w + 1] << 4 | flat[i + w] << 5 | flat[i + w - 1] << 6
                | flat[i - 1] << 7)
        gone[removed] = k  # branch-free, as the appends of stairs_removed
        removed += lut[code]
    for j in range(removed):
        flat[at[gone[j]]] = 0
    kept = 0
    for k in range(n):
        at[kept] = at[k]
        kept += flat[at[k]]
    return kept


@_compiled
def stairs_removed(edges: NDArray[np.uint8], first: NDArray[np.uint8],
                   second: NDArray[np.uint8]) -> NDArray[np.uint8]:  # pragma: no cover
    """The 0/1 map of the nonzero pixels of ``edges`` (H, W) less the stair corners of two
    table-driven passes (``first``, then ``second``: 256-entry tables of the removable
    8-neighbour codes, bit i the ring neighbour i clockwise from north-west, off the image
    0), each pass reading every code before it clears any; see
    :func:`~stackpick_sim.vision.edges.remove_stairs` (the same pixels)."""
    padded, _, _ = _stairs_pass_pair(edges, first, second)
    return np.ascontiguousarray(padded[1:-1, 1:-1])


@_compiled
def _stairs_pass_pair(edges: NDArray[np.uint8], first: NDArray[np.uint8],
                      second: NDArray[np.uint8]
                      ) -> tuple[NDArray[np.uint8], NDArray[np.int64],
                                 int]:  # pragma: no cover - compiled
    """:func:`stairs_removed` on a map with a zero border of one pixel, the flat indices
    (into it, ascending) of the pixels left at the front of the returned index array, and
    how many."""
    h, w = edges.shape
    wp = w + 2
    padded = np.zeros((h + 2, wp), np.uint8)
    flat = padded.ravel()
    # The set pixels' flat indices (into the padded map, ascending), set to 1 in it.
    found = _set_indices(edges)
    n = found.shape[0]
    at = np.empty(n + 1, np.int64)
    for k in range(n):
        i = found[k]
        at[k] = (i // w + 1) * wp + i % w + 1
        flat[at[k]] = 1
    gone = np.empty(n, np.int64)
    n = _stair_pass(padded, at, n, first, gone)
    n = _stair_pass(padded, at, n, second, gone)
    return padded, at, n


@_compiled
def stairs_removed_pixels(edges: NDArray[np.uint8], first: NDArray[np.uint8],
                          second: NDArray[np.uint8], gx: NDArray[np.int16],
                          gy: NDArray[np.int16]
                          ) -> tuple[NDArray[np.uint8], NDArray[np.float64],
                                     NDArray[np.float64]]:  # pragma: no cover - compiled
    """:func:`stairs_removed` and the :func:`edge_pixels` of its result (with the gradients
    ``gx``, ``gy`` of the map's shape) in one call: the pixels left by the passes are
    already listed in row-major order, so the map is not scanned again."""
    padded, at, n = _stairs_pass_pair(edges, first, second)
    wp = padded.shape[1]
    pts, g = np.empty((2, n)), np.empty((2, n))
    kept = np.zeros(edges.shape, np.uint8)  # the map written pixel by pixel, not copied
    for k in range(n):
        r, c = at[k] // wp - 1, at[k] % wp - 1
        kept[r, c] = 1
        pts[0, k], pts[1, k] = c, r
        x, y = np.float64(gx[r, c]), np.float64(gy[r, c])
        norm = max(np.hypot(x, y), 1e-9)
        g[0, k], g[1, k] = x / norm, y / norm
    return kept, pts, g


@_compiled
def edge_pixels(edges: NDArray[np.uint8], gx: NDArray[np.int16], gy: NDArray[np.int16]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:  # pragma: no cover
    """The nonzero pixels of ``edges`` (H, W) in row-major order as (2, M) rows u, v and
    their unit gradients (gx, gy) / max(hypot, 1e-9) as (2, M) rows; see
    :func:`~stackpick_sim.vision.refine.edge_points` (the same values)."""
    h, w = edges.shape
    src = edges.ravel()
    fx, fy = gx.ravel(), gy.ravel()
    n = 0
    for i in range(h * w):
        if src[i]:
            n += 1
    pts, g = np.empty((2, n)), np.empty((2, n))
    k = 0
    for i in range(h * w):
        if src[i]:
            pts[0, k], pts[1, k] = i % w, i // w
            x, y = np.float64(fx[i]), np.float64(fy[i])
            norm = max(np.hypot(x, y), 1e-9)
            g[0, k], g[1, k] = x / norm, y / norm
            k += 1
    return pts, g


@_compiled
def row_keys(u: NDArray[np.float64], v: NDArray[np.float64]
             ) -> tuple[NDArray[np.float64], int, bool]:  # pragma: no cover - compiled
    """Row-major keys v W + u of pixels (u, v) (integer values >= 0, (N,) columns) for W two
    past the largest u (0 without pixels), W, and whether the keys ascend; see
    :func:`~stackpick_sim.vision.occlusion._row_major` (the same values)."""
    n = u.shape[0]
    top = 0.0
    for i in range(n):
        if u[i] > top:
            top = u[i]
    width = int(top) + 2
    scale = float(width)
    keys = np.empty(n)
    ascending = True
    for i in range(n):
        keys[i] = v[i] * scale + u[i]
        if i > 0 and not keys[i] >= keys[i - 1]:
            ascending = False
    return keys, width, ascending


@_compiled
def project_outside(band: NDArray[np.float64], terms: NDArray[np.float64], fx: float,
                    fy: float, kcx: float, kcy: float, margin_px: float
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.bool_]]:  # pragma: no cover - compiled
    """The pixels u, v (S, P) of the (3, S, P) camera-frame points ``band`` (pinhole fx,
    fy, kcx, kcy) and which lie more than ``margin_px`` outside face s (row s of (S, 6)
    ``terms``: cx, cy, the angle's cosine and sine, a, b), by the radial distance; see
    :func:`~stackpick_sim.vision.wall._project_outside` (the same arithmetic)."""
    n_s, n_p = band.shape[1], band.shape[2]
    pu, pv = np.empty((n_s, n_p)), np.empty((n_s, n_p))
    out = np.empty((n_s, n_p), np.bool_)
    for f in range(n_s):
        cx, cy, c, s, a, b = (terms[f, 0], terms[f, 1], terms[f, 2], terms[f, 3],
                              terms[f, 4], terms[f, 5])
        for k in range(n_p):
            u = fx * band[0, f, k] / band[2, f, k] + kcx
            v = fy * band[1, f, k] / band[2, f, k] + kcy
            du, dv = u - cx, v - cy
            x = (c * du + s * dv) / a
            y = (-s * du + c * dv) / b
            rho = np.sqrt(x * x + y * y)
            pu[f, k], pv[f, k] = u, v
            out[f, k] = (rho - 1.0) * np.hypot(x * a, y * b) / max(rho, 1e-9) > margin_px
    return pu, pv, out


@_compiled
def junction_cuts(pixels: NDArray[np.int32], starts: NDArray[np.int64],
                  reach_sq: float) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    """Per pixel of the chains (all (N, 2) pixels concatenated, chain k at
    ``starts[k]:starts[k + 1]``): whether it is the pixel of its chain nearest (the first of
    equals) to another chain's end point, within ``reach_sq`` (px^2), other than the chain's
    own two end pixels; see :func:`~stackpick_sim.vision.regroup.split_at_junctions`. A chain
    whose box grown by the reach misses an end is not scanned for it (its nearest pixel lies
    farther)."""
    n_chains = starts.shape[0] - 1
    cut = np.zeros(pixels.shape[0], np.bool_)
    reach = math.sqrt(reach_sq)
    for k in range(n_chains):
        lo, hi = starts[k], starts[k + 1]
        if hi - lo < 3:
            continue
        u0, v0 = pixels[lo, 0], pixels[lo, 1]
        u1, v1 = u0, v0
        for i in range(lo, hi):
            u0, u1 = min(u0, pixels[i, 0]), max(u1, pixels[i, 0])
            v0, v1 = min(v0, pixels[i, 1]), max(v1, pixels[i, 1])
        for other in range(n_chains):
            if other == k:
                continue
            for end in (starts[other], starts[other + 1] - 1):
                eu, ev = float(pixels[end, 0]), float(pixels[end, 1])
                if (eu < u0 - reach or eu > u1 + reach or ev < v0 - reach
                        or ev > v1 + reach):
                    continue
                best, at = np.inf, -1
                for i in range(lo, hi):
                    du, dv = pixels[i, 0] - eu, pixels[i, 1] - ev
                    d2 = du * du + dv * dv
                    if d2 < best:
                        best, at = d2, i
                if best <= reach_sq and lo < at < hi - 1:
                    cut[at] = True
    return cut


@_compiled
def _contrast_pick(mag: NDArray[np.float64], threshold: float, innermost: bool
                   ) -> int:  # pragma: no cover - compiled
    """:func:`contrast_peaks`' pick among one sample's offsets ``mag``: the strongest (the
    first of equals), or with ``innermost`` the first local peak (not below either
    neighbour, 0 beyond the ends) reaching ``threshold`` when there is one."""
    k = mag.shape[0]
    best = 0
    for j in range(1, k):
        if mag[j] > mag[best]:
            best = j
    if innermost:
        for j in range(k):
            left = mag[j - 1] if j > 0 else 0.0
            right = mag[j + 1] if j + 1 < k else 0.0
            if mag[j] >= left and mag[j] >= right and mag[j] >= threshold:
                return j
    return best


@_compiled
def contrast_peaks(pu: NDArray[np.float64], pv: NDArray[np.float64], nu: NDArray[np.float64],
                   nv: NDArray[np.float64], gx: NDArray[np.int16], gy: NDArray[np.int16],
                   offsets: NDArray[np.float64], window: int, gain: float, threshold: float,
                   innermost: bool) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """The contrast refit's points: at each outline sample (pu, pv) with unit normal (nu, nv),
    the signed normal gradient read at the pixel nearest each of the ``offsets`` along the
    normal (clamped into the image), its mean over the ``window`` (odd) samples centred on the
    sample (wrapping round the outline; summed in order, as ``np.convolve``), as an absolute
    value over ``gain``; the offset of the strongest (the first of equals), or with
    ``innermost`` of the first local peak reaching ``threshold`` when there is one. Returns
    the (K, 2) positions of the samples whose chosen offset reaches ``threshold``, in sample
    order; see :func:`~stackpick_sim.vision.contrast.refit_on_contrast`."""
    h, w = gx.shape
    n, k = pu.shape[0], offsets.shape[0]
    g = np.empty((n, k))
    for i in range(n):
        for j in range(k):
            u = min(max(np.int64(np.rint(pu[i] + offsets[j] * nu[i])), 0), w - 1)
            v = min(max(np.int64(np.rint(pv[i] + offsets[j] * nv[i])), 0), h - 1)
            g[i, j] = gx[v, u] * nu[i] + gy[v, u] * nv[i]
    weight = 1.0 / window
    half = window // 2
    mag = np.empty(k)
    out = np.empty((n, 2))
    count = 0
    rows = np.empty(window, np.int64)  # the window's rows (wrapped) of sample i
    for i in range(n):
        for t in range(window):
            rows[t] = (i + t - half) % n
        for j in range(k):
            total = 0.0
            for t in range(window):
                total += g[rows[t], j] * weight
            mag[j] = abs(total) / gain
        best = _contrast_pick(mag, threshold, innermost)
        if mag[best] >= threshold:
            out[count, 0] = pu[i] + offsets[best] * nu[i]
            out[count, 1] = pv[i] + offsets[best] * nv[i]
            count += 1
    return out[:count]


@_compiled
def outline_columns(cx: float, cy: float, a: float, b: float, c: float, s: float,
                    ct: NDArray[np.float64], st: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.float64]]:  # pragma: no cover - compiled
    """The points (u, v) and unit outward normals (nu, nv), (n,) each, of the ellipse of
    centre (cx, cy), semi-axes a, b and angle cosine c, sine s at the unit-circle samples
    (ct, st): ``u = (cx + c a ct) - s b st``, ``v = (cy + s a ct) + c b st``, the normal
    the gradient (b ct, a st) over its ``hypot``, turned by the angle."""
    n = ct.shape[0]
    pu, pv = np.empty(n), np.empty(n)
    nu, nv = np.empty(n), np.empty(n)
    for i in range(n):
        x, y = a * ct[i], b * st[i]
        pu[i] = (cx + c * x) - s * y
        pv[i] = (cy + s * x) + c * y
        gx, gy = b * ct[i], a * st[i]
        norm = math.hypot(gx, gy)
        gx /= norm
        gy /= norm
        nu[i] = c * gx - s * gy
        nv[i] = s * gx + c * gy
    return pu, pv, nu, nv


@_compiled
def level_histogram(small: NDArray[np.uint8]
                    ) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:  # pragma: no cover
    """The brightest channel (H, W) of an (H, W, C) uint8 image and its 256-bin histogram
    (counts as float64); see :func:`~stackpick_sim.vision.roi.find_roi` (the same values as
    ``np.maximum`` over the channels and ``cv2.calcHist``)."""
    h, w, channels = small.shape
    level = np.empty((h, w), np.uint8)
    flat, out = small.reshape(h * w, channels), level.ravel()
    if channels == 3:  # the colour frames: the channel loop unrolled
        for i in range(h * w):
            out[i] = max(flat[i, 0], flat[i, 1], flat[i, 2])
    else:
        for i in range(h * w):
            top = flat[i, 0]
            for k in range(1, channels):
                top = max(top, flat[i, k])
            out[i] = top
    # Integer counts (exact, as the float sums of ones), two interleaved tables: a run of
    # equal levels (the belt) would otherwise wait on each increment's store.
    tables = np.zeros((2, 256), np.int64)
    for i in range(0, h * w - 1, 2):
        tables[0, out[i]] += 1
        tables[1, out[i + 1]] += 1
    if (h * w) % 2:
        tables[0, out[h * w - 1]] += 1
    counts = np.empty(256)
    for v in range(256):
        counts[v] = np.float64(tables[0, v] + tables[1, v])
    return level, counts


@_compiled
def belt_box(small: NDArray[np.uint8], level: NDArray[np.uint8], belt: int, spread: int,
             delta: float) -> tuple[NDArray[np.float64], int,
                                    NDArray[np.int64]]:  # pragma: no cover - compiled
    """For the (H, W, C) uint8 image ``small`` of brightest channel ``level`` (H, W) and the
    belt's level ``belt``: the mean colour of the pixels whose level lies within ``spread``
    of it (each channel's sum times the reciprocal of their count, as ``cv2.mean`` with a
    mask; zeros without such pixels), their count, and the box (u, v, width, height, as
    ``cv2.boundingRect``; zeros when empty) of the pixels whose level differs from the
    belt's by more than ``delta``; see :func:`~stackpick_sim.vision.roi.find_roi`."""
    h, w, channels = small.shape
    sums = np.zeros(channels, np.int64)
    near = 0
    lo, hi = max(0, belt - spread), min(255, belt + spread)
    u0, v0, u1, v1 = w, h, -1, -1
    # Per level, whether it is near the belt's and whether it is foreground: two table
    # lookups per pixel instead of the tests.
    is_near, is_fore = np.zeros(256, np.int64), np.zeros(256, np.bool_)
    for x in range(256):
        is_near[x] = lo <= x <= hi
        is_fore[x] = abs(x - belt) > delta
    for r in range(h):
        row, levels = small[r], level[r]
        if channels == 3:  # the colour frames: the sums in registers
            s0, s1, s2 = sums[0], sums[1], sums[2]
            for c in range(w):
                on = is_near[levels[c]]
                near += on
                s0 += on * np.int64(row[c, 0])
                s1 += on * np.int64(row[c, 1])
                s2 += on * np.int64(row[c, 2])
            sums[0], sums[1], sums[2] = s0, s1, s2
        else:
            for c in range(w):
                on = is_near[levels[c]]
                near += on
                for k in range(channels):
                    sums[k] += on * np.int64(row[c, k])
        first, last = -1, -1
        for c in range(w):
            if is_fore[levels[c]]:
                last = c
                if first < 0:
                    first = c
        if first >= 0:  # the row's foreground spans first..last
            u0, u1 = min(u0, first), max(u1, last)
            v0 = min(v0, r)
            v1 = r
    mean = np.zeros(channels)
    scale = 1.0 / near if near else 0.0
    for k in range(channels):
        mean[k] = sums[k] * scale
    box = np.zeros(4, np.int64)
    if u1 >= 0:
        box[0], box[1], box[2], box[3] = u0, v0, u1 - u0 + 1, v1 - v0 + 1
    return mean, near, box


@_compiled
def _eq2_holds(a: float, b: float, angle_deg: float) -> bool:  # pragma: no cover - compiled
    """Paper Eq. 2 on the ellipse of semi-axes (a, b) and angle ``angle_deg``: see
    :func:`~stackpick_sim.vision.fitting.satisfies_eq2` (the same arithmetic)."""
    t = angle_deg * (math.pi / 180.0)
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0, math.pow(a / b, 2.0)
    big_a, big_b, big_h = c * c * ia + s * s * ib, s * s * ia + c * c * ib, c * s * (ia - ib)
    return big_a * big_b - big_h * big_h > 0.0


@_compiled
def fit_checks(raw: NDArray[np.float64], min_axis: float, max_axis: float, ratio_sq: float
               ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                          NDArray[np.bool_]]:  # pragma: no cover - compiled
    """Per direct fit (row k of (K, 5) ``raw``: centre u, v, full axes w, h and angle (deg) as
    ``cv2.fitEllipseDirect`` gives them): (K, 5) rows cx, cy, a, b and the angle in radians
    (zeros where the fit fails), the angle (deg, in [0, 180)) and whether it is an ellipse
    (finite, positive axes, Eq. 2 checked beyond the squared axis ratio ``ratio_sq``) with a
    semi-minor axis of at least ``min_axis`` and a semi-major axis of at most ``max_axis``;
    see :func:`~stackpick_sim.vision.fitting.fit_ellipse` and
    :func:`~stackpick_sim.vision.fitting.plausible` (the same arithmetic)."""
    k = raw.shape[0]
    params = np.zeros((k, 5))
    degrees = np.zeros(k)
    ok = np.zeros(k, np.bool_)
    for i in range(k):
        cx, cy, w, h, angle = raw[i, 0], raw[i, 1], raw[i, 2], raw[i, 3], raw[i, 4]
        if not (math.isfinite(cx) and math.isfinite(cy) and w > 0 and h > 0
                and math.isfinite(angle)):
            continue
        if w >= h:
            a, b, ang = w / 2.0, h / 2.0, angle
        else:
            a, b, ang = h / 2.0, w / 2.0, angle + 90.0
        ang = ang % 180.0
        if math.pow(a / b, 2.0) > ratio_sq and not _eq2_holds(a, b, ang):
            continue
        params[i, 0], params[i, 1], params[i, 2], params[i, 3] = cx, cy, a, b
        params[i, 4] = ang * (math.pi / 180.0)
        degrees[i] = ang
        ok[i] = min_axis <= b and a <= max_axis
    return params, degrees, ok


@_compiled
def _form_into(out: NDArray[np.float64], e: int, cx: float, cy: float, a: float, b: float,
               t: float) -> None:  # pragma: no cover - compiled
    """Row ``e`` of ``out``: the centre and quadratic form (cx, cy, A, H, B) of the ellipse
    (cx, cy, a, b) at angle ``t`` (rad); see :func:`~stackpick_sim.vision.refine._form` (the
    same arithmetic)."""
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0 / (a * a), 1.0 / (b * b)
    out[e, 0], out[e, 1] = cx, cy
    out[e, 2] = c * c * ia + s * s * ib
    out[e, 3] = c * s * (ia - ib)
    out[e, 4] = s * s * ia + c * c * ib


@_compiled
def ellipse_forms(rows: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover
    """(E, 5) centres and quadratic forms (cx, cy, A, H, B) of the ellipses of (E, 5)
    ``rows`` cx, cy, a, b, angle (deg); see :func:`~stackpick_sim.vision.refine._form` (the
    same arithmetic)."""
    out = np.empty((rows.shape[0], 5))
    for e in range(rows.shape[0]):
        _form_into(out, e, rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3],
                   rows[e, 4] * (math.pi / 180.0))
    return out


@_compiled
def refit_checks(raw: NDArray[np.float64], which: NDArray[np.int64],
                 forms: NDArray[np.float64], active: NDArray[np.bool_], min_axis: float,
                 max_axis: float, ratio_sq: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                            NDArray[np.bool_]]:  # pragma: no cover - compiled
    """:func:`fit_checks` of the direct fits ``raw`` (K, 5) of the ellipses ``which`` (K,);
    in place, the row ``which[k]`` of ``forms`` (E, 5) becomes the form (:func:`ellipse_forms`)
    of each fit that passes, and ``active[which[k]]`` is cleared for each that fails."""
    rows, degrees, ok = fit_checks(raw, min_axis, max_axis, ratio_sq)
    for k in range(which.shape[0]):
        if ok[k]:
            _form_into(forms, which[k], rows[k, 0], rows[k, 1], rows[k, 2], rows[k, 3],
                       rows[k, 4])
        else:
            active[which[k]] = False
    return rows, degrees, ok


@_compiled
def level_fits(raw: NDArray[np.float64], pixels: NDArray, starts: NDArray[np.int64],
               stops: NDArray[np.int64], min_axis: float, max_axis: float, ratio_sq: float,
               max_residual: float
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_],
                          NDArray[np.float64]]:  # pragma: no cover - compiled
    """:func:`fit_checks` of the direct fits ``raw`` (K, 5) of the pieces
    ``pixels[starts[k]:stops[k]]``, then the RMS Sampson distance of each piece to its fit
    (its squares summed in order; 0 for the fits that fail): the rows, the angles
    (deg), whether each fit passes and is within ``max_residual`` px, and the residuals."""
    rows, degrees, ok = fit_checks(raw, min_axis, max_axis, ratio_sq)
    k = raw.shape[0]
    rms = np.zeros(k)
    good = np.zeros(k, np.bool_)
    for e in range(k):
        if not ok[e]:
            continue
        cx, cy, a, b = rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3]
        c, s = math.cos(rows[e, 4]), math.sin(rows[e, 4])
        total = 0.0
        for j in range(starts[e], stops[e]):
            d = _sampson(pixels[j, 0] - cx, pixels[j, 1] - cy, a, b, c, s)
            total += d * d
        rms[e] = math.sqrt(total / (stops[e] - starts[e]))
        good[e] = rms[e] <= max_residual
    return rows, degrees, good, rms


@_compiled
def range_screen(pixels: NDArray, starts: NDArray[np.int64], stops: NDArray[np.int64],
                 shortest: int, min_bow: float
                 ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """The pieces worth a fit among the pieces ``pixels[starts[i]:stops[i]]``: the indices
    (ascending) of those of at least ``shortest`` pixels with a :func:`_bow` of at least
    ``min_bow`` px."""
    tried = np.empty(starts.shape[0], np.int64)
    k = 0
    for i in range(starts.shape[0]):
        if (stops[i] - starts[i] >= shortest
                and _bow(pixels, starts[i], stops[i]) >= min_bow):
            tried[k] = i
            k += 1
    return tried[:k]


@_compiled
def _tried_rows(pixels: NDArray, pieces: NDArray[np.int64], shortest: int, min_bow: float
                ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """:func:`range_screen` of the pieces (3, P) (start, stop in ``pixels`` and chain of each)
    as (K, 4) rows: the piece's index, start, stop and chain."""
    tried = range_screen(pixels, pieces[0], pieces[1], shortest, min_bow)
    rows = np.empty((tried.shape[0], 4), np.int64)
    for k in range(tried.shape[0]):
        i = tried[k]
        rows[k, 0], rows[k, 1], rows[k, 2], rows[k, 3] = i, pieces[0, i], pieces[1, i], pieces[2, i]
    return rows


@_compiled
def chain_pieces(pixels: NDArray, counts: NDArray[np.int64], shortest: int, min_bow: float
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """The pieces (3, S) start, stop and chain of the chains of (N, 2) ``pixels`` (one after
    another, ``counts[i]`` pixels each) and :func:`range_screen` of them (as
    :func:`_tried_rows`)."""
    pieces = np.empty((3, counts.shape[0]), np.int64)
    start = 0
    for i in range(counts.shape[0]):
        pieces[0, i], pieces[1, i], pieces[2, i] = start, start + counts[i], i
        start += counts[i]
    return pieces, _tried_rows(pixels, pieces, shortest, min_bow)


@_compiled
def level_step(raw: NDArray[np.float64], pixels: NDArray, pieces: NDArray[np.int64],
               tried: NDArray[np.int64], min_axis: float, max_axis: float, ratio_sq: float,
               max_residual: float, split_px: int, shortest: int, min_bow: float
               ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.int64],
                          NDArray[np.int64]]:  # pragma: no cover - compiled
    """One level of :func:`~stackpick_sim.vision.fitting.fit_all`: :func:`level_fits` of the
    direct fits ``raw`` (K, 5) of the ``tried`` pieces (K, 4) (:func:`_tried_rows`) of
    ``pieces`` (3, P) (start, stop in ``pixels`` and chain of each), with its ``min_axis``,
    ``max_axis``, ``ratio_sq`` and ``max_residual``; then the next level's pieces: the two
    halves (in order) of every piece not accepted of at least ``split_px`` pixels (none when
    ``split_px`` is 0) and those of them worth a fit (:func:`_tried_rows`: ``shortest``,
    ``min_bow``). Returns the (K, 6) rows cx, cy, a, b, angle (deg) and residual, which of
    them are accepted, the next (3, P') pieces and their tried ones."""
    starts, stops = tried[:, 1].copy(), tried[:, 2].copy()
    rows, degrees, good, rms = level_fits(raw, pixels, starts, stops, min_axis, max_axis,
                                          ratio_sq, max_residual)
    k = raw.shape[0]
    out = np.empty((k, 6))
    out[:, :4] = rows[:, :4]
    out[:, 4] = degrees
    out[:, 5] = rms
    done = np.zeros(pieces.shape[1], np.bool_)
    for e in range(k):
        done[tried[e, 0]] = good[e]
    halves = np.empty((3, 2 * pieces.shape[1]), np.int64)
    m = 0
    for i in range(pieces.shape[1]):
        lo, hi = pieces[0, i], pieces[1, i]
        if done[i] or split_px == 0 or hi - lo < split_px:
            continue
        mid = lo + (hi - lo) // 2
        halves[0, m], halves[1, m], halves[2, m] = lo, mid, pieces[2, i]
        halves[0, m + 1], halves[1, m + 1], halves[2, m + 1] = mid, hi, pieces[2, i]
        m += 2
    nxt = halves[:, :m].copy()
    return out, good, nxt, _tried_rows(pixels, nxt, shortest, min_bow)


@_compiled
def set_pixels(image: NDArray[np.uint8]
               ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """The rows and columns of the nonzero pixels of ``image`` (H, W), row-major (as
    ``np.nonzero``)."""
    h, w = image.shape
    n = 0
    for r in range(h):
        for c in range(w):
            n += image[r, c] != 0
    rows, cols = np.empty(n, np.int64), np.empty(n, np.int64)
    k = 0
    for r in range(h):
        for c in range(w):
            if image[r, c] != 0:
                rows[k], cols[k] = r, c
                k += 1
    return rows, cols


@_compiled
def junctions_cut(edges: NDArray[np.uint8], rows: NDArray[np.int64], cols: NDArray[np.int64]
                  ) -> tuple[NDArray[np.uint8], NDArray[np.uint8], bool]:  # pragma: no cover
    """For a 0/1 edge map (H, W) whose set pixels are (``rows``, ``cols``) in row-major
    order: the 0/1 map of its pixels with at most two edge neighbours (the junctions cut
    out: a 3x3 sum, the pixel included, of at most 3) and, per pixel of that map, 1 where
    it has at most one neighbour left in it (an end point: a 3x3 sum of at most 2; 0
    elsewhere), off the image 0 (the same maps as the box filters of
    :func:`~stackpick_sim.vision.segments.link_segments`); and whether the pixels given are
    set and ascending (if not, the maps are not computed)."""
    h, w = edges.shape
    wp = w + 2
    n = rows.shape[0]
    padded = np.zeros((h + 2, wp), np.uint8)
    flat = padded.ravel()
    at = np.empty(n, np.int64)
    for j in range(n):
        r, c = rows[j], cols[j]
        if not (0 <= r < h and 0 <= c < w and edges[r, c] != 0):
            return padded, padded, False
        at[j] = (r + 1) * wp + c + 1
        if j > 0 and at[j] <= at[j - 1]:
            return padded, padded, False
        flat[at[j]] = 1
    keep = np.empty(n, np.uint8)
    for j in range(n):
        keep[j] = _padded_box(flat, at[j], wp) <= 3
    cut_padded = np.zeros((h + 2, wp), np.uint8)
    cut_flat = cut_padded.ravel()
    for j in range(n):
        cut_flat[at[j]] = keep[j]
    end = np.zeros((h, w), np.uint8)
    for j in range(n):
        if keep[j]:
            end[rows[j], cols[j]] = _padded_box(cut_flat, at[j], wp) <= 2
    return np.ascontiguousarray(cut_padded[1:-1, 1:-1]), end, True


@_compiled
def uv_rows_cols(uv: NDArray[np.float64]
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64], bool]:  # pragma: no cover
    """The rows and columns of pixels given as (2, M) rows u, v, and whether they are whole
    numbers (as the edge stage lists them)."""
    n = uv.shape[1]
    rows, cols = np.empty(n, np.int64), np.empty(n, np.int64)
    for j in range(n):
        rows[j], cols[j] = np.int64(uv[1, j]), np.int64(uv[0, j])
        if rows[j] != uv[1, j] or cols[j] != uv[0, j]:
            return rows, cols, False
    return rows, cols, True


@_compiled
def _padded_box(flat: NDArray[np.uint8], i: int, wp: int) -> int:  # pragma: no cover
    """The 3x3 sum round flat index ``i`` of a map of row length ``wp`` with a zero border."""
    return (int(flat[i - wp - 1]) + flat[i - wp] + flat[i - wp + 1] + flat[i - 1] + flat[i]
            + flat[i + 1] + flat[i + wp - 1] + flat[i + wp] + flat[i + wp + 1])


#: The 8 directions of the border follower, counter-clockwise from east (image rows down):
#: column and row steps.
_STEP_U = np.array([1, 1, 0, -1, -1, -1, 0, 1], np.int64)
_STEP_V = np.array([0, -1, -1, -1, 0, 1, 1, 1], np.int64)


@_compiled
def _follow_border(flat: NDArray[np.int8], at: int, offsets: NDArray[np.int64], hole: bool,
                   out: NDArray[np.int64], k: int) -> int:  # pragma: no cover - compiled
    """Follow the border that starts at flat index ``at`` of a zero-padded map (``offsets``:
    the flat steps of the 8 directions, twice over; 1: a set pixel not yet visited; the
    pixels passed are marked 2, or -2 where the pixel east of them is background), Suzuki
    and Abe's border following as OpenCV's contour finder does it (the first neighbour
    searched clockwise from the west for an outer border, from the east for a hole; then
    counter-clockwise round each pixel from the one it came from). An outer border's pixels
    passed are written (flat indices) into ``out`` from ``k`` on; returns the next free
    place."""
    s_end = 0 if hole else 4
    s = s_end
    first = at
    while True:
        s = (s - 1) & 7
        first = at + offsets[s]
        if flat[first] != 0 or s == s_end:
            break
    if flat[first] == 0:  # a single pixel
        flat[at] = -2
        if not hole:
            out[k] = at
            k += 1
        return k
    here = at
    while True:
        s_end = s
        nxt = here
        while s < 15:
            s += 1
            nxt = here + offsets[s]
            if flat[nxt] != 0:
                break
        s &= 7
        if 1 <= s <= s_end:  # the pixel east of this one was searched: background
            flat[here] = -2
        elif flat[here] == 1:
            flat[here] = 2
        if not hole:
            out[k] = here
            k += 1
        if nxt == at and here == first:
            return k
        here = nxt
        s = (s + 4) & 7


@_compiled
def contours_at(binary: NDArray[np.uint8], rows: NDArray[np.int64], cols: NDArray[np.int64]
                ) -> tuple[NDArray[np.int32], NDArray[np.int64]]:  # pragma: no cover
    """:func:`outer_contours` of an (H, W) map given pixels (``rows``, ``cols``) in
    row-major order among which are all its set ones (the others are skipped): the raster
    scan visits only those and the pixel after each."""
    h, w = binary.shape
    wp = w + 2
    flat = np.zeros((h + 2) * wp, np.int8)
    n = 0
    for j in range(rows.shape[0]):
        if binary[rows[j], cols[j]]:
            flat[(rows[j] + 1) * wp + cols[j] + 1] = 1
            n += 1
    offsets = np.empty(16, np.int64)
    for d in range(8):
        offsets[d] = offsets[d + 8] = _STEP_V[d] * wp + _STEP_U[d]
    # A pixel is passed at most once per set neighbour (once when it has none).
    out = np.empty(8 * n + 1, np.int64)
    starts = np.empty(n + 1, np.int64)
    count, k = 0, 0
    # The scan's value of the pixel before (0 past a background pixel) and where it is.
    prev, prev_at = 0, -1
    for j in range(rows.shape[0]):
        at = (rows[j] + 1) * wp + cols[j] + 1
        if flat[at] == 0 and binary[rows[j], cols[j]] == 0:
            continue  # not a set pixel
        if at != prev_at + 1:
            prev = 0
        p = flat[at]
        if prev == 0 and p == 1:  # an outer border starts here
            starts[count] = k
            count += 1
            k = _follow_border(flat, at, offsets, False, out, k)
            p = flat[at]
        prev, prev_at = p, at
        # The pixel after: a hole's border starts at this one when it is background.
        if flat[at + 1] == 0 and p >= 1:
            _follow_border(flat, at, offsets, True, out, k)
            prev = 0
    starts[count] = k
    # OpenCV lists them last found first.
    pixels = np.empty((k, 2), np.int32)
    lengths = np.empty(count, np.int64)
    m = 0
    for i in range(count - 1, -1, -1):
        lengths[count - 1 - i] = starts[i + 1] - starts[i]
        for q in range(starts[i], starts[i + 1]):
            pixels[m, 0], pixels[m, 1] = out[q] % wp - 1, out[q] // wp - 1
            m += 1
    return pixels, lengths


@_compiled
def outer_contours(binary: NDArray[np.uint8]
                   ) -> tuple[NDArray[np.int32], NDArray[np.int64]]:  # pragma: no cover
    """The outer borders of the set pixels of an (H, W) map, as
    ``cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)`` gives the contours
    without a parent: their pixels (u, v), concatenated in OpenCV's order (the last found in
    the raster scan first), and their lengths. The holes' borders are followed too (their
    marks decide where later borders start) but not listed.

    A compiled follower rather than OpenCV's own call: OpenCV's contour finder (4.10 and
    later) takes two to three times as long on the detector's edge maps, the segments
    stage's largest single cost; the tests hold the two to the same contours."""
    rows, cols = set_pixels(binary)
    return contours_at(binary, rows, cols)


@_compiled
def ordered_chains(contours: NDArray[np.int32], lengths: NDArray[np.int64],
                   end: NDArray[np.uint8], shortest: int
                   ) -> tuple[NDArray[np.int32], NDArray[np.int64],
                              NDArray[np.bool_]]:  # pragma: no cover - compiled
    """The ordered chains of OpenCV contours of a one-pixel-wide map (all (M, 2) pixels
    (u, v) concatenated, ``lengths[i]`` each) given its ``end`` point map (H, W): per
    contour, the stretch from its first end pixel to its next one, or with a single end the
    contour turned to start there, or without any the contour itself (closed); only those
    of at least ``shortest`` pixels, concatenated, with their bounds (C + 1,) and whether
    each is closed; see :func:`~stackpick_sim.vision.segments.link_segments`."""
    out = np.empty_like(contours)
    bounds = np.zeros(lengths.shape[0] + 1, np.int64)
    closed = np.zeros(lengths.shape[0], np.bool_)
    k, count, start = 0, 0, 0
    for i in range(lengths.shape[0]):
        n = lengths[i]
        first, second = -1, -1
        for j in range(n):
            if end[contours[start + j, 1], contours[start + j, 0]]:
                if first < 0:
                    first = j
                else:
                    second = j
                    break
        lo, size = 0, n  # no end: the contour as it is
        if second >= 0:
            lo, size = first, second - first + 1
        elif first >= 0:
            lo = first  # one end: turned to start there, n pixels
        if size >= shortest:
            for j in range(size):
                at = start + (lo + j) % n
                out[k + j, 0], out[k + j, 1] = contours[at, 0], contours[at, 1]
            closed[count] = first < 0
            k += size
            count += 1
            bounds[count] = k
        start += n
    return out[:k], bounds[:count + 1], closed[:count]


@_compiled
def _far_pair(pts: NDArray[np.int32], n: int, iters: int
              ) -> tuple[int, int, float]:  # pragma: no cover - compiled
    """Two roughly farthest of the ``n`` pixels ``pts`` (a closed curve), as OpenCV's
    approximation finds them: from pixel 0 the farthest one, then from there (``iters``
    rounds; the first of equals). Returns the last round's start, the offset of its
    farthest pixel from it and their squared distance."""
    pos, right, far_sq = 0, 0, 0.0
    for _ in range(iters):
        pos = (pos + right) % n
        sx, sy = pts[pos, 0], pts[pos, 1]
        far_sq = 0.0
        for j in range(1, n):
            q = (pos + j) % n
            dx, dy = float(pts[q, 0] - sx), float(pts[q, 1] - sy)
            if dx * dx + dy * dy > far_sq:
                far_sq = dx * dx + dy * dy
                right = j
    return pos, right, far_sq


@_compiled
def _far_from_chord(pts: NDArray[np.int32], n: int, lo: int, hi: int
                    ) -> tuple[float, int, float]:  # pragma: no cover - compiled
    """The pixel of the stretch ``lo`` .. ``hi`` (cyclically, ends excluded) of the ``n``
    pixels ``pts`` farthest from the chord as a segment (beyond an end: from that end; the
    first of equals): its squared distance times the chord's squared length (whole
    numbers), its index, and the chord's squared length."""
    sx, sy, ex, ey = pts[lo, 0], pts[lo, 1], pts[hi, 0], pts[hi, 1]
    dx, dy = float(ex - sx), float(ey - sy)
    chord_sq = dx * dx + dy * dy
    far, split = 0.0, 0
    pos = (lo + 1) % n
    while pos != hi:
        qx, qy = pts[pos, 0] - sx, pts[pos, 1] - sy
        along = qx * dx + qy * dy
        if along < 0:
            d = (qx * qx + qy * qy) * chord_sq
        elif along > chord_sq:
            rx, ry = pts[pos, 0] - ex, pts[pos, 1] - ey
            d = (rx * rx + ry * ry) * chord_sq
        else:
            across = qy * dx - qx * dy
            d = across * across
        if d > far:
            far, split = d, pos
        pos = (pos + 1) % n
    return far, split, chord_sq


@_compiled
def _dp_slices(pts: NDArray[np.int32], n: int, closed: bool, eps_sq: float,
               out: NDArray[np.int32], stack: NDArray[np.int64]
               ) -> tuple[int, bool]:  # pragma: no cover - compiled
    """The Ramer-Douglas-Peucker recursion of :func:`poly_dp` on the ``n`` pixels ``pts``:
    the kept vertices written into ``out`` (their count returned) and whether the curve was
    taken as closed (an open one whose ends coincide is). ``stack``: (n + 2, 2) scratch."""
    top, count, iters = 0, 0, 3
    if not closed:
        if pts[n - 1, 0] != pts[0, 0] or pts[n - 1, 1] != pts[0, 1]:
            stack[0, 0], stack[0, 1] = 0, n - 1
            top = 1
        else:
            closed, iters = True, 1
    if closed:
        start, right, far_sq = _far_pair(pts, n, iters)
        if far_sq > eps_sq:
            stack[0, 0], stack[0, 1] = (right + start) % n, start
            stack[1, 0], stack[1, 1] = start, (right + start) % n
            top = 2
        else:
            out[0, 0], out[0, 1] = pts[start, 0], pts[start, 1]
            count = 1
    while top > 0:
        top -= 1
        lo, hi = stack[top, 0], stack[top, 1]
        flat, split = True, 0
        if (lo + 1) % n != hi:
            far, split, chord_sq = _far_from_chord(pts, n, lo, hi)
            flat = far <= eps_sq * chord_sq
        if flat:
            out[count, 0], out[count, 1] = pts[lo, 0], pts[lo, 1]
            count += 1
        else:
            stack[top, 0], stack[top, 1] = split, hi
            stack[top + 1, 0], stack[top + 1, 1] = lo, split
            top += 2
    if not closed:
        out[count, 0], out[count, 1] = pts[n - 1, 0], pts[n - 1, 1]
        count += 1
    return count, closed


@_compiled
def poly_dp(pts: NDArray[np.int32], closed: bool, eps: float, out: NDArray[np.int32],
            stack: NDArray[np.int64]) -> int:  # pragma: no cover - compiled
    """``cv2.approxPolyDP(pts, eps, closed)`` of (n, 2) int32 pixels (n >= 1), the same
    vertices in the same order (OpenCV's Ramer-Douglas-Peucker recursion: a closed curve
    split first at two roughly farthest pixels, each stretch split at its pixel farthest
    from its chord (as a segment) until none is more than ``eps`` off it; then a pass
    dropping a vertex that lies within eps / sqrt(2) of the line through its neighbours,
    between them), written into ``out`` ((n + 1, 2) or larger); returns their count.
    ``stack``: (n + 2, 2) scratch."""
    n = pts.shape[0]
    eps_sq = eps * eps
    count, _ = _dp_slices(pts, n, closed, eps_sq, out, stack)
    # The clean-up pass over the vertices (cyclically for a closed curve).
    new_count = count
    pos = count - 1 if closed else 0
    sx, sy = out[pos, 0], out[pos, 1]
    pos = (pos + 1) % count
    wpos = pos
    px, py = out[pos, 0], out[pos, 1]
    pos = (pos + 1) % count
    i = 0 if closed else 1
    stop = count if closed else count - 1
    while i < stop and new_count > 2:
        ex, ey = out[pos, 0], out[pos, 1]
        pos = (pos + 1) % count
        dx, dy = float(ex - sx), float(ey - sy)
        d = abs((px - sx) * dy - (py - sy) * dx)
        inner = float((px - sx) * (ex - px) + (py - sy) * (ey - py))
        if d * d <= 0.5 * eps_sq * (dx * dx + dy * dy) and dx != 0 and dy != 0 and inner >= 0:
            new_count -= 1
            out[wpos, 0], out[wpos, 1] = ex, ey
            sx, sy = ex, ey
            wpos = (wpos + 1) % count
            px, py = out[pos, 0], out[pos, 1]
            pos = (pos + 1) % count
            i += 2
            continue
        out[wpos, 0], out[wpos, 1] = px, py
        sx, sy = px, py
        wpos = (wpos + 1) % count
        px, py = ex, ey
        i += 1
    if not closed:
        out[wpos, 0], out[wpos, 1] = px, py
    return new_count


@_compiled
def chain_polys(chains: NDArray[np.int32], bounds: NDArray[np.int64],
                closed: NDArray[np.bool_], eps: float
                ) -> tuple[NDArray[np.int32], NDArray[np.int64]]:  # pragma: no cover
    """:func:`poly_dp` of each chain (``chains[bounds[c]:bounds[c + 1]]``, ``closed[c]``):
    the polygons' vertices concatenated and their bounds (C + 1,), as :func:`chain_arcs`
    takes them."""
    n_c = bounds.shape[0] - 1
    polys = np.empty((chains.shape[0] + n_c, 2), np.int32)
    poly_bounds = np.zeros(n_c + 1, np.int64)
    stack = np.empty((chains.shape[0] + 2, 2), np.int64)
    k = 0
    for c in range(n_c):
        lo, hi = bounds[c], bounds[c + 1]
        if hi > lo:
            k += poly_dp(chains[lo:hi], closed[c], eps, polys[k:], stack)
        poly_bounds[c + 1] = k
    return polys[:k], poly_bounds


@_compiled
def chain_arcs(chains: NDArray[np.int32], bounds: NDArray[np.int64], closed: NDArray[np.bool_],
               polys: NDArray[np.int32], poly_bounds: NDArray[np.int64], shortest: int,
               corner_deg: float, spike_deg: float, spike_ratio: float, signed_deg: float
               ) -> tuple[NDArray[np.int32], NDArray[np.int64]]:  # pragma: no cover
    """Each chain (``chains[bounds[c]:bounds[c + 1]]``, ``closed[c]``) cut at the
    :func:`corner_cuts` of its polygon (``polys[poly_bounds[c]:poly_bounds[c + 1]]``; fewer
    than 3 vertices: no cut), a closed chain turned to start at its first cut: the chains'
    pixels so turned and the (A, 2) [start, stop) ranges of the arcs of at least
    ``shortest`` pixels, in order; see :func:`~stackpick_sim.vision.segments.split_chain`."""
    out = np.empty_like(chains)
    ranges = np.empty((chains.shape[0] + bounds.shape[0], 2), np.int64)
    count = 0
    for c in range(bounds.shape[0] - 1):
        lo, hi = bounds[c], bounds[c + 1]
        n = hi - lo
        chain = chains[lo:hi]
        poly = polys[poly_bounds[c]:poly_bounds[c + 1]]
        cuts = np.empty(0, np.int64)
        if poly.shape[0] >= 3:
            cuts = corner_cuts(chain, poly, closed[c], corner_deg, spike_deg, spike_ratio,
                               signed_deg)
        first = cuts[0] if closed[c] and cuts.shape[0] else 0
        for j in range(n):
            at = (first + j) % n
            out[lo + j, 0], out[lo + j, 1] = chain[at, 0], chain[at, 1]
        prev = 0
        for j in range(cuts.shape[0] + 1):
            stop = n if j == cuts.shape[0] else cuts[j] - first
            if stop > prev and stop - prev >= shortest:
                ranges[count, 0], ranges[count, 1] = lo + prev, lo + stop
                count += 1
            prev = max(prev, stop)
    return out, ranges[:count]


@_compiled
def longest_contours(contours: NDArray[np.int32], lengths: NDArray[np.int64], shortest: int,
                     cap: int) -> tuple[NDArray[np.int32],
                                        NDArray[np.int64]]:  # pragma: no cover - compiled
    """Of the contours (``contours`` concatenated, ``lengths`` each) of at least ``shortest``
    pixels, the ``cap`` longest (the first of equals) in their order when there are more
    (the others give no chain of ``shortest`` pixels); else all of them as they are."""
    long = np.nonzero(lengths >= shortest)[0]
    if long.shape[0] <= cap:
        return contours, lengths
    order = np.argsort(-lengths[long], kind="mergesort")  # stable: the first of equals
    kept = np.sort(long[order[:cap]])
    starts = np.zeros(lengths.shape[0] + 1, np.int64)
    for i in range(lengths.shape[0]):
        starts[i + 1] = starts[i] + lengths[i]
    total = 0
    for i in kept:
        total += lengths[i]
    out = np.empty((total, 2), np.int32)
    k = 0
    for i in kept:
        out[k:k + lengths[i]] = contours[starts[i]:starts[i + 1]]
        k += lengths[i]
    return out, lengths[kept]


@_compiled
def linked_chains(edges: NDArray[np.uint8], rows: NDArray[np.int64], cols: NDArray[np.int64],
                  cap: int, shortest: int, eps: float,
                  turns: tuple[float, float, float, float]
                  ) -> tuple[NDArray[np.int32], NDArray[np.int64]]:  # pragma: no cover
    """The compiled passes of :func:`~stackpick_sim.vision.segments.link_segments` in one
    call, on a 0/1 map ``edges`` (H, W) whose set pixels are ``rows``, ``cols`` (row-major;
    when they are not, the map's are read): the junctions cut out and the end points marked
    (:func:`junctions_cut`), the pieces' outer borders (:func:`contours_at`), the ``cap``
    longest (``cap`` < 0: all; :func:`longest_contours`), ordered from end to end
    (:func:`ordered_chains`), their polygons (:func:`chain_polys`, tolerance ``eps``) and
    the arcs between their corners (:func:`chain_arcs` with ``turns``: the corner angle,
    the spike angle and ratio, the least signed turn). Returns :func:`chain_arcs`' pixels
    and arc ranges."""
    cut, end, valid = junctions_cut(edges, rows, cols)
    if not valid:
        rows, cols = set_pixels(edges)
        cut, end, valid = junctions_cut(edges, rows, cols)
    contours, lengths = contours_at(cut, rows, cols)
    if cap >= 0:
        contours, lengths = longest_contours(contours, lengths, shortest, cap)
    ordered, bounds, closed = ordered_chains(contours, lengths, end, shortest)
    polys, poly_bounds = chain_polys(ordered, bounds, closed, eps)
    return chain_arcs(ordered, bounds, closed, polys, poly_bounds, shortest, turns[0],
                      turns[1], turns[2], turns[3])


@_compiled
def pair_products(pair_g: NDArray[np.int64], pair_p: NDArray[np.int64],
                  owner: NDArray[np.int64], n_groups: int
                  ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """The (G, G) Eq. 3 products C[i, j] = N[i, j] N[j, i] (0 on the diagonal) of the shares
    N[b, a] of group a's pixels within tolerance of ellipse b, from the (ellipse, pixel)
    pairs within tolerance (``pair_g``, ``pair_p``) and ``owner`` (N,), the group of every
    pixel (all 0..G-1): each hit count over max(the group's pixel count, 1), in float64; see
    :func:`~stackpick_sim.vision.merging._pair_scores` (the same values as the
    ``np.bincount`` form)."""
    hits = np.zeros((n_groups, n_groups), np.int64)
    for k in range(pair_g.shape[0]):
        hits[pair_g[k], owner[pair_p[k]]] += 1
    counts = np.zeros(n_groups, np.int64)
    for p in range(owner.shape[0]):
        counts[owner[p]] += 1
    share = np.empty((n_groups, n_groups))
    for b in range(n_groups):
        for a in range(n_groups):
            share[b, a] = np.float64(hits[b, a]) / max(np.float64(counts[a]), 1.0)
    c = np.empty((n_groups, n_groups))
    for i in range(n_groups):
        for j in range(n_groups):
            c[i, j] = 0.0 if i == j else share[i, j] * share[j, i]
    return c


@_compiled
def lying_pairs(pair_g: NDArray[np.int64], pair_p: NDArray[np.int64],
                starts: NDArray[np.int64], n_groups: int, fraction: float
                ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """The (group, segment) pairs, in ``np.nonzero`` order of the (G, S) matrix, where at
    least ``fraction`` of the segment's pixels (segment s: pixels ``starts[s]`` to
    ``starts[s + 1] - 1``) appear among the (group, pixel) pairs (``pair_g``, ``pair_p``)
    (each pair once; the share as the count over the size, in float64); see
    :func:`~stackpick_sim.vision.merging._lying_segments`."""
    n_seg = starts.shape[0] - 1
    seg = np.empty(starts[n_seg], np.int64)
    for s in range(n_seg):
        for p in range(starts[s], starts[s + 1]):
            seg[p] = s
    hits = np.zeros((n_groups, n_seg), np.int64)
    for k in range(pair_g.shape[0]):
        hits[pair_g[k], seg[pair_p[k]]] += 1
    count = 0
    for g in range(n_groups):
        for s in range(n_seg):
            count += hits[g, s] / np.float64(starts[s + 1] - starts[s]) >= fraction
    on_g, on_s = np.empty(count, np.int64), np.empty(count, np.int64)
    k = 0
    for g in range(n_groups):
        for s in range(n_seg):
            if hits[g, s] / np.float64(starts[s + 1] - starts[s]) >= fraction:
                on_g[k], on_s[k] = g, s
                k += 1
    return on_g, on_s


@_compiled
def segments_rms(rows: NDArray[np.float64], points: NDArray[np.float64],
                 starts: NDArray[np.int64], segments: NDArray[np.int64],
                 per: NDArray[np.int64]) -> NDArray[np.float64]:  # pragma: no cover
    """Per ellipse e (column e of (6, E) ``rows``: cx, cy, a, b and the angle's cosine and
    sine), the RMS Sampson distance to it of the pixels of its ``per[e]`` segments (the next
    ones of ``segments``; segment s: ``points[starts[s]:starts[s + 1]]``, (N, 2)), their
    squares summed in that order; see :meth:`~stackpick_sim.vision.merging._Chains.rms`
    (the same sums)."""
    out = np.empty(rows.shape[1])
    j = 0
    for e in range(rows.shape[1]):
        cx, cy, a, b, c, s = rows[0, e], rows[1, e], rows[2, e], rows[3, e], rows[4, e], rows[5, e]
        total = 0.0
        count = 0
        for _ in range(per[e]):
            seg = segments[j]
            j += 1
            for k in range(starts[seg], starts[seg + 1]):
                d = _sampson(points[k, 0] - cx, points[k, 1] - cy, a, b, c, s)
                total += d * d
            count += starts[seg + 1] - starts[seg]
        out[e] = math.sqrt(total / count)
    return out


def warm_up() -> None:
    """Compile (or load from the cache) every kernel for the argument types the detector
    passes, on tiny inputs: run once after installing, so that parallel workers start on a
    warm cache instead of each compiling the same code."""
    img = np.zeros((4, 4), np.int16)
    col = np.zeros(1)
    counts = np.ones(1, np.int64)
    box_pairs(col, col, col, col, col)
    grouped_distances(np.ones((6, 1)), counts, col, col)
    bilinear_uv(img, img, col, col)
    subpixel_columns(img, img, col, col, col, col, 0.5)
    junction_cuts(np.zeros((1, 2), np.int32), np.array([0, 1], np.int64), 1.0)
    corner_cuts(np.zeros((3, 2), np.int32), np.zeros((3, 2), np.int32), True, 1.0, 1.0, 1.0, 1.0)
    outline_near_shares(np.ones((1, 6)), counts, col, col, np.ones((6, 1)), 1.0)
    interior_counts(np.ones((1, 6)), counts, col, 4)
    outline_samples(np.ones((1, 6)), counts, col, col)
    point_distances(np.zeros((1, 2)), 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)
    pair_lies(np.zeros((1, 2), np.int32), 1, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0)
    stride_magnitudes(img, img, 4, 8.0)
    stride_quantiles(img, img, 4, 8.0)
    strongest_gradients(np.zeros((3, 2, 4, 4), np.int16))
    for pts in (np.zeros((1, 2), np.int32), np.zeros((1, 2))):
        points_rms(pts, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)
        chain_hits(pts, np.zeros(1, np.int64), 1, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0)
    project_outside(np.ones((3, 1, 1)), np.ones((1, 6)), 1.0, 1.0, 1.0, 1.0, 1.0)
    face_median(np.zeros((4, 4, 3), np.uint8), 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, col, col)
    junction_ends(col, col, np.zeros((1, 2)), np.zeros(1, np.int64), np.ones((1, 8)), 1.0,
                  1.0, 1.0, 1.0)
    along_select(np.ones((1, 5)), np.array([0, 1], np.int64), np.ones(1, np.bool_),
                 np.zeros(1, np.int64), col, col, col, col, 1.0, 1.0)
    box_runs(col, col, col, col, col)
    subpixel_along(col, col, col, col, np.ones(5), 1.0, 1.0, 1.0, img, img, 0.5)
    profile_peaks(img, img, col, col, col, col, np.zeros(3), 0.5, 1.0)
    near_pairs_split(col, col, np.ones((6, 1)), col, 1.0, 1)
    segments_rms(np.ones((6, 1)), np.zeros((1, 2)), np.array([0, 1], np.int64), counts - 1,
                 counts)
    lying_pairs(np.zeros(1, np.int64), np.zeros(1, np.int64), np.array([0, 1], np.int64), 1,
                0.5)
    pair_products(np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64), 1)
    fit_checks(np.ones((1, 5)), 1.0, 1.0, 1.0)
    for pixels in (np.zeros((1, 2), np.int32), np.zeros((1, 2))):
        level_fits(np.ones((1, 5)), pixels, counts - 1, counts, 1.0, 1.0, 1.0, 1.0)
    for pixels in (np.zeros((1, 2), np.int32), np.zeros((1, 2))):
        pieces, tried = chain_pieces(pixels, counts, 1, 0.0)
        level_step(np.ones((1, 5)), pixels, pieces, tried, 1.0, 1.0, 1.0, 1.0, 2, 1, 0.0)
    ellipse_forms(np.ones((1, 5)))
    refit_checks(np.ones((1, 5)), np.zeros(1, np.int64), np.ones((1, 5)), np.ones(1, np.bool_),
                 1.0, 1.0, 1.0)
    outline_support(np.zeros((4, 4), np.uint8), np.ones((1, 6)), counts, col, col, 1)
    outline_rows(np.ones((1, 5)))
    outline_contrasts(col, col, col, col, img, img, col, np.zeros((1, 1), np.int64), 8.0)
    contrast_peaks(col, col, col, col, img, img, col, 1, 8.0, 1.0, True)
    fixed = np.zeros(1)  # the cached tables (unit circles, depths) are read-only
    fixed.setflags(write=False)
    band_points(np.ones((4, 1, 3)), fixed, fixed, fixed)
    circle_solutions(np.ones(6), np.ones(3), np.eye(3), np.ones(6), np.ones(4))
    table = np.zeros(256, np.uint8)
    small = np.zeros((4, 4, 3), np.uint8)
    belt_box(small, level_histogram(small)[0], 0, 1, 1.0)
    grey = np.zeros((4, 4, 1), np.uint8)
    belt_box(grey, level_histogram(grey)[0], 0, 1, 1.0)
    stairs_removed(np.zeros((4, 4), np.uint8), table, table)
    grid = np.zeros((4, 4), np.uint8)
    _, end, _ = junctions_cut(grid, *set_pixels(grid))
    uv_rows_cols(np.zeros((2, 1)))
    pixels, bounds, closed = ordered_chains(*outer_contours(grid), end, 2)
    contours_at(grid, *set_pixels(grid))
    polys, poly_bounds = chain_polys(pixels, bounds, closed, 1.0)
    chain_arcs(pixels, bounds, closed, polys, poly_bounds, 2, 1.0, 1.0, 1.0, 1.0)
    rows, cols = set_pixels(grid)
    linked_chains(grid, rows, cols, 1, 2, 1.0, (1.0, 1.0, 1.0, 1.0))
    longest_contours(*outer_contours(grid), 2, 1)
    stairs_removed_pixels(np.zeros((4, 4), np.uint8), table, table, img, img)
    edge_pixels(np.zeros((4, 4), np.uint8), img, img)
    row_keys(col, col)
    outline_columns(0.0, 0.0, 1.0, 1.0, 1.0, 0.0, fixed, fixed)
    band_hits(np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 1), np.bool_),
              np.zeros((4, 4, 3), np.uint8), np.ones((1, 3)), col, col, True, 0.1, 0.1,
              1.0)
    from stackpick_sim.vision import kernels_top  # the top rule's kernels (imports this one)

    kernels_top.warm_up()
    from stackpick_sim.vision import kernels_pose  # the evidence's and pose's passes (too)

    kernels_pose.warm_up()
    from stackpick_sim.vision import kernels_refine  # the top face's final fit's passes

    kernels_refine.warm_up()
    from stackpick_sim.vision import kernels_fit  # the direct ellipse fits

    kernels_fit.warm_up()
    from stackpick_sim.vision import under_wall  # the far-rim test's pass

    under_wall.warm_up()

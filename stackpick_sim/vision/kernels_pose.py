"""Compiled passes of the top rule's evidence and the pose (numba; see
:mod:`~stackpick_sim.vision.kernels` for how kernels are compiled and cached).

Each pass chains kernels of :mod:`~stackpick_sim.vision.kernels` and the array steps between
them into one call, with the same arithmetic in the same order (so the same values): what it
saves is the calls, conversions and temporaries between the steps on the few thousand outline
samples of a frame.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.vision import kernels
from stackpick_sim.vision.kernels import _compiled


@_compiled
def _strongest_normal(pu: NDArray[np.float64], pv: NDArray[np.float64],
                      nu: NDArray[np.float64], nv: NDArray[np.float64],
                      gx: NDArray[np.int16], gy: NDArray[np.int16], offsets: NDArray[np.float64]
                      ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Per outline sample (pu, pv) with unit normal (nu, nv): the normal gradient read at the
    pixel nearest each of the ``offsets`` along the normal (0 off the image), the strongest
    of them (the first of equals): the first step of :func:`~stackpick_sim.vision.kernels.
    outline_contrasts` (the same arithmetic)."""
    h, w = gx.shape
    n = pu.shape[0]
    best = np.empty(n)
    # Flat row-major reads: one index per pixel instead of two wrapped ones per array.
    fx, fy = gx.ravel(), gy.ravel()
    for i in range(n):
        top = -1.0
        pick = 0.0
        u, v, du, dv = pu[i], pv[i], nu[i], nv[i]
        for k in range(offsets.shape[0]):
            # u + o du: for the offsets 0 and +-1 the same value as u, u + du, u - du.
            ru, rv = np.rint(u + offsets[k] * du), np.rint(v + offsets[k] * dv)
            g = 0.0
            if 0.0 <= ru < w and 0.0 <= rv < h:  # tested as floats: any value is safe
                at = np.intp(rv) * w + np.intp(ru)
                g = fx[at] * du + fy[at] * dv
            if k == 0 or abs(g) > top:
                pick, top = g, abs(g)
        best[i] = pick
    return best


@_compiled
def contrast_ok(rows: NDArray[np.float64], counts: NDArray[np.int64],
                ct: NDArray[np.float64], st: NDArray[np.float64],
                gx: NDArray[np.int16], gy: NDArray[np.int16],
                offsets: NDArray[np.float64], shifts: NDArray[np.int64], gain: float,
                threshold: float
                ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:  # pragma: no cover
    """The outline samples of each ellipse (:func:`~stackpick_sim.vision.kernels.
    outline_samples`'s arguments), their contrast profile (:func:`~stackpick_sim.vision.
    kernels.outline_contrasts` over the gradients ``gx``, ``gy`` at the normal ``offsets``,
    each sample's window the samples ``shifts`` steps along its own outline, cyclic, summed
    in that order) and which samples reach ``threshold``: (2, N) points and (N,) ok; see
    :func:`~stackpick_sim.vision.contrast.supported_samples`."""
    pts, normals = kernels.outline_samples(rows, counts, ct, st)
    best = _strongest_normal(pts[0], pts[1], normals[0], normals[1], gx, gy, offsets)
    n_rows = shifts.shape[0]
    profile = np.empty(ct.shape[0])
    start = 0
    for e in range(counts.shape[0]):
        size = counts[e]
        stop = start + size
        for i in range(start, stop):
            total = 0.0
            for r in range(n_rows):
                j = i + shifts[r]
                j = j + size if j < start else (j - size if j >= stop else j)
                total = best[j] if r == 0 else total + best[j]
            profile[i] = abs(total / n_rows) / gain
        start = stop
    return pts, profile >= threshold


@_compiled
def _gap_ends(ok: NDArray[np.bool_], counts: NDArray[np.int64], min_gap: int
              ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                         NDArray[np.int64]]:  # pragma: no cover - compiled
    """Per outline (``counts[e]`` samples each, concatenated): how many samples are ``ok``
    and the longest cyclic run of samples that are not (its whole size when none is); and,
    run by run in the order of their first samples, the ok samples at both ends of each run
    of at least ``min_gap`` samples and its outline; see
    :func:`~stackpick_sim.vision.occlusion.evidence_all`."""
    n_e = counts.shape[0]
    supported = np.zeros(n_e, np.int64)
    longest = np.zeros(n_e, np.int64)
    ends = np.empty(ok.shape[0] + 1, np.int64)
    owners = np.empty(ok.shape[0] + 1, np.int64)
    k = 0
    start = 0
    for e in range(n_e):
        size = counts[e]
        stop = start + size
        for i in range(start, stop):
            supported[e] += ok[i]
        if supported[e] == 0:
            longest[e] = size
        for i in range(start, stop if 0 < supported[e] < size else start):
            if ok[i] or not ok[i - 1 if i > start else stop - 1]:
                continue  # not a run's first sample
            last, length = i, 1
            while not ok[last + 1 if last + 1 < stop else start]:
                last = last + 1 if last + 1 < stop else start
                length += 1
            longest[e] = max(longest[e], length)
            if length >= min_gap:
                ends[k], ends[k + 1] = (i - 1 if i > start else stop - 1,
                                        last + 1 if last + 1 < stop else start)
                owners[k], owners[k + 1] = e, e
                k += 2
        start = stop
    return supported, longest, ends[:k], owners[:k]


@_compiled
def gap_evidence(ok: NDArray[np.bool_], counts: NDArray[np.int64], pts: NDArray[np.float64],
                 rows: NDArray[np.float64], pu: NDArray[np.float64], pv: NDArray[np.float64],
                 min_gap: int, reach: float, junction_sq: float, crossing_sq: float,
                 tol_px: float
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64],
                            NDArray[np.int64]]:  # pragma: no cover - compiled
    """Per outline of the ellipses of (E, 6) ``rows`` (cx, cy, a, b and the angle's cosine
    and sine; ``counts[e]`` samples each, (2, N) ``pts``, which are ``ok``): the ok
    samples, the longest gap and how many gap ends are T-junctions
    (:func:`~stackpick_sim.vision.kernels.junction_ends` of the ends of the gaps of at least
    ``min_gap`` samples among the edge pixels (pu, pv), rows ascending, with the axes less
    ``tol_px`` inside); see :func:`~stackpick_sim.vision.occlusion.evidence_all` (the same
    values)."""
    supported, longest, ends, owners = _gap_ends(ok, counts, min_gap)
    occluded = np.zeros(counts.shape[0], np.int64)
    if ends.shape[0] == 0:
        return supported, longest, occluded
    params = np.empty((rows.shape[0], 8))
    for e in range(rows.shape[0]):
        params[e, 0], params[e, 1], params[e, 2] = rows[e, 0], rows[e, 1], rows[e, 4]
        params[e, 3], params[e, 4], params[e, 5] = rows[e, 5], rows[e, 2], rows[e, 3]
        params[e, 6], params[e, 7] = max(rows[e, 2] - tol_px, 1e-6), max(rows[e, 3] - tol_px, 1e-6)
    at = np.empty((ends.shape[0], 2))
    for k in range(ends.shape[0]):
        at[k, 0], at[k, 1] = pts[0, ends[k]], pts[1, ends[k]]
    both = kernels.junction_ends(pu, pv, at, owners, params, reach, junction_sq, crossing_sq,
                                 tol_px)
    for k in range(ends.shape[0]):
        occluded[owners[k]] += both[k]
    return supported, longest, occluded


@_compiled
def interior_counts_of(rows: NDArray[np.float64], margin_px: float, keys: NDArray[np.float64],
                       width: int) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.interior_counts` of the ellipses of (E, 6)
    ``rows`` (cx, cy, a, b and the angle's cosine and sine) with their semi-axes less
    ``margin_px``: their shrunk forms and rows first, in the arithmetic of
    :func:`~stackpick_sim.vision.occlusion._interior_counts`."""
    n_e = rows.shape[0]
    params = np.empty((n_e, 6))
    sizes = np.empty(n_e, np.int64)
    for e in range(n_e):
        cx, cy, a, b, c, s = rows[e, 0], rows[e, 1], rows[e, 2], rows[e, 3], rows[e, 4], rows[e, 5]
        ia = 1.0 / max(a - margin_px, 1e-6) ** 2
        ib = 1.0 / max(b - margin_px, 1e-6) ** 2
        p, q, r = c * c * ia + s * s * ib, 2.0 * c * s * (ia - ib), s * s * ia + c * c * ib
        half = math.sqrt(p / (p * r - 0.25 * q * q))
        first = math.ceil(cy - half)
        params[e, 0], params[e, 1], params[e, 2] = cx, cy, p
        params[e, 3], params[e, 4], params[e, 5] = q, r, float(first)
        sizes[e] = max(0, math.floor(cy + half) - first + 1)
    return kernels.interior_counts(params, sizes, keys, width)


@_compiled
def occlusion_counts(ok: NDArray[np.bool_], counts: NDArray[np.int64], pts: NDArray[np.float64],
                     rows: NDArray[np.float64], pu: NDArray[np.float64],
                     pv: NDArray[np.float64], margin_px: float, min_gap: int, reach: float,
                     junction_sq: float, crossing_sq: float, tol_px: float
                     ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                                NDArray[np.int64]]:  # pragma: no cover - compiled
    """Per outline of the ellipses of (E, 6) ``rows`` (``counts[e]`` samples each, (2, N)
    ``pts``, which are ``ok``), over the edge pixels (pu, pv) (integer values >= 0, any
    order): :func:`gap_evidence`'s ok samples, longest gap and T-junction ends, and
    :func:`interior_counts_of` with ``margin_px``; the pixels put in row-major order first
    (:func:`~stackpick_sim.vision.kernels.row_keys`, a stable sort where they are not in
    it), as :func:`~stackpick_sim.vision.occlusion._row_major` does: the evidence's counts
    in one call (the same values)."""
    keys, width, ascending = kernels.row_keys(pu, pv)
    if not ascending:
        order = np.argsort(keys, kind="mergesort")
        keys, pu, pv = keys[order], pu[order], pv[order]
    interior = interior_counts_of(rows, margin_px, keys, width)
    supported, longest, occluded = gap_evidence(ok, counts, pts, rows, pu, pv, min_gap, reach,
                                                junction_sq, crossing_sq, tol_px)
    return supported, longest, occluded, interior


#: Entries of the cone's form beyond this magnitude (and non-finite ones) are left to
#: ``np.linalg.eigh`` itself (see :func:`~stackpick_sim.vision.pose.unit_circle_poses`).
EIGH_DIRECT_MAX = 1e100


@_compiled
def cone_of(cx: float, cy: float, a2: float, b2: float, angle_deg: float, fx: float,
            fy: float, kcx: float, kcy: float
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:  # pragma: no cover
    """The cone ``Q = K^T C K`` of the ellipse (centre cx, cy, squared semi-axes a2, b2, as
    Python's ``a ** 2`` gives them (libm's pow, which can differ from ``a * a`` in the last
    bit), angle) seen through the pinhole (fx, fy, kcx, kcy), C the ellipse's pixel conic (M
    = R diag(1/a2, 1/b2) R^T, d = -M c, f = -d.c - 1): the (3, 3) symmetric matrix; what
    :func:`~stackpick_sim.vision.kernels.circle_solutions` takes besides its eigen
    decomposition as one (16,) row (Q00, Q01, Q02, Q11, Q12, Q22; cx, cy, the angle's cosine
    and sine, a^2, b^2; fx, fy, kcx, kcy); and whether every entry is finite and within
    :data:`EIGH_DIRECT_MAX`. The arithmetic of :func:`~stackpick_sim.vision.pose.
    unit_circle_poses` on Python floats, step for step (the same values)."""
    t = angle_deg * (math.pi / 180.0)  # math.radians
    c, s = math.cos(t), math.sin(t)
    ia, ib = 1.0 / a2, 1.0 / b2
    m00, m01, m11 = c * c * ia + s * s * ib, c * s * (ia - ib), s * s * ia + c * c * ib
    d0 = -(m00 * cx + m01 * cy)
    d1 = -(m01 * cx + m11 * cy)
    f = -(d0 * cx + d1 * cy) - 1.0
    r0, r1 = m00 * kcx + m01 * kcy + d0, m01 * kcx + m11 * kcy + d1  # C K's last column
    packed = np.empty(16)
    packed[0], packed[1], packed[2] = fx * fx * m00, fx * fy * m01, fx * r0
    packed[3], packed[4] = fy * fy * m11, fy * r1
    packed[5] = kcx * r0 + kcy * r1 + (d0 * kcx + d1 * kcy + f)
    packed[6], packed[7], packed[8], packed[9], packed[10], packed[11] = cx, cy, c, s, a2, b2
    packed[12], packed[13], packed[14], packed[15] = fx, fy, kcx, kcy
    cone = np.empty((3, 3))
    moderate = True
    for i, j, k in ((0, 0, 0), (0, 1, 1), (0, 2, 2), (1, 1, 3), (1, 2, 4), (2, 2, 5)):
        cone[i, j] = cone[j, i] = packed[k]
        if not abs(packed[k]) <= EIGH_DIRECT_MAX:
            moderate = False
    return cone, packed, moderate


@_compiled
def cone_solutions(packed: NDArray[np.float64], evals: NDArray[np.float64],
                   evecs: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], bool, bool]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.circle_solutions` of the (16,) row of
    :func:`cone_of` and the cone's ascending ``evals`` (3,) and ``evecs`` (3, 3), and whether
    those are all finite."""
    finite = True
    for i in range(3):
        if not math.isfinite(evals[i]):
            finite = False
        for j in range(3):
            if not math.isfinite(evecs[i, j]):
                finite = False
    solutions, ok = kernels.circle_solutions(packed[0:6], evals, evecs, packed[6:12],
                                             packed[12:16])
    return solutions, ok, finite


@_compiled
def plane_axes(n0: float, n1: float, n2: float
           ) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """The in-plane axes u, v of the normal (n0, n1, n2), six floats: u = n x e (e the helper
    axis e_x, or e_y where |n0| >= 0.9, n normalised) normalised, then v = n x u; see
    :func:`~stackpick_sim.vision.wall.plane_basis`."""
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
    if abs(n0) < 0.9:  # helper (1, 0, 0): u = n x e_x
        u0, u1, u2 = 0.0, n2, -n1
    else:  # helper (0, 1, 0): u = n x e_y
        u0, u1, u2 = -n2, 0.0, n0
    un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    u0, u1, u2 = u0 / un, u1 / un, u2 / un
    return u0, u1, u2, n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0


@_compiled
def _tan_tilt(n0: float, n1: float, n2: float, c0: float, c1: float, c2: float
              ) -> float:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.wall.tan_tilt` of the normal n and centre c (its
    arithmetic)."""
    c_norm = max(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-12)
    n_norm = max(math.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-12)
    cos_tilt = min(1.0, abs((n0 * c0 + n1 * c1 + n2 * c2) / c_norm) / n_norm)
    return math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt)) / max(cos_tilt, 1e-6)


@_compiled
def band_points_of(solutions: NDArray[np.float64], ct: NDArray[np.float64],
                   st: NDArray[np.float64], depths: NDArray[np.float64]
                   ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.band_points` of the S unit-radius solutions (S, 2,
    3) (normal, centre), their rim axes those of :func:`plane_axes`; see
    :func:`~stackpick_sim.vision.wall.solution_band_points` (the same values)."""
    n_s = solutions.shape[0]
    vectors = np.empty((4, n_s, 3))
    for s in range(n_s):
        n0, n1, n2 = solutions[s, 0, 0], solutions[s, 0, 1], solutions[s, 0, 2]
        u0, u1, u2, v0, v1, v2 = plane_axes(n0, n1, n2)
        vectors[0, s, 0], vectors[0, s, 1], vectors[0, s, 2] = n0, n1, n2
        vectors[1, s, 0] = solutions[s, 1, 0]
        vectors[1, s, 1] = solutions[s, 1, 1]
        vectors[1, s, 2] = solutions[s, 1, 2]
        vectors[2, s, 0], vectors[2, s, 1], vectors[2, s, 2] = u0, u1, u2
        vectors[3, s, 0], vectors[3, s, 1], vectors[3, s, 2] = v0, v1, v2
    return kernels.band_points(vectors, ct, st, depths)


@_compiled
def wall_hits(solutions: NDArray[np.float64], ct: NDArray[np.float64],
              st: NDArray[np.float64], depths: NDArray[np.float64], face: tuple[float, ...],
              camera: tuple[float, float, float, float], margin_px: float,
              image: NDArray[np.uint8], colour: NDArray[np.float64],
              settings: tuple[float, float, float, float], belt: NDArray[np.float64],
              use_belt: bool
              ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:  # pragma: no cover - compiled
    """:func:`~stackpick_sim.vision.kernels.band_hits` of the wall bands of the S unit-radius
    solutions (S, 2, 3) (normal, centre) of one face (``face``: its cx, cy, angle's cosine
    and sine, a, b): their rims (``ct``, ``st``) at the ``depths``
    (:func:`~stackpick_sim.vision.kernels.band_points`), projected by ``camera`` (fx, fy, cx,
    cy) and kept more than ``margin_px`` outside the face (:func:`~stackpick_sim.vision.
    kernels.project_outside`), tested against the face's ``colour``, each solution's
    :func:`_tan_tilt` plus ``settings[0]`` the brightest a wall may be, ``settings[1:]`` the
    chroma tolerance, least brightness and belt distance; see
    :func:`~stackpick_sim.vision.wall.wall_evidences` (the same arithmetic)."""
    n_s = solutions.shape[0]
    brightest = np.empty(n_s)
    for s in range(n_s):
        brightest[s] = _tan_tilt(solutions[s, 0, 0], solutions[s, 0, 1], solutions[s, 0, 2],
                                 solutions[s, 1, 0], solutions[s, 1, 1],
                                 solutions[s, 1, 2]) + settings[0]
    band = band_points_of(solutions, ct, st, depths)
    per = band.shape[2]
    terms = np.empty((1, 6))
    for k in range(6):
        terms[0, k] = face[k]
    pu, pv, keep = kernels.project_outside(band.reshape(3, 1, n_s * per), terms, camera[0],
                                           camera[1], camera[2], camera[3], margin_px)
    colours = np.empty((n_s, colour.shape[0]))
    for s in range(n_s):
        colours[s] = colour
    return kernels.band_hits(pu.reshape(n_s, per), pv.reshape(n_s, per),
                             keep.reshape(n_s, per), image, colours, brightest, belt,
                             use_belt, settings[1], settings[2], settings[3])


def warm_up() -> None:
    """Compile (or load from the cache) these kernels for the argument types the detector
    passes (see :func:`~stackpick_sim.vision.kernels.warm_up`, which calls this)."""
    col = np.zeros(16)
    counts = np.array([16], np.int64)
    img = np.zeros((4, 4), np.int16)
    rows = np.ones((1, 6))
    contrast_ok(rows, counts, col, col, img, img, np.zeros(3), np.zeros(5, np.int64), 8.0,
                1.0)
    interior_counts_of(rows, 0.5, col, 4)
    occlusion_counts(np.ones(16, np.bool_), counts, np.zeros((2, 16)), rows, col, col, 0.5, 5,
                     1.0, 1.0, 1.0, 1.0)
    gap_evidence(np.ones(16, np.bool_), counts, np.zeros((2, 16)), rows, col, col, 5, 1.0,
                 1.0, 1.0, 1.0)
    fixed = np.zeros(1)  # the cached tables (unit circles, depths) are read-only
    fixed.setflags(write=False)
    colour = np.ones(3)
    plane_axes(0.0, 0.0, 1.0)
    cone, packed, _ = cone_of(1.0, 1.0, 4.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0)
    cone_solutions(packed, np.ones(3), cone)
    band_points_of(np.ones((2, 2, 3)), fixed, fixed, fixed)
    wall_hits(np.ones((2, 2, 3)), fixed, fixed, fixed, (1.0,) * 6, (1.0,) * 4, 1.0,
              np.zeros((4, 4, 3), np.uint8), colour, (1.0,) * 4, colour, True)

"""The T-junction rule for side walls: a face lying over another object's wall is above it.

The top-object rule (:mod:`stackpick_sim.vision.occlusion`) reads occlusion off face
outlines. A lower object's face can still be whole when the object on top of it rests on its
side wall, not on its face; then both faces pass as top candidates and the larger or better
supported one wins, often the lower one. Its wall shows the occlusion instead: the wall band
a pose solution predicts next to the face (:func:`~stackpick_sim.vision.wall.band_points`)
lies under the other face's ellipse, i.e. the other face's outline runs through where this
object's wall silhouette would be, and the wall's contour ends at it.

The face's tilt is known only up to the two-fold ambiguity, so both solutions' bands are
checked; a face counts as under another when either solution's band runs under it. A false
hit needs a second whole face right beside this face's rim, on the side a wall would show.

Given each face's radius (from its colour), the test also asks that the cover be physically
possible: a face hides a wall point only if it lies nearer the camera there. A band point
counts as covered only where the other face's plane (the nearer of its two pose solutions,
scaled by its radius) is in front of the point, within ``cover_depth_tolerance_m``
(settings: the ``cover_*`` fields of :class:`~stackpick_sim.config.vision_params.TopParams`).
A face seen
nearly square on next to a lower, farther face (its wrong solution's band falling on that
face) is then not under it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels_top
from stackpick_sim.vision.kernels import kernel_array
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.wall import solution_band_points, solution_bands

#: The top rule's default settings (the ``cover_*`` fields).
DEFAULT_TOP = TopParams()
#: The pose's default settings (its wall band's depths and margin).
DEFAULT_POSE = PoseParams()


def cover_depths(params: TopParams = DEFAULT_TOP, pose: PoseParams = DEFAULT_POSE
                 ) -> tuple[float, ...]:
    """Depths along the axis (face radii) of the band checked for cover: the colour test's
    (``pose.wall_depths``, first: the rest test reads its bands from these), then
    ``params.cover_extra_depths``."""
    return (*pose.wall_depths, *params.cover_extra_depths)


#: Bands kept by :func:`face_bands` for one run of the top rule: per (face, intrinsics), its
#: two solutions' (u, v, outside) rows.
BandCache = dict[tuple[Ellipse, CameraIntrinsics],
                 tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]]


def face_bands(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
               cache: BandCache | None = None, *, params: TopParams = DEFAULT_TOP,
               pose: PoseParams = DEFAULT_POSE
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`~stackpick_sim.vision.wall.solution_bands` of both unit-radius pose solutions
    of each face at :func:`cover_depths` (of ``params`` and ``pose``, whose
    ``wall_margin_px`` sets which lie outside the face): pixels u, v (2n, P) and which lie
    outside the
    face, rows 2i and 2i + 1 face i's (its :func:`~stackpick_sim.vision.pose.
    unit_circle_poses` order), ellipses in the pixel frame of ``intrinsics``; the faces not
    in ``cache`` in one array pass.

    With a ``cache`` (the caller's, for one run of the top rule) each face's bands are
    computed once and kept there: the cover test runs a second time with the radii, and the
    rest test (:mod:`~stackpick_sim.vision.resting`) reads the same bands' first depths."""
    kept: BandCache = {} if cache is None else cache
    found = {f: kept.get((f, intrinsics)) for f in faces}
    missing = [f for f, bands in found.items() if bands is None]
    if missing:
        for f, new in zip(missing, _bands_of(missing, intrinsics, params, pose), strict=True):
            found[f] = kept[(f, intrinsics)] = new
    got = [bands for f in faces if (bands := found[f]) is not None]
    return (np.concatenate([g[0] for g in got]), np.concatenate([g[1] for g in got]),
            np.concatenate([g[2] for g in got]))


def _bands_of(faces: list[Ellipse], intrinsics: CameraIntrinsics, params: TopParams,
              pose: PoseParams
              ) -> list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]]:
    """Each face's two solutions' (u, v, outside) rows (see :func:`face_bands`), all faces in
    one array pass."""
    sols = [(s.normal_cam, s.centre_cam) for f in faces
            for s in unit_circle_poses(f, intrinsics)]
    pu, pv, keep = solution_bands(sols, [f for f in faces for _ in range(2)], intrinsics,
                                  cover_depths(params, pose), pose.wall_margin_px)
    return [(pu[2 * i:2 * i + 2], pv[2 * i:2 * i + 2], keep[2 * i:2 * i + 2])
            for i in range(len(faces))]


def covered_shares(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                   radii: Sequence[float | None] | None = None, *,
                   cache: BandCache | None = None, params: TopParams = DEFAULT_TOP,
                   pose: PoseParams = DEFAULT_POSE) -> NDArray[np.float64]:
    """(n, n) share (0-1) ``[i, j]``: the largest, over the two pose solutions of face i, of
    its predicted wall band lying inside face j (0 on the diagonal), all ellipses in the
    pixel frame of ``intrinsics``; every band and pair in one array pass.

    Solutions whose band shows fewer than ``params.cover_min_samples`` points give 0. With
    ``radii`` (each face's radius, m, or None if unknown; parallel to ``faces``), a band point
    inside face j counts only where face j lies in front of it (within
    ``params.cover_depth_tolerance_m``) when both radii are known; a point counts inside
    ``params.cover_margin_px`` from the outline. ``cache``: :func:`face_bands`'; ``pose``:
    the band's depths and margin (with ``params.cover_extra_depths``).
    """
    return _largest_of_two(solution_shares(faces, intrinsics, radii, cache=cache,
                                           params=params, pose=pose))


def _largest_of_two(each: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, n) of the (2n, n) :func:`solution_shares`: each face's larger of its two
    solutions' shares, 0 on the diagonal."""
    n = each.shape[1]
    share = each.reshape(n, 2, n).max(axis=1)
    np.fill_diagonal(share, 0.0)
    return np.asarray(share, np.float64)


def solution_shares(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                    radii: Sequence[float | None] | None = None, *,
                    cache: BandCache | None = None, params: TopParams = DEFAULT_TOP,
                    pose: PoseParams = DEFAULT_POSE) -> NDArray[np.float64]:
    """(2n, n) share (0-1) ``[2 i + s, j]``: of pose solution s of face i (its
    :func:`~stackpick_sim.vision.pose.unit_circle_poses` order), its predicted wall band
    lying inside face j (the diagonal pairs are not meaningful); see
    :func:`covered_shares`, the larger of each face's two."""
    return _shares(_band_cover(faces, intrinsics, cache, params, pose), faces, intrinsics,
                   radii, params, pose)


#: What :func:`_band_cover` finds: (S, n, P) whether band point p of solution s lies inside
#: face j, the band pixels u, v (S, P) and each solution's band sample count (S,).
BandCover = tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64],
                  NDArray[np.int64]]


def _band_cover(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                cache: BandCache | None, params: TopParams, pose: PoseParams) -> BandCover:
    """The faces' bands (:func:`face_bands`) and which of their points lie inside each face
    (``params.cover_margin_px`` inside its outline), before any depth test: what
    :func:`solution_shares` computes with and without the radii alike."""
    pu, pv, keep = face_bands(faces, intrinsics, cache, params=params, pose=pose)
    samples = keep.sum(axis=1)
    # Ellipse.inside of every solution's band points (S, 1, P) in every face (1, n, 1).
    rows, margin = [], params.cover_margin_px
    for f in faces:
        t = math.radians(f.angle_deg)
        rows.append((f.cx, f.cy, math.cos(t), math.sin(t), max(f.a - margin, 1e-6),
                     max(f.b - margin, 1e-6)))
    # One compiled pass (kernels_top.bands_inside: the same arithmetic as the array form).
    covered = kernels_top.bands_inside(kernel_array(pu, np.float64),
                                       kernel_array(pv, np.float64),
                                       kernel_array(keep, np.bool_),
                                       np.array(rows, np.float64).reshape(-1, 6))
    return covered, pu, pv, samples


def _shares(cover: BandCover, faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
            radii: Sequence[float | None] | None, params: TopParams, pose: PoseParams
            ) -> NDArray[np.float64]:
    """:func:`solution_shares` of the faces' :func:`_band_cover` ``cover`` (with ``radii``,
    only the points in front of which the face lies count)."""
    covered, pu, pv, samples = cover
    if radii is not None:
        sols = [(s.normal_cam, s.centre_cam) for f in faces
                for s in unit_circle_poses(f, intrinsics)]
        covered = covered & _in_front(sols, pu, pv, radii, intrinsics,
                                      params.cover_depth_tolerance_m, cover_depths(params, pose))
    inside = np.count_nonzero(covered, axis=2)
    # Each solution's shares (0 for too few band points).
    return np.asarray(np.where((samples >= params.cover_min_samples)[:, None],
                               inside / np.maximum(samples, 1)[:, None], 0.0), np.float64)


def _in_front(solutions: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
              pu: NDArray[np.float64], pv: NDArray[np.float64], radii: Sequence[float | None],
              intrinsics: CameraIntrinsics, tolerance_m: float, depths: tuple[float, ...]
              ) -> NDArray[np.bool_]:
    """(S, n, P): whether face j's plane (the nearer of its two solutions, scaled by its
    radius) lies in front of solution s's band point p (scaled by its face's radius), within
    ``tolerance_m``; True where either radius is unknown. ``solutions``: two unit
    solutions per face, face by face; ``pu``, ``pv``: (S, P) band pixels at ``depths``."""
    known = np.array([r is not None for r in radii])
    scale = np.array([0.0 if r is None else float(r) for r in radii])
    # (S, P) depth (camera z) of every band point, metres.
    wall = solution_band_points(solutions, depths)[2] * scale.repeat(2)[:, None]
    rx = (pu - intrinsics.cx) / intrinsics.fx
    ry = (pv - intrinsics.cy) / intrinsics.fy
    normals = np.array([nc[0] for nc in solutions], np.float64)  # (S, 3)
    offsets = np.array([float(nc[0] @ nc[1]) for nc in solutions]) * scale.repeat(2)
    # Depth of each plane k (a solution of face k // 2) along each band point's ray.
    along = (normals[:, 0, None, None] * rx[None] + normals[:, 1, None, None] * ry[None]
             + normals[:, 2, None, None])  # (planes, S, P)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = offsets[:, None, None] / along
    depth[~(depth > 0.0)] = np.inf  # a plane the ray meets behind the camera, or never
    plane = np.minimum(depth[0::2], depth[1::2])  # (n, S, P): face j's nearer solution
    front = plane.transpose(1, 0, 2) <= wall[:, None, :] + tolerance_m
    both = known.repeat(2)[:, None, None] & known[None, :, None]
    return front | ~both


def covered_share(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics) -> float:
    """Largest share (0-1), over the two pose solutions of ``face``, of its predicted wall
    band lying inside ``other`` (both ellipses in the pixel frame of ``intrinsics``); see
    :func:`covered_shares`."""
    return float(covered_shares([face, other], intrinsics)[0, 1])


#: Whether pose solution s of face i can lie under face j, for (i, s, j) triples (face
#: indices into the faces of :func:`under_another`): a cover the solids rule out is none.
CoverCheck = Callable[[list[tuple[int, int, int]]], list[bool]]


def under_another(faces: list[Ellipse], intrinsics: CameraIntrinsics,
                  radius_of: Callable[[Ellipse], float | None] | None = None, *,
                  cache: BandCache | None = None, params: TopParams = DEFAULT_TOP,
                  pose: PoseParams = DEFAULT_POSE, possible: CoverCheck | None = None
                  ) -> list[bool]:
    """Per face: does its wall band run under another of the (whole) ``faces``.

    When each of two faces' bands runs under the other (one of them through its wrong pose
    solution), the face with the larger covered share is the one under. With ``radius_of``
    (a face's radius, m, or None if unknown), a cover must also be possible in depth (see
    :func:`covered_shares`); that is checked only when the shares alone find one.
    With ``possible`` (see :data:`CoverCheck`), a solution whose band runs under a face counts
    only where the solids allow it: the failure class *wrong solution's wall under a nearer
    face*, a face beside a nearer one whose wrong pose solution's wall falls on it, which
    would put its cylinder through the nearer one's (:func:`~stackpick_sim.vision.resting.
    cover_check`); checked only for the solutions found under another. A cover ruled out
    puts neither face under: the other face's share is still weighed against it.
    ``cache``: the bands' (:func:`face_bands`); both passes read the same bands.
    ``params``: the ``cover_*`` settings (a face is under another from a covered share of
    ``cover_min_share``); ``pose``: the band's depths and margin.
    """
    least = params.cover_min_share
    # The bands and their points inside each face once, for both passes.
    cover = _band_cover(faces, intrinsics, cache, params, pose)
    share = _largest_of_two(_shares(cover, faces, intrinsics, None, params, pose))
    allowed = share
    if radius_of is not None and np.any(share >= least):
        each = _shares(cover, faces, intrinsics, [radius_of(f) for f in faces], params, pose)
        share = allowed = _largest_of_two(each)
        if possible is not None and np.any(share >= least):
            allowed = _largest_of_two(_possible_only(each, possible, least))
    under = np.any((allowed >= least) & (share > share.T), axis=1)
    return [bool(u) for u in under]


def _possible_only(each: NDArray[np.float64], possible: CoverCheck, least: float
                   ) -> NDArray[np.float64]:
    """The (2n, n) :func:`solution_shares` ``each`` with 0 where a share of at least
    ``least`` is one ``possible`` rules out."""
    hits = [(int(r) // 2, int(r) % 2, int(j)) for r, j in np.argwhere(each >= least)
            if int(r) // 2 != int(j)]
    if not hits:
        return each
    out = each.copy()
    for (i, s, j), ok in zip(hits, possible(hits), strict=True):
        if not ok:
            out[2 * i + s, j] = 0.0
    return out

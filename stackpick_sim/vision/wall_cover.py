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
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.pose import MIN_BAND_SAMPLES, unit_circle_poses
from stackpick_sim.vision.wall import solution_bands

#: A face is under another when at least this share of one solution's predicted wall band
#: lies inside the other face. Placeholder from the development seeds 0-299.
MIN_COVERED_SHARE = 0.15
#: Depths along the axis (face radii) of the band checked for cover: 0.8 stays on the wall
#: of the paper scene's squattest cylinder (height / radius = 0.86). Deeper than the colour
#: test's band: an object resting on a wall often covers only its far part (dev seed 67).
COVER_DEPTH_FRACTIONS: tuple[float, ...] = (0.2, 0.4, 0.6, 0.8)
#: Band points must lie this far (px) inside the other ellipse: its blurred outline and the
#: fit error are not evidence.
COVER_MARGIN_PX = 1.0


def covered_shares(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics) -> NDArray[np.float64]:
    """(n, n) share (0-1) ``[i, j]``: the largest, over the two pose solutions of face i, of
    its predicted wall band lying inside face j (0 on the diagonal), all ellipses in the
    pixel frame of ``intrinsics``; every band and pair in one array pass.

    Solutions whose band shows fewer than MIN_BAND_SAMPLES points give 0.
    """
    n = len(faces)
    sols = [(s.normal_cam, s.centre_cam) for f in faces for s in unit_circle_poses(f, intrinsics)]
    pu, pv, keep = solution_bands(sols, [f for f in faces for _ in range(2)], intrinsics,
                                  COVER_DEPTH_FRACTIONS)
    samples = keep.sum(axis=1)
    # Ellipse.inside of every solution's band points (S, 1, P) in every face (1, n, 1).
    rows = []
    for f in faces:
        t = math.radians(f.angle_deg)
        rows.append((f.cx, f.cy, math.cos(t), math.sin(t), max(f.a - COVER_MARGIN_PX, 1e-6),
                     max(f.b - COVER_MARGIN_PX, 1e-6)))
    cx, cy, c, s, a, b = np.array(rows, np.float64).T[:, None, :, None]
    du, dv = pu[:, None, :] - cx, pv[:, None, :] - cy
    x = (c * du + s * dv) / a
    y = (-s * du + c * dv) / b
    inside = np.count_nonzero((x * x + y * y < 1.0) & keep[:, None, :], axis=2)
    share = np.zeros((n, n))
    for k, (count, hits) in enumerate(zip(samples.tolist(), inside.tolist(), strict=True)):
        if count >= MIN_BAND_SAMPLES:
            i = k // 2
            share[i] = np.maximum(share[i], [h / count for h in hits])
    np.fill_diagonal(share, 0.0)
    return share


def covered_share(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics) -> float:
    """Largest share (0-1), over the two pose solutions of ``face``, of its predicted wall
    band lying inside ``other`` (both ellipses in the pixel frame of ``intrinsics``); see
    :func:`covered_shares`."""
    return float(covered_shares([face, other], intrinsics)[0, 1])


def under_another(faces: list[Ellipse], intrinsics: CameraIntrinsics) -> list[bool]:
    """Per face: does its wall band run under another of the (whole) ``faces``.

    When each of two faces' bands runs under the other (one of them through its wrong pose
    solution), the face with the larger covered share is the one under.
    """
    share = covered_shares(faces, intrinsics)
    return [bool(np.any((share[i] >= MIN_COVERED_SHARE) & (share[i] > share[:, i])))
            for i in range(len(faces))]

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

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.pose import MIN_BAND_SAMPLES, circle_poses
from stackpick_sim.vision.wall import band_points

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


def _bands(face: Ellipse, intrinsics: CameraIntrinsics) -> list[NDArray[np.float64]]:
    """Predicted wall bands (N_i, 2) px of the two pose solutions of ``face`` that show at
    least MIN_BAND_SAMPLES points (a face seen square on shows none)."""
    bands = [band_points(sol.normal_cam, sol.centre_cam, face, intrinsics,
                         COVER_DEPTH_FRACTIONS)
             for sol in circle_poses(face, intrinsics, 1.0)]
    return [b for b in bands if b.shape[0] >= MIN_BAND_SAMPLES]


def _share(bands: list[NDArray[np.float64]], other: Ellipse) -> float:
    """Largest share of any of ``bands`` lying inside ``other``; 0 without bands."""
    return max((float(np.mean(other.inside(b, COVER_MARGIN_PX))) for b in bands), default=0.0)


def covered_share(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics) -> float:
    """Largest share (0-1), over the two pose solutions of ``face``, of its predicted wall
    band lying inside ``other`` (both ellipses in the pixel frame of ``intrinsics``).

    Solutions whose band shows fewer than MIN_BAND_SAMPLES points give 0.
    """
    return _share(_bands(face, intrinsics), other)


def under_another(faces: list[Ellipse], intrinsics: CameraIntrinsics) -> list[bool]:
    """Per face: does its wall band run under another of the (whole) ``faces``.

    When each of two faces' bands runs under the other (one of them through its wrong pose
    solution), the face with the larger covered share is the one under.
    """
    n = len(faces)
    bands = [_bands(f, intrinsics) for f in faces]
    share = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if i != j:
                share[i, j] = _share(bands[i], faces[j])
    return [bool(np.any((share[i] >= MIN_COVERED_SHARE) & (share[i] > share[:, i])))
            for i in range(n)]

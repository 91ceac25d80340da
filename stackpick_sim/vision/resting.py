"""Which whole face's object rests on which: a contact test of the reconstructed cylinders.

The image rules (T-junctions on face outlines, :mod:`~stackpick_sim.vision.wall_cover` on
side walls) see an object lying on another only where one covers the other in the image. A
cylinder leaning on another's side wall, below that one's face, covers little or nothing of
it: both faces show whole, with no T-junction, and the leaning one's face can be the farther
from the camera (paper scene seed 487: a small cylinder tilted 42 deg leans its far rim on a
large one's wall, faces 2 mm apart in depth). The ground truth calls the leaned-on object not
top: a contact whose normal points up (z >= 0.3) into another object.

That contact can be read from the 3-D reconstruction instead. Each whole face gives its
cylinder: the pose solution its wall band favours (:func:`~stackpick_sim.vision.pose.
choose_by_band`), the radius from its colour, the axis along the inward normal for its kind's
height (the caller's, from the scene's object kinds). For two convex bodies the largest
separation along a direction,
``max_d (min_{x in A} x.d - max_{x in B} x.d)``, is their distance when apart and minus their
penetration depth when overlapping, and the maximising ``d`` is the contact normal from B to A
(the separating axis); a cylinder's support function is closed-form, so the maximum is taken
over a fixed set of directions, all pairs in one array pass. When the bodies touch (within
CONTACT_GAP_M .. CONTACT_PENETRATION_M) and the normal points up (UP_CAM) by MIN_REST_UP or
more, A rests on B. A face seen square on (neither solution's band visible) takes the smaller
tilt, as the pose does; a face whose visible bands cannot tell its solution gives no evidence.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.pose import MIN_BAND_SAMPLES, choose_by_band, unit_circle_poses
from stackpick_sim.vision.wall import face_colour, wall_evidences

#: Two bodies farther apart than this (m) do not touch. The face depth error is ~1 mm and a
#: 1-2 deg tilt error moves a far rim ~1 mm.
CONTACT_GAP_M = 0.003
#: Bodies overlapping deeper than this (m) are not a consistent reconstruction (a wrong pose
#: solution, a misfitted face): no evidence. The pose errors above, both ways.
CONTACT_PENETRATION_M = 0.004
#: A contact normal (from the lower body to the upper) with at least this upward component
#: means the upper body rests on the lower: the ground truth's own threshold
#: (:mod:`stackpick_sim.sim.ground_truth`).
MIN_REST_UP = 0.3
#: World up in the camera frame: the look pose looks straight down (OpenCV axes, +z forward).
UP_CAM = np.array([0.0, 0.0, -1.0])
#: Directions searched for the separating axis (a Fibonacci sphere): ~3 deg apart, so the
#: normal's upward component is off by < 0.06 and a touching pair's separation reads up to
#: ~1.5 mm negative (a face of 0.035 m radius seen ~2 deg off its normal).
AXIS_DIRECTIONS = 4000


@functools.lru_cache(maxsize=1)
def _directions(n: int = AXIS_DIRECTIONS) -> NDArray[np.float64]:
    """(n, 3) unit vectors spread evenly over the sphere (read-only)."""
    k = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * k / n)
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * k
    d = np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                  np.cos(polar)], axis=1)
    d.setflags(write=False)
    return d


def _support(centre: NDArray[np.float64], normal: NDArray[np.float64], radius: NDArray[np.float64],
             height: NDArray[np.float64], dirs: NDArray[np.float64]) -> NDArray[np.float64]:
    """(P, D) support function max_x x.d of P cylinders (face centre (P, 3) m, inward unit
    axis (P, 3), radius (P,) m, height (P,) m) over directions (D, 3)."""
    nd = normal @ dirs.T
    return (centre @ dirs.T + np.maximum(0.0, height[:, None] * nd)
            + radius[:, None] * np.sqrt(np.maximum(0.0, 1.0 - nd * nd)))


def contact(centres: NDArray[np.float64], normals: NDArray[np.float64],
            radii: NDArray[np.float64], heights: NDArray[np.float64], pairs: NDArray[np.int64]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Separation (P,) m (negative: penetration) and contact normal (P, 3) from body
    ``pairs[:, 1]`` to body ``pairs[:, 0]`` of cylinders given by face centre (N, 3) m, inward
    unit axis (N, 3), radius (N,) m and height (N,) m, camera frame; see the module
    docstring."""
    dirs = _directions()
    a, b = pairs[:, 0], pairs[:, 1]
    sep = (-_support(centres[a], normals[a], radii[a], heights[a], -dirs)
           - _support(centres[b], normals[b], radii[b], heights[b], dirs))
    best = np.argmax(sep, axis=1)
    return sep[np.arange(len(pairs)), best], dirs[best]


def rests_on(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
             radius_of: Callable[[Ellipse], float | None],
             height_of: Callable[[float], float | None], image: NDArray[np.uint8]
             ) -> list[bool]:
    """Per face (whole faces of an (H, W, 3) RGB image, pixel frame of ``intrinsics``): does
    another face's cylinder rest on its cylinder (see the module docstring). ``radius_of``:
    a face's radius (m); ``height_of``: the cylinder height (m) of a radius; a face for which
    either gives None takes no part. The true height matters: one 5 mm too tall flips the
    contact normal of a lean on a far rim (development frame 128 of ds_paper_dev3)."""
    n = len(faces)
    under = [False] * n
    bodies: list[tuple[int, NDArray[np.float64], NDArray[np.float64], float, float]] = []
    for i, face in enumerate(faces):
        radius = radius_of(face)
        height = None if radius is None else height_of(radius)
        if radius is None or height is None:
            continue
        unit = unit_circle_poses(face, intrinsics)
        bands = wall_evidences([(s.normal_cam, s.centre_cam) for s in unit], face, intrinsics,
                               image, face_colour(face, image))
        pick = choose_by_band(bands)
        if pick is None and all(b.samples < MIN_BAND_SAMPLES for b in bands):
            # Seen square on, no wall shows and the two solutions nearly coincide: the
            # smaller tilt, as the pose takes (paper seed 544: a flat face leaned on).
            pick = int(np.argmax([float(s.normal_cam[2]) for s in unit]))
        if pick is not None:
            bodies.append((i, unit[pick].centre_cam * radius, unit[pick].normal_cam, radius,
                           height))
    if len(bodies) < 2:
        return under
    pairs = np.array([(p, q) for p in range(len(bodies)) for q in range(p + 1, len(bodies))],
                     np.int64)
    sep, normal = contact(np.array([b[1] for b in bodies]), np.array([b[2] for b in bodies]),
                          np.array([b[3] for b in bodies]), np.array([b[4] for b in bodies]),
                          pairs)
    up = normal @ UP_CAM
    touching = (sep <= CONTACT_GAP_M) & (sep >= -CONTACT_PENETRATION_M)
    for (p, q), t, u in zip(pairs.tolist(), touching.tolist(), up.tolist(), strict=True):
        if t and u >= MIN_REST_UP:  # p rests on q
            under[bodies[q][0]] = True
        elif t and u <= -MIN_REST_UP:
            under[bodies[p][0]] = True
    return under

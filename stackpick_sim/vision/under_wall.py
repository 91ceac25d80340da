"""A face lying under a nearer cylinder's body: the cover test in reverse.

The cover test (:mod:`~stackpick_sim.vision.wall_cover`) puts a face under another when its
own wall runs under the other face. The reverse case: an ellipse whose face, placed where its
size and kind put it, lies behind another object's cylinder (face and side wall) along the
camera's lines of sight cannot be seen at all; what the edge map shows there is that
cylinder's own outline. Typically *the far rim of a steep cylinder*: its wall's silhouette
beyond its face, closed by the face's own near rim or a neighbour's arc, fitted as an ellipse
of about the face's size that passes the top rule (no T-junction, no edge inside, the wall's
smooth shading inside it), while the true face fails on a neighbour's outline touching it.

Each face is reconstructed from its ellipse (both pose solutions, its kind's radius) and
sampled on its disc; each other face's cylinder (both pose solutions, its kind's radius and
height) is a solid that the rays to those samples may pass through. The share of a face's
samples hidden behind the cylinder, nearer than the sample by more than a depth tolerance, is
the face's covered share under that cylinder (:func:`hidden_share`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, plane_basis
from stackpick_sim.vision.markings import holds_centre
from stackpick_sim.vision.pose import unit_circle_poses

#: The disc samples: radii (shares of the face's radius) and angles, one per (ring, angle).
_RING_SHARES, _RING_ANGLES = (grid.ravel() for grid in np.meshgrid(
    np.array([0.0, 0.35, 0.65, 0.9]), np.linspace(0.0, 2.0 * math.pi, 12, endpoint=False)))


def _disc(centre: NDArray[np.float64], normal: NDArray[np.float64], radius: float
          ) -> NDArray[np.float64]:
    """(N, 3) samples of the disc of ``radius`` (m) about ``centre`` in the plane of unit
    ``normal`` (camera frame, m)."""
    u, v = plane_basis(normal)
    rr = _RING_SHARES * radius
    return centre + np.outer(rr * np.cos(_RING_ANGLES), u) + np.outer(rr * np.sin(_RING_ANGLES), v)


def _hidden(points: NDArray[np.float64], centre: NDArray[np.float64],
            normal: NDArray[np.float64], radius: float, height: float, tolerance: float
            ) -> NDArray[np.bool_]:
    """Per point (N, 3), camera frame: whether the ray from the camera to it passes through
    the solid cylinder of ``radius`` and ``height`` (m) whose face is centred at ``centre``
    with inward unit ``normal`` (the body extends along it) before reaching the point, by
    more than ``tolerance`` (m)."""
    dist = np.linalg.norm(points, axis=1)
    d = points / dist[:, None]
    w = -centre
    dn = d @ normal
    d_perp = d - dn[:, None] * normal
    w_perp = w - (w @ normal) * normal
    a = np.einsum("ij,ij->i", d_perp, d_perp)
    b = d_perp @ w_perp
    c = w_perp @ w_perp - radius * radius
    disc = b * b - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = (-b - root) / a, (-b + root) / a
        # The slab between the face's plane and the far end's: c.n <= t d.n <= c.n + h.
        s0, s1 = (centre @ normal) / dn, (centre @ normal + height) / dn
    lo = np.maximum(np.minimum(s0, s1), np.where(a > 1e-12, t0, -np.inf))
    hi = np.minimum(np.maximum(s0, s1), np.where(a > 1e-12, t1, np.inf))
    inside_radially = (a > 1e-12) & (disc > 0.0) | (a <= 1e-12) & (c <= 0.0)
    return inside_radially & (hi > lo) & (lo > 0.0) & (lo < dist - tolerance)


def hidden_share(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics,
                 face_radius: float, other_radius: float, other_height: float,
                 tolerance: float) -> float:
    """Share [0, 1] of ``face``'s disc hidden behind ``other``'s cylinder (:func:`_hidden`),
    the least over ``face``'s two pose solutions and the largest over ``other``'s: the face
    lies under the cylinder whichever way it is tilted, under one of the cylinder's two
    reconstructions. Radii and height in m; ``tolerance`` (m) the depth margin."""
    faces = unit_circle_poses(face, intrinsics)
    others = unit_circle_poses(other, intrinsics)
    least = 1.0
    for s in faces:
        points = _disc(s.centre_cam * face_radius, s.normal_cam, face_radius)
        share = max(float(np.mean(_hidden(points, o.centre_cam * other_radius, o.normal_cam,
                                          other_radius, other_height, tolerance)))
                    for o in others)
        least = min(least, share)
    return least


def _may_hide(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics,
              face_radius: float, other_radius: float, other_height: float) -> bool:
    """A cheap bound before :func:`hidden_share`: whether ``other``'s cylinder can reach in
    front of ``face`` at all. Its image lies within its semi-major axis times (1 + height /
    radius) of its centre (the wall's image is at most the face's size times height over
    radius long), and its nearest point lies at least its radius in front of its face's
    centre; ``face``'s disc lies within its semi-major axis of its centre, at most its radius
    behind it."""
    reach = other.a * (1.0 + other_height / other_radius) + face.a
    if math.hypot(face.cx - other.cx, face.cy - other.cy) > reach:
        return False
    return (_depth(other, intrinsics, other_radius) - other_radius
            < _depth(face, intrinsics, face_radius) + face_radius)


def _depth(face: Ellipse, intrinsics: CameraIntrinsics, radius: float) -> float:
    """The face's centre depth (m), the nearer of its two pose solutions'."""
    return radius * min(float(s.centre_cam[2]) for s in unit_circle_poses(face, intrinsics))


def under_a_wall(faces: Sequence[Ellipse], i: int, covering: Sequence[int],
                 intrinsics: CameraIntrinsics, radius_of: Callable[[Ellipse], float | None],
                 height_of: Callable[[float], float | None], min_share: float,
                 tolerance: float) -> bool:
    """Whether face ``i`` of ``faces`` lies under the cylinder of one of the faces
    ``covering`` (indices): at least ``min_share`` of it hidden (:func:`hidden_share`,
    ``tolerance`` m). Faces whose radius (``radius_of``) or height (``height_of``) is unknown
    take no part, nor a face that holds ``i``'s centre or whose centre ``i`` holds (a second
    fit of the same face reads nearer or farther by its size alone)."""
    face = faces[i]
    face_radius = radius_of(face)
    if face_radius is None:
        return False
    for j in covering:
        other = faces[j]
        if j == i or holds_centre(face, other) or holds_centre(other, face):
            continue
        radius = radius_of(other)
        height = None if radius is None else height_of(radius)
        if (radius is not None and height is not None
                and _may_hide(face, other, intrinsics, face_radius, radius, height)
                and hidden_share(face, other, intrinsics, face_radius, radius, height,
                                 tolerance) >= min_share):
            return True
    return False

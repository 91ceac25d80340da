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
the face's covered share under that cylinder (:func:`hidden_share`, one compiled pass).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.kernels import _compiled
from stackpick_sim.vision.kernels_pose import plane_axes
from stackpick_sim.vision.markings import holds_centre
from stackpick_sim.vision.pose import unit_circle_poses

#: The disc samples: radii (shares of the face's radius) and angles, the centre and 12 on
#: each ring.
_RING_SHARES = np.concatenate(([0.0], np.repeat([0.35, 0.65, 0.9], 12)))
_RING_ANGLES = np.concatenate(([0.0], np.tile(np.linspace(0.0, 2.0 * math.pi, 12,
                                                          endpoint=False), 3)))


@_compiled
def _ray_hidden(p: NDArray[np.float64], c: NDArray[np.float64], n: NDArray[np.float64],
                radius: float, height: float, tolerance: float
                ) -> bool:  # pragma: no cover - compiled
    """Whether the ray from the camera to point ``p`` (3,) passes through the solid cylinder
    of ``radius`` and ``height`` (m) whose face is centred at ``c`` with inward unit normal
    ``n`` (the body extends along it) before reaching ``p``, by more than ``tolerance`` (m).
    Camera frame, m."""
    dist = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    d0, d1, d2 = p[0] / dist, p[1] / dist, p[2] / dist
    dn = d0 * n[0] + d1 * n[1] + d2 * n[2]
    cn = c[0] * n[0] + c[1] * n[1] + c[2] * n[2]
    # Across the axis: |w_perp + t d_perp| <= radius, w = -c.
    e0, e1, e2 = d0 - dn * n[0], d1 - dn * n[1], d2 - dn * n[2]
    w0, w1, w2 = -c[0] + cn * n[0], -c[1] + cn * n[1], -c[2] + cn * n[2]
    a = e0 * e0 + e1 * e1 + e2 * e2
    b = e0 * w0 + e1 * w1 + e2 * w2
    cc = w0 * w0 + w1 * w1 + w2 * w2 - radius * radius
    if a > 1e-12:
        disc = b * b - a * cc
        if disc <= 0.0:
            return False
        root = math.sqrt(disc)
        lo, hi = (-b - root) / a, (-b + root) / a
    elif cc > 0.0:
        return False
    else:
        lo, hi = -math.inf, math.inf
    # Along the axis: between the face's plane and the far end's, c.n <= t d.n <= c.n + h.
    if abs(dn) > 1e-12:
        s0, s1 = cn / dn, (cn + height) / dn
        lo, hi = max(lo, min(s0, s1)), min(hi, max(s0, s1))
    elif not 0.0 <= -cn <= height:
        return False
    return hi > lo and lo > 0.0 and lo < dist - tolerance


@_compiled
def _hidden_share(faces: NDArray[np.float64], face_radius: float, others: NDArray[np.float64],
                  other_radius: float, other_height: float, tolerance: float,
                  shares: NDArray[np.float64], angles: NDArray[np.float64]
                  ) -> float:  # pragma: no cover - compiled
    """:func:`hidden_share` of the two unit-radius pose solutions ``faces`` and ``others``
    (2, 6: centre, inward normal), on the disc samples (``shares`` of the radius, ``angles``
    in rad)."""
    least = 1.0
    point = np.empty(3)
    for f in range(2):
        centre, normal = faces[f, :3] * face_radius, faces[f, 3:]
        # An orthonormal basis (u, v) of the face's plane.
        u0, u1, u2, v0, v1, v2 = plane_axes(normal[0], normal[1], normal[2])
        best = 0.0
        for o in range(2):
            c, n = others[o, :3] * other_radius, others[o, 3:]
            hidden = 0
            for k in range(shares.shape[0]):
                x = shares[k] * face_radius * math.cos(angles[k])
                y = shares[k] * face_radius * math.sin(angles[k])
                point[0] = centre[0] + x * u0 + y * v0
                point[1] = centre[1] + x * u1 + y * v1
                point[2] = centre[2] + x * u2 + y * v2
                if _ray_hidden(point, c, n, other_radius, other_height, tolerance):
                    hidden += 1
            best = max(best, hidden / shares.shape[0])
        least = min(least, best)
    return least


def _solutions(face: Ellipse, intrinsics: CameraIntrinsics) -> NDArray[np.float64]:
    """(2, 6) the unit-radius pose solutions of ``face``: centre (m), inward normal."""
    out = np.empty((2, 6))
    for k, s in enumerate(unit_circle_poses(face, intrinsics)):
        out[k, :3], out[k, 3:] = s.centre_cam, s.normal_cam
    return out


def hidden_share(face: Ellipse, other: Ellipse, intrinsics: CameraIntrinsics,
                 face_radius: float, other_radius: float, other_height: float,
                 tolerance: float) -> float:
    """Share [0, 1] of ``face``'s disc (its centre and 12 samples on each ring at 0.35, 0.65
    and 0.9 of its radius) whose ray from the camera passes through ``other``'s solid
    cylinder before reaching it, by more than ``tolerance`` (m): the least over ``face``'s
    two pose solutions and the largest over ``other``'s (the face lies under the cylinder
    whichever way it is tilted, under one of the cylinder's two reconstructions). Radii and
    height in m."""
    return _share(_solutions(face, intrinsics), face_radius, _solutions(other, intrinsics),
                  other_radius, other_height, tolerance)


def _share(face: NDArray[np.float64], face_radius: float, other: NDArray[np.float64],
           other_radius: float, other_height: float, tolerance: float) -> float:
    """:func:`hidden_share` of the pose solutions (:func:`_solutions`) ``face`` and
    ``other``."""
    return float(_hidden_share(face, face_radius, other, other_radius, other_height,
                               tolerance, _RING_SHARES, _RING_ANGLES))


def _within_reach(face: Ellipse, other: Ellipse, other_radius: float, other_height: float
                  ) -> bool:
    """Whether ``other``'s cylinder can reach ``face`` in the image: its image lies within its
    semi-major axis times (1 + height / radius) of its centre (the wall's image is at most the
    face's size times height over radius long), ``face``'s disc within its semi-major axis of
    its centre."""
    reach = other.a * (1.0 + other_height / other_radius) + face.a
    return math.hypot(face.cx - other.cx, face.cy - other.cy) <= reach


def _may_lie_in_front(solutions: tuple[NDArray[np.float64], NDArray[np.float64]],
                      face_radius: float, other_radius: float) -> bool:
    """Whether the other's cylinder can lie in front of the face at all (``solutions``: the
    face's and the other's pose solutions, :func:`_solutions`): its nearest point lies at
    most its radius in front of its face's centre (the nearer solution's), the face's disc
    at most its radius behind its centre."""
    mine, theirs = solutions
    near = other_radius * (min(theirs[0, 2], theirs[1, 2]) - 1.0)
    return bool(near < face_radius * (min(mine[0, 2], mine[1, 2]) + 1.0))


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
    mine = None
    for j in covering:
        other = faces[j]
        if j == i or holds_centre(face, other) or holds_centre(other, face):
            continue
        radius = radius_of(other)
        height = None if radius is None else height_of(radius)
        if radius is None or height is None or not _within_reach(face, other, radius, height):
            continue
        mine = _solutions(face, intrinsics) if mine is None else mine
        theirs = _solutions(other, intrinsics)
        if (_may_lie_in_front((mine, theirs), face_radius, radius)
                and _share(mine, face_radius, theirs, radius, height, tolerance) >= min_share):
            return True
    return False


def warm_up() -> None:
    """Compile (or load from the cache) the compiled pass for the argument types
    :func:`hidden_share` passes."""
    solutions = np.array([[0.0, 0.0, 1.0, 0.0, 0.0, -1.0]] * 2)
    _share(solutions, 0.03, solutions, 0.03, 0.03, 0.001)

"""Stage 6: pose of a circular face from its image ellipse (camera frame, OpenCV axes).

With K known, an image ellipse is a cone ``X^T Q X = 0`` (``Q = K^T C K``, ``C`` the pixel
conic). Sorting Q's eigenvalues so that l1 >= l2 > 0 > l3 (eigenvectors e1, e2, e3), the
planes cutting the cone in circles have normals ``n ~ +-sqrt(l1 - l2) e1 + sqrt(l2 - l3) e3``:
two solutions, the classic two-fold ambiguity. For each normal the circle's centre projects
to the pole of the plane's vanishing line, ``C^-1 K^-T n`` (which corrects the perspective
shift between the ellipse centre and the face centre), and the depth follows from the radius:
everything scales with it, so each candidate radius gives one depth.

**Radius**: of the candidate radii, the one whose implied face depth lies inside the expected
depth range (nearest to the range's middle if several do, nearest to the range if none).
Only depth depends on it; the face-centre pixel and the tilt angles do not.

**Two-fold ambiguity**: the cylinder's side wall is visible on the side its axis leans
towards (the inward normal, projected). Given the colour image, each solution's predicted wall
band is checked for the face's hue at a wall's brightness (:mod:`stackpick_sim.vision.wall`:
under the ring light a wall is at most ~tan(tilt) as bright as its face) and, given the belt's
colour, for not being bare belt: the true band shows the wall, the other the belt or another
object, often a lower face of the same colour, which is as bright as the face. The solution
with the clearly better band wins; a solution whose band is visible but not the face's colour
loses. When neither predicts a visible band (a face seen nearly square on, where both
solutions nearly coincide) the smaller tilt from the optical axis is taken: a face resting
flat under a downward-looking camera.
Without an image, the older test is used: the two straight silhouette lines of each
solution's wall (the hull of the face rim and a rim ``wall_probe_radii`` radii further along
the axis) are checked against the edge map. The settings and their reasons:
:class:`~stackpick_sim.config.vision_params.PoseParams`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, FloatArray, tilt_angles
from stackpick_sim.vision import kernels_pose
from stackpick_sim.vision.wall import WallEvidence, face_colour, plane_basis, wall_evidences

#: The default settings (see PoseParams: the reasons for each).
DEFAULT = PoseParams()


@dataclass(frozen=True, kw_only=True)
class CirclePose:
    """One pose solution: inward unit normal (3,), face centre (3,) m, camera frame."""

    normal_cam: FloatArray
    centre_cam: FloatArray

    @classmethod
    def of(cls, normal_cam: FloatArray, centre_cam: FloatArray) -> CirclePose:
        """``CirclePose(normal_cam=normal_cam, centre_cam=centre_cam)`` (an equal object) at
        a fraction of the frozen dataclass constructor's cost, as
        :meth:`~stackpick_sim.geometry.Ellipse.of` (no validation to skip): every face the
        top rule weighs gets two."""
        pose = object.__new__(cls)
        pose.__dict__.update(normal_cam=normal_cam, centre_cam=centre_cam)
        return pose


@dataclass(frozen=True, kw_only=True)
class Pose:
    """The top face's pose: paper's (x, y, theta_x, theta_y) plus depth and 3-D vectors.

    ``x``, ``y``: face-centre pixel (perspective-corrected); ``theta_x_deg``,
    ``theta_y_deg``: tilt angles (see :mod:`stackpick_sim.geometry`); ``depth_m``: z of the
    face centre; ``normal_cam``: inward face normal; ``centre_cam``: face centre, metres;
    ``radius_m``: the chosen radius; ``wall_support``: wall evidence of the chosen and the
    rejected solution (0-1 each: colour band share with an image, edge-line share without).
    """

    x: float
    y: float
    theta_x_deg: float
    theta_y_deg: float
    depth_m: float
    radius_m: float
    normal_cam: FloatArray
    centre_cam: FloatArray
    wall_support: tuple[float, float]

    def as_dict(self) -> dict[str, float]:
        """JSON-friendly dict of the paper's pose (x, y, theta_x, theta_y) and depth."""
        return {"x": self.x, "y": self.y, "theta_x": self.theta_x_deg,
                "theta_y": self.theta_y_deg, "depth_m": self.depth_m, "radius_m": self.radius_m}


def circle_poses(ellipse: Ellipse, intrinsics: CameraIntrinsics, radius: float
                 ) -> tuple[CirclePose, CirclePose]:
    """The two circle poses (radius ``radius`` m) whose image is ``ellipse``.

    Everything but the scale is independent of the radius, so the unit-radius solutions are
    computed once per (ellipse, intrinsics) (cached: the top rule and the pose ask for the
    same ellipses several times) and scaled; callers get their own arrays.
    """
    unit = unit_circle_poses(ellipse, intrinsics)
    return (CirclePose(normal_cam=unit[0].normal_cam.copy(),
                       centre_cam=unit[0].centre_cam * radius),
            CirclePose(normal_cam=unit[1].normal_cam.copy(),
                       centre_cam=unit[1].centre_cam * radius))


@functools.lru_cache(maxsize=256)
def unit_circle_poses(ellipse: Ellipse, intrinsics: CameraIntrinsics
                      ) -> tuple[CirclePose, CirclePose]:
    """:func:`circle_poses` for a unit radius (read-only arrays: they are shared)."""
    # The cone's form Q = K^T C K in one compiled pass (kernels_pose.cone_of: the arithmetic
    # on floats), numpy for its eigenvectors, then both solutions in another
    # (kernels.circle_solutions, with the conic's inverse written out: for C = [[M, -M c],
    # [-c^T M, c^T M c - 1]] (c the ellipse centre), C^-1 = [[M^-1 - c c^T, -c], [-c^T, -1]],
    # M^-1 = R diag(a^2, b^2) R^T).
    cone, packed, moderate = kernels_pose.cone_of(
        ellipse.cx, ellipse.cy, ellipse.a ** 2, ellipse.b ** 2, ellipse.angle_deg,
        intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy)
    solutions, ok = _solutions(cone, packed, moderate)
    if not ok:
        raise ZeroDivisionError("float division by zero")
    solutions.setflags(write=False)
    return (CirclePose.of(solutions[0, 0], solutions[0, 1]),
            CirclePose.of(solutions[1, 0], solutions[1, 1]))


#: numpy's own eigh kernel (the gufunc np.linalg.eigh calls; None where numpy keeps it
#: elsewhere): a third of eigh's cost on a 3x3 matrix, the rest being its checks and error
#: state. Cones with an entry beyond kernels_pose.EIGH_DIRECT_MAX (or a non-finite one) go
#: to np.linalg.eigh itself, whose error state keeps overflow quiet and raises on
#: non-convergence.
_EIGH_LO = getattr(getattr(np.linalg, "_umath_linalg", None), "eigh_lo", None)


def _solutions(cone: NDArray[np.float64], packed: NDArray[np.float64], moderate: bool
               ) -> tuple[NDArray[np.float64], bool]:
    """The (2, 2, 3) circle solutions of :func:`~stackpick_sim.vision.kernels_pose.cone_of`'s
    ``cone`` and ``packed`` row, and whether they exist, on ``np.linalg.eigh``'s eigen
    decomposition (the same values): its kernel called directly on a ``moderate`` cone (no
    floating-point warning can arise there), ``np.linalg.eigh`` otherwise and wherever that
    decomposition is not finite."""
    if _EIGH_LO is not None and moderate:
        w, v = _EIGH_LO(cone, signature="d->dd")
        solutions, ok, finite = kernels_pose.cone_solutions(packed, w, v)
        if finite:
            return solutions, ok
    w, v = np.linalg.eigh(cone)
    solutions, ok, _ = kernels_pose.cone_solutions(packed, w, v)
    return solutions, ok


def wall_support(pose: CirclePose, radius: float, intrinsics: CameraIntrinsics,
                 support: NDArray[np.uint8], params: PoseParams = DEFAULT) -> float:
    """Share of the predicted wall silhouette lines (px samples) on the (H, W) support map."""
    u, v = plane_basis(pose.normal_cam)
    n_rim, skip = params.wall_rim_points, params.wall_end_skip_px
    t = np.linspace(0.0, 2.0 * np.pi, n_rim, endpoint=False)
    rim = pose.centre_cam + radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), v))
    probe = rim + params.wall_probe_radii * radius * pose.normal_cam
    pts = intrinsics.project(np.vstack([rim, probe])).astype(np.float32)
    hull = cv2.convexHull(pts, returnPoints=False)[:, 0]
    samples = []
    for a, b in zip(hull, np.roll(hull, -1), strict=True):
        if (a < n_rim) == (b < n_rim):
            continue  # not a line from the face rim to the probe rim
        p, q = pts[a].astype(float), pts[b].astype(float)
        length = float(np.hypot(*(q - p)))
        if length <= 2 * skip + 1:
            continue
        s = np.linspace(skip / length, 1.0 - skip / length, max(2, int(length)))
        samples.append(p + np.outer(s, q - p))
    if not samples:
        return 0.0
    pix = np.rint(np.vstack(samples)).astype(np.int64)
    h, w = support.shape
    ok = (pix[:, 0] >= 0) & (pix[:, 0] < w) & (pix[:, 1] >= 0) & (pix[:, 1] < h)
    hits = np.zeros(pix.shape[0], bool)
    hits[ok] = support[pix[ok, 1], pix[ok, 0]] > 0
    return float(hits.mean())


def choose_radius(depth_per_metre: float, radii: Sequence[float],
                  depth_range_m: tuple[float, float] | None) -> float:
    """The candidate radius whose implied depth (``depth_per_metre * r``) fits the range."""
    if not radii:
        raise ValueError("no candidate radii")
    if depth_range_m is None:
        return float(radii[0])
    lo, hi = depth_range_m
    mid = 0.5 * (lo + hi)

    def cost(r: float) -> tuple[float, float]:
        z = depth_per_metre * r
        return (max(lo - z, 0.0, z - hi), abs(z - mid))

    return float(min(radii, key=cost))


def choose_by_band(evidence: Sequence[WallEvidence], params: PoseParams = DEFAULT
                   ) -> int | None:
    """Index (0 or 1) of the solution the two wall bands favour, or None when they cannot tell."""
    visible = [e.samples >= params.min_band_samples for e in evidence]
    if all(visible):
        diff = evidence[0].share - evidence[1].share
        return None if abs(diff) < params.band_tie else (0 if diff > 0 else 1)
    if any(visible):
        lone = visible.index(True)
        return lone if evidence[lone].share >= params.lone_band_min_share else 1 - lone
    return None


def estimate_pose(ellipse: Ellipse, intrinsics: CameraIntrinsics, radii: Sequence[float],
                  support: NDArray[np.uint8] | None = None,
                  depth_range_m: tuple[float, float] | None = None, *,
                  image: NDArray[np.uint8] | None = None,
                  face_rgb: NDArray[np.float64] | None = None,
                  belt: NDArray[np.float64] | None = None,
                  params: PoseParams = DEFAULT) -> Pose:
    """Pose of the face imaged as ``ellipse``; see the module docstring for the choices
    (``params``: their settings).

    ``image`` is the (H, W, 3) RGB frame used for the wall colour test (preferred);
    ``support`` the (H, W) 0/1 dilated edge map used for the edge-line wall test when no image
    is given. With neither, the smaller tilt is taken. ``face_rgb``: the face's (3,) colour in
    ``image`` (:func:`~stackpick_sim.vision.wall.face_colour`) when the caller has it;
    ``belt`` the bare belt's colour in ``image`` (:attr:`~stackpick_sim.vision.roi.Roi.belt`),
    which tells a grey object's wall from the belt.
    """
    unit = unit_circle_poses(ellipse, intrinsics)  # shared, read-only: not modified here
    radius = choose_radius(float(unit[0].centre_cam[2]), radii, depth_range_m)
    tilts = [math.acos(min(1.0, float(s.normal_cam[2]))) for s in unit]
    best: int | None = None
    scores = [0.0, 0.0]
    if image is not None:
        face = face_colour(ellipse, image) if face_rgb is None else face_rgb
        evidence = wall_evidences([(s.normal_cam, s.centre_cam) for s in unit], ellipse,
                                  intrinsics, image, face, belt, params)
        scores = [e.share for e in evidence]
        best = choose_by_band(evidence, params)
    elif support is not None:
        scores = [wall_support(CirclePose(normal_cam=s.normal_cam,
                                          centre_cam=s.centre_cam * radius),
                               radius, intrinsics, support, params) for s in unit]
        if abs(scores[0] - scores[1]) >= params.wall_tie:
            best = 0 if scores[0] > scores[1] else 1
    if best is None:
        best = 0 if tilts[0] <= tilts[1] else 1
    chosen = unit[best]
    centre = chosen.centre_cam * radius
    cx, cy, cz = centre.tolist()  # projected as CameraIntrinsics.project, on floats
    tx, ty = tilt_angles(chosen.normal_cam)
    return Pose(x=intrinsics.fx * cx / cz + intrinsics.cx,
                y=intrinsics.fy * cy / cz + intrinsics.cy, theta_x_deg=tx, theta_y_deg=ty,
                depth_m=cz, radius_m=radius, normal_cam=chosen.normal_cam.copy(),
                centre_cam=centre, wall_support=(scores[best], scores[1 - best]))

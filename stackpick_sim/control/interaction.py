"""Interaction matrices (image Jacobians w.r.t. the camera twist) of the servo features.

Every matrix ``L`` here is (k, 6) and satisfies ``ds/dt = L @ (v, w)`` for a *static* target,
with ``(v, w)`` the camera twist in the camera (OpenCV) frame, ordering of
:mod:`stackpick_sim.control.twist`. Image coordinates are normalised: ``x = X/Z, y = Y/Z``
(``CameraIntrinsics.normalized`` converts pixels).

Two feature sets align the tool with a cylinder's top face:

* ``"pose"`` (default, 2.5-D visual servoing after Malis, Chaumette & Boudet 1999):
  ``s = (x, y, log Z, m_x, m_y)``: the projection and depth of the face centre and the two
  lateral components of the unit inward face normal ``m`` in the camera frame. ``m`` comes
  from the ellipse and the known face radius (the paper's pose output ``theta_x, theta_y``,
  see :func:`stackpick_sim.geometry.normal_from_tilt`). Its matrix is full rank (5) at the
  goal, and the rotation and translation parts decouple there.
* ``"ellipse"`` (ViSP's vpFeatureEllipse): ``s = (x_g, y_g, n20, n11, n02)``, the ellipse
  centroid and centred second moments divided by the area. It needs no pose estimate, but
  for a *circle* seen square-on the tilt changes the moments only to second order, so the
  matrix loses rank exactly at the goal (see :func:`ellipse_interaction`): the tilt converges
  slowly and its final accuracy depends on sub-pixel moment accuracy. That is why the servo
  uses ``"pose"``; ``"ellipse"`` stays available for comparison.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ControlError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse

FloatArray = NDArray[np.float64]

#: Smallest depth (m) accepted in front of the camera; below it 1/Z makes L meaningless.
#: Placeholder: well below any standoff the cell uses (the wrist camera's near clip is 10 mm).
MIN_DEPTH_M = 1e-3

#: Smallest |m_z| accepted for a face normal: a face seen edge-on has no usable ellipse.
MIN_NORMAL_Z = 1e-3


def point_interaction(x: float, y: float, depth: float) -> FloatArray:
    """(2, 6) interaction matrix of a normalised image point (x, y) at depth ``depth`` (m).

    Chaumette & Hutchinson 2006, Eq. 11; ViSP's vpFeaturePoint.
    """
    z = _check_depth(depth)
    return np.array([
        [-1.0 / z, 0.0, x / z, x * y, -(1.0 + x * x), y],
        [0.0, -1.0 / z, y / z, 1.0 + y * y, -x * y, -x],
    ])


def log_depth_interaction(x: float, y: float, depth: float) -> FloatArray:
    """(1, 6) interaction matrix of ``log Z`` of a point at normalised (x, y), depth (m).

    From ``dP/dt = -v - w x P``: ``dZ/dt = -v_z - Y w_x + X w_y``, divided by Z.
    """
    z = _check_depth(depth)
    return np.array([[0.0, 0.0, -1.0 / z, -y, x, 0.0]])


def normal_interaction(normal_cam: FloatArray) -> FloatArray:
    """(2, 6) interaction matrix of (m_x, m_y), the lateral parts of a world-fixed unit normal.

    A direction fixed in the world seen from a camera turning at ``w``: ``dm/dt = -w x m =
    [m]x w``; translation does not change it. Rows are the first two rows of ``[m]x``.
    """
    m = _unit_normal(normal_cam)
    return np.array([
        [0.0, 0.0, 0.0, 0.0, -m[2], m[1]],
        [0.0, 0.0, 0.0, m[2], 0.0, -m[0]],
    ])


def circle_pose_features(centre_cam: FloatArray, normal_cam: FloatArray) -> FloatArray:
    """(5,) features ``(x, y, log Z, m_x, m_y)`` of a face with centre/normal in the camera frame.

    ``centre_cam`` (3,) metres; ``normal_cam`` (3,) either sign, normalised here and flipped to
    the inward normal (``m_z > 0``, geometry.py's convention) so both signs give one feature.
    """
    c = _check_point(centre_cam)
    m = _unit_normal(normal_cam)
    return np.array([c[0] / c[2], c[1] / c[2], math.log(c[2]), m[0], m[1]])


def circle_pose_interaction(centre_cam: FloatArray, normal_cam: FloatArray) -> FloatArray:
    """(5, 6) interaction matrix of :func:`circle_pose_features` (rows in the same order)."""
    c = _check_point(centre_cam)
    x, y, z = c[0] / c[2], c[1] / c[2], c[2]
    return np.vstack([point_interaction(x, y, z), log_depth_interaction(x, y, z),
                      normal_interaction(normal_cam)])


def desired_circle_pose_features(cam_T_tool: FloatArray, standoff: float) -> FloatArray:
    """(5,) goal features: tool axis along the face's inward normal, face centre on the tool axis.

    ``cam_T_tool`` (4, 4): tool (approach +z) frame in the camera frame, metres. ``standoff``
    (m) is the distance from the tool point to the face centre along the tool z axis at the
    goal; it may be negative (the tool pressing past the face, during a grasp or the last
    ticks of a descent) as long as the face centre stays in front of the camera. Rotation
    about the face normal stays free (the face is a circle).
    """
    t = np.asarray(cam_T_tool, dtype=float)
    if t.shape != (4, 4):
        raise ControlError(f"cam_T_tool must be (4, 4); got shape {t.shape}")
    centre = t[:3, :3] @ np.array([0.0, 0.0, standoff]) + t[:3, 3]
    if centre[2] < MIN_DEPTH_M:
        raise ControlError(f"standoff {standoff} m puts the face centre {centre[2]:.4f} m in "
                           f"front of the camera; it must be >= {MIN_DEPTH_M} m")
    return circle_pose_features(centre, t[:3, 2])


def ellipse_moments(ellipse: Ellipse, intrinsics: CameraIntrinsics) -> FloatArray:
    """(5,) ellipse features ``(x_g, y_g, n20, n11, n02)`` in normalised image coordinates.

    ``n_ij = mu_ij / area`` (centred moments over the area): for semi-axes a, b at angle t the
    second-moment matrix is ``R(t) diag(a^2, b^2) R(t)^T / 4``, then scaled by 1/fx, 1/fy.
    """
    centre = intrinsics.normalized(np.array([[ellipse.cx, ellipse.cy]]))[0]
    t = math.radians(ellipse.angle_deg)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    cov_px = rot @ np.diag([ellipse.a**2, ellipse.b**2]) @ rot.T / 4.0
    scale = np.diag([1.0 / intrinsics.fx, 1.0 / intrinsics.fy])
    cov = scale @ cov_px @ scale
    return np.array([centre[0], centre[1], cov[0, 0], cov[0, 1], cov[1, 1]])


def plane_coefficients(point_cam: FloatArray, normal_cam: FloatArray) -> tuple[float, float, float]:
    """(A, B, C) with ``1/Z = A x + B y + C`` on the plane through ``point_cam`` (m) with normal.

    From ``n . (Z x, Z y, Z) = n . p``: ``(A, B, C) = n / (n . p)``, 1/m. Raises if the plane
    passes through the camera centre (it then projects to a line).
    """
    p = np.asarray(point_cam, dtype=float).reshape(3)
    n = _unit_normal(normal_cam)
    d = float(n @ p)
    if abs(d) < MIN_DEPTH_M:
        raise ControlError(f"plane passes {abs(d):.3g} m from the camera centre; need >= "
                           f"{MIN_DEPTH_M} m")
    return float(n[0] / d), float(n[1] / d), float(n[2] / d)


def ellipse_interaction(features: FloatArray, plane: tuple[float, float, float]) -> FloatArray:
    """(5, 6) interaction matrix of ``(x_g, y_g, n20, n11, n02)`` for a planar conic.

    ``features`` from :func:`ellipse_moments`; ``plane`` (A, B, C) 1/m from
    :func:`plane_coefficients`. Rows after Chaumette 2004 (image moments), as in ViSP's
    vpFeatureEllipse; ViSP's older releases store ``4 n_ij`` (so a circle has ``r^2``), hence
    the factor 4 in the centroid rows here, checked against finite differences. At the goal
    of a circle seen square-on (A = B = 0, n11 = 0, centred) the w_x, w_y columns of the
    moment rows vanish: tilt is unobservable to first order.
    """
    s = np.asarray(features, dtype=float).reshape(5)
    xg, yg, n20, n11, n02 = s
    a, b, c = plane
    inv_z = a * xg + b * yg + c
    if inv_z <= 1.0 / 1e6:
        raise ControlError(f"plane gives 1/Z = {inv_z:.3g} 1/m at the centroid; need > 0")
    return np.array([
        [-inv_z, 0.0, xg * inv_z + 4.0 * (a * n20 + b * n11), xg * yg + 4.0 * n11,
         -1.0 - xg * xg - 4.0 * n20, yg],
        [0.0, -inv_z, yg * inv_z + 4.0 * (a * n11 + b * n02), 1.0 + yg * yg + 4.0 * n02,
         -xg * yg - 4.0 * n11, -xg],
        [-2.0 * (a * n20 + b * n11), 0.0, 2.0 * ((inv_z + a * xg) * n20 + b * xg * n11),
         2.0 * (yg * n20 + xg * n11), -4.0 * n20 * xg, 2.0 * n11],
        [-a * n11 - b * n02, -a * n20 - b * n11,
         a * yg * n20 + (3.0 * inv_z - c) * n11 + b * xg * n02,
         3.0 * yg * n11 + xg * n02, -yg * n20 - 3.0 * xg * n11, n02 - n20],
        [0.0, -2.0 * (a * n11 + b * n02), 2.0 * ((inv_z + b * yg) * n02 + a * yg * n11),
         4.0 * yg * n02, -2.0 * (yg * n11 + xg * n02), -2.0 * n11],
    ])


def _check_depth(depth: float) -> float:
    if not depth >= MIN_DEPTH_M:
        raise ControlError(f"depth must be >= {MIN_DEPTH_M} m in front of the camera; got {depth}")
    return float(depth)


def _check_point(point_cam: FloatArray) -> FloatArray:
    p = np.asarray(point_cam, dtype=float)
    if p.shape != (3,):
        raise ControlError(f"a camera-frame point must have shape (3,); got {p.shape}")
    _check_depth(float(p[2]))
    return p


def _unit_normal(normal_cam: FloatArray) -> FloatArray:
    m = np.asarray(normal_cam, dtype=float)
    if m.shape != (3,):
        raise ControlError(f"a normal must have shape (3,); got {m.shape}")
    norm = float(np.linalg.norm(m))
    if norm == 0.0:
        raise ControlError("a normal must be non-zero; got (0, 0, 0)")
    m = m / norm
    if abs(m[2]) < MIN_NORMAL_Z:
        raise ControlError(f"face seen edge-on: |m_z| = {abs(m[2]):.3g} < {MIN_NORMAL_Z}")
    return m if m[2] > 0.0 else -m

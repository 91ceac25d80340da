"""Pixels to world points on a plane or at a known depth, and back.

``world_T_cam`` (4, 4) is the camera pose in the world with OpenCV camera axes (see
:mod:`stackpick_sim.geometry`), e.g. from forward kinematics
(:meth:`stackpick_sim.control.eye_in_hand.EyeInHand.world_T_cam`). The belt plane is
``z = const`` in the world and the belt moves along world +y; a face centre is tracked on
the horizontal plane through it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import EstimationError
from stackpick_sim.geometry import CameraIntrinsics

FloatArray = NDArray[np.float64]

#: Smallest |cos| between a viewing ray and the plane normal: grazing rays amplify pixel
#: noise by 1/cos, and at 0.01 (89.4 deg) by 100x, beyond any use.
MIN_RAY_PLANE_COS = 1e-2

#: World +z: the normal of the belt plane.
WORLD_UP: FloatArray = np.array([0.0, 0.0, 1.0])


def pixel_rays(pixels: FloatArray, intrinsics: CameraIntrinsics,
               world_T_cam: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Viewing rays of (N, 2) pixels: ``(origin (3,), directions (N, 3))`` in the world, metres.

    Directions are scaled so that their camera-frame z is 1 (a point at depth Z is
    ``origin + Z * direction``), not unit length.
    """
    t = _check_pose(world_T_cam)
    xy = intrinsics.normalized(np.asarray(pixels, dtype=float).reshape(-1, 2))
    rays_cam = np.column_stack([xy, np.ones(len(xy))])
    return t[:3, 3].copy(), rays_cam @ t[:3, :3].T


def backproject_to_plane(pixels: FloatArray, intrinsics: CameraIntrinsics,
                         world_T_cam: FloatArray, plane_point: FloatArray,
                         plane_normal: FloatArray = WORLD_UP) -> FloatArray:
    """(N, 3) world points (m) where the rays of (N, 2) pixels meet a plane.

    The plane passes through ``plane_point`` (3,) with normal ``plane_normal`` (3,), world
    frame. Raises EstimationError for a ray (nearly) parallel to the plane or meeting it
    behind the camera.
    """
    origin, dirs = pixel_rays(pixels, intrinsics, world_T_cam)
    n = _unit(plane_normal)
    denom = dirs @ n
    cos = np.abs(denom) / np.linalg.norm(dirs, axis=1)
    if np.any(cos < MIN_RAY_PLANE_COS):
        raise EstimationError(f"a viewing ray grazes the plane (|cos| = {cos.min():.3g} < "
                              f"{MIN_RAY_PLANE_COS})")
    depth = ((np.asarray(plane_point, dtype=float) - origin) @ n) / denom
    if np.any(depth <= 0.0):
        raise EstimationError(f"the plane is behind the camera for some pixels (depth "
                              f"{depth.min():.3g} m); it must be in front")
    return np.asarray(origin + depth[:, None] * dirs)


def backproject_at_depth(pixels: FloatArray, intrinsics: CameraIntrinsics,
                         world_T_cam: FloatArray, depth: float | FloatArray) -> FloatArray:
    """(N, 3) world points (m) of (N, 2) pixels at camera-frame depth(s) Z > 0 (m)."""
    z = np.asarray(depth, dtype=float)
    if np.any(z <= 0.0):
        raise EstimationError(f"depth must be > 0 m (in front of the camera); got {depth}")
    origin, dirs = pixel_rays(pixels, intrinsics, world_T_cam)
    return np.asarray(origin + np.reshape(z, (-1, 1)) * dirs)


def project_to_pixels(points_world: FloatArray, intrinsics: CameraIntrinsics,
                      world_T_cam: FloatArray) -> FloatArray:
    """(N, 2) pixels (u, v) of (N, 3) world points (m); the inverse of the back-projections."""
    t = _check_pose(world_T_cam)
    p = np.asarray(points_world, dtype=float).reshape(-1, 3)
    p_cam = (p - t[:3, 3]) @ t[:3, :3]
    if np.any(p_cam[:, 2] <= 0.0):
        raise EstimationError(f"a point is behind the camera (z = {p_cam[:, 2].min():.3g} m)")
    return intrinsics.project(p_cam)


def plane_backprojection_jacobian(pixel: FloatArray, intrinsics: CameraIntrinsics,
                                  world_T_cam: FloatArray, plane_point: FloatArray,
                                  plane_normal: FloatArray = WORLD_UP) -> FloatArray:
    """(3, 2) derivative (m/px) of the plane point w.r.t. the pixel (u, v) at ``pixel`` (2,).

    With ``X = o + s d``, ``s = n.(p0 - o) / n.d``: ``dX/dd = s (I - d n^T / n.d)`` and
    ``dd/du = R[:, 0] / fx``, ``dd/dv = R[:, 1] / fy``. Maps pixel noise covariance into
    world covariance: ``Sigma_X = G Sigma_px G^T`` (the belt tracker's R).
    """
    t = _check_pose(world_T_cam)
    point = backproject_to_plane(np.reshape(pixel, (1, 2)), intrinsics, t, plane_point,
                                 plane_normal)[0]
    n = _unit(plane_normal)
    _, dirs = pixel_rays(np.reshape(pixel, (1, 2)), intrinsics, t)
    d = dirs[0]
    s = float((point - t[:3, 3]) @ n / (d @ n))
    dx_dd = s * (np.eye(3) - np.outer(d, n) / (d @ n))
    dd_duv = np.column_stack([t[:3, 0] / intrinsics.fx, t[:3, 1] / intrinsics.fy])
    return np.asarray(dx_dd @ dd_duv)


def transfer_via_plane(pixel: FloatArray, intrinsics: CameraIntrinsics, from_T_cam: FloatArray,
                       to_T_cam: FloatArray, plane_point: FloatArray,
                       plane_normal: FloatArray = WORLD_UP) -> tuple[FloatArray, FloatArray]:
    """A pixel of camera pose ``from_T_cam`` seen from ``to_T_cam``, through a world plane.

    The plane-induced homography between two views: back-project ``pixel`` (2,) onto the
    plane, project the point into the other view. Returns the (2,) pixel and the (2, 2)
    Jacobian d(pixel in ``to``)/d(pixel in ``from``) there (chain rule through
    :func:`plane_backprojection_jacobian`). Raises EstimationError as the back-projection
    and projection do.
    """
    point = backproject_to_plane(np.reshape(pixel, (1, 2)), intrinsics, from_T_cam,
                                 plane_point, plane_normal)
    g = plane_backprojection_jacobian(pixel, intrinsics, from_T_cam, plane_point, plane_normal)
    t = _check_pose(to_T_cam)
    c = (point[0] - t[:3, 3]) @ t[:3, :3]
    if c[2] <= 0.0:
        raise EstimationError(f"the plane point is behind the target camera (z = {c[2]:.3g} m)")
    dproj = np.array([[intrinsics.fx / c[2], 0.0, -intrinsics.fx * c[0] / c[2] ** 2],
                      [0.0, intrinsics.fy / c[2], -intrinsics.fy * c[1] / c[2] ** 2]])
    return intrinsics.project(c)[0], np.asarray(dproj @ t[:3, :3].T @ g)


def _check_pose(world_T_cam: FloatArray) -> FloatArray:
    t = np.asarray(world_T_cam, dtype=float)
    if t.shape != (4, 4):
        raise EstimationError(f"world_T_cam must be a (4, 4) transform; got shape {t.shape}")
    return t


def _unit(v: FloatArray) -> FloatArray:
    a = np.asarray(v, dtype=float).reshape(3)
    norm = float(np.linalg.norm(a))
    if norm == 0.0:
        raise EstimationError("a plane normal must be non-zero; got (0, 0, 0)")
    return a / norm

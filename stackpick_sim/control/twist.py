"""Rigid transforms and the velocity twist transform between frames.

Conventions:

* A homogeneous transform ``a_T_b`` (4, 4) maps points expressed in frame ``b`` to frame
  ``a``: ``p_a = a_T_b @ [p_b, 1]``.
* A twist is the (6,) vector ``(v, w)``: linear velocity first (m/s), then angular velocity
  (rad/s), ViSP's ordering. ``v`` is the velocity of the *origin* of the frame the twist is
  expressed in, and both parts are expressed in that frame's axes.
* ``a_V_b = velocity_twist_matrix(a_T_b)`` (ViSP's ``cVe`` for ``a=c, b=e``) maps the twist
  of a rigid body expressed at/in frame ``b`` to the same motion expressed at/in frame ``a``
  (both frames fixed to the same body, e.g. camera and end effector on the wrist):
  ``[v_a, w_a] = a_V_b @ [v_b, w_b]`` with ``a_V_b = [[R, [t]x R], [0, R]]``,
  ``(R, t) = a_T_b``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ControlError

FloatArray = NDArray[np.float64]


def skew(w: FloatArray) -> FloatArray:
    """(3, 3) matrix ``[w]x`` with ``[w]x @ p == cross(w, p)`` for a (3,) vector ``w``."""
    x, y, z = np.asarray(w, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def make_transform(rotation: FloatArray, translation: FloatArray) -> FloatArray:
    """(4, 4) homogeneous transform from a (3, 3) rotation and a (3,) translation (metres)."""
    t = np.eye(4)
    t[:3, :3] = np.asarray(rotation, dtype=float)
    t[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return t


def invert_transform(a_T_b: FloatArray) -> FloatArray:
    """``b_T_a`` from a (4, 4) rigid transform ``a_T_b`` (uses R^T, not a general inverse)."""
    t = _check_transform(a_T_b, "a_T_b")
    r = t[:3, :3]
    return make_transform(r.T, -r.T @ t[:3, 3])


def velocity_twist_matrix(a_T_b: FloatArray) -> FloatArray:
    """(6, 6) ``a_V_b`` taking a twist (v, w) at/in frame ``b`` to the same twist at/in ``a``.

    Both frames are rigidly attached to the same moving body. ``a_T_b`` is (4, 4) with the
    translation in metres. This is the SE(3) adjoint for the (v, w) ordering.
    """
    t = _check_transform(a_T_b, "a_T_b")
    r = t[:3, :3]
    out = np.zeros((6, 6))
    out[:3, :3] = r
    out[:3, 3:] = skew(t[:3, 3]) @ r
    out[3:, 3:] = r
    return out


def rotate_twist_matrix(a_R_b: FloatArray) -> FloatArray:
    """(6, 6) block-diagonal ``diag(R, R)``: re-expresses a twist's axes without moving its point.

    Used to bring MuJoCo's world-axis Jacobian rows to a body frame: ``e_J = rotate(e_R_w) w_J``.
    """
    r = np.asarray(a_R_b, dtype=float)
    if r.shape != (3, 3):
        raise ControlError(f"a rotation must be (3, 3); got shape {r.shape}")
    out = np.zeros((6, 6))
    out[:3, :3] = r
    out[3:, 3:] = r
    return out


def twist_exp(twist: FloatArray, dt: float) -> FloatArray:
    """(4, 4) ``b_T_b'``: where frame ``b`` ends after ``dt`` s at a constant body twist (6,).

    The SE(3) exponential of ``twist * dt`` with ``twist = (v, w)`` in ``b``'s axes (m/s, rad/s);
    a camera at ``world_T_cam`` moving at its own twist is then at ``world_T_cam @ twist_exp``.
    """
    xi = np.asarray(twist, dtype=float).reshape(6) * dt
    v, w = xi[:3], xi[3:]
    theta = float(np.linalg.norm(w))
    k = skew(w)
    if theta < 1e-9:
        rot = np.eye(3) + k
        left = np.eye(3) + 0.5 * k
    else:
        a = np.sin(theta) / theta
        b = (1.0 - np.cos(theta)) / theta**2
        c = (theta - np.sin(theta)) / theta**3
        rot = np.eye(3) + a * k + b * k @ k
        left = np.eye(3) + b * k + c * k @ k
    return make_transform(rot, left @ v)


def _check_transform(t: FloatArray, name: str) -> FloatArray:
    arr = np.asarray(t, dtype=float)
    if arr.shape != (4, 4):
        raise ControlError(f"{name} must be a (4, 4) homogeneous transform; got shape {arr.shape}")
    return arr

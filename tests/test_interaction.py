"""Twist transforms and interaction matrices against finite differences of re-projection."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.control.interaction import (
    circle_pose_features,
    circle_pose_interaction,
    desired_circle_pose_features,
    ellipse_interaction,
    ellipse_moments,
    plane_coefficients,
    point_interaction,
)
from stackpick_sim.control.twist import (
    invert_transform,
    make_transform,
    twist_exp,
    velocity_twist_matrix,
)
from stackpick_sim.exceptions import ControlError
from stackpick_sim.geometry import CameraIntrinsics, project_circle

INTRINSICS = CameraIntrinsics.from_fovy(45.0, 320, 240)
RADIUS = 0.03  # m, face radius of the test cylinder
STEP = 1e-5  # FD step (s at unit twist); central differences, error O(STEP^2)
# Analytic and FD agree to ~1e-9 here; 1e-6 leaves margin for rounding, and a wrong term
# (e.g. ViSP's old moment scaling, off by 3 n20 ~ 7e-3) fails it by three orders.
FD_TOL = 1e-6


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    return twist_exp(np.r_[0.0, 0.0, 0.0, axis], angle)[:3, :3]


def _moved(cam_T_point: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
    """cam'_T_point after the camera moves at ``twist`` (its own frame) for ``dt``."""
    return invert_transform(twist_exp(twist, dt)) @ cam_T_point


def _fd_interaction(features, n_features: int) -> np.ndarray:
    out = np.zeros((n_features, 6))
    for j in range(6):
        tw = np.zeros(6)
        tw[j] = 1.0
        out[:, j] = (features(tw, STEP) - features(tw, -STEP)) / (2 * STEP)
    return out


@pytest.fixture(params=[0, 1, 2])
def circle(request: pytest.FixtureRequest) -> tuple[np.ndarray, np.ndarray]:
    """(centre_cam, inward normal_cam) of tilted, off-axis faces."""
    rng = np.random.default_rng(request.param)
    centre = np.array([*rng.uniform(-0.05, 0.05, 2), rng.uniform(0.2, 0.4)])
    normal = _rot(np.array([1.0, 0.0, 0.0]), rng.uniform(-0.4, 0.4)) @ _rot(
        np.array([0.0, 1.0, 0.0]), rng.uniform(-0.4, 0.4)) @ np.array([0.0, 0.0, 1.0])
    return centre, normal


def test_velocity_twist_matrix_matches_motion_of_attached_frame() -> None:
    rng = np.random.default_rng(7)
    a_T_b = make_transform(_rot(rng.normal(size=3) / 2, 0.8), rng.normal(size=3) * 0.1)
    twist_b = rng.normal(size=6)
    # b moves by b_T_b' = exp(twist_b dt); the attached a moves by a_T_a' = a_T_b b_T_b' b_T_a.
    dt = 1e-6
    moved = a_T_b @ twist_exp(twist_b, dt) @ invert_transform(a_T_b)
    v_fd = (moved[:3, 3]) / dt
    w_fd = np.array([moved[2, 1], moved[0, 2], moved[1, 0]]) / dt
    assert np.allclose(velocity_twist_matrix(a_T_b) @ twist_b, np.r_[v_fd, w_fd], atol=1e-5)
    assert np.allclose(invert_transform(a_T_b) @ a_T_b, np.eye(4), atol=1e-12)


def test_point_interaction_matches_reprojection() -> None:
    p = np.array([0.04, -0.03, 0.3])

    def features(tw: np.ndarray, dt: float) -> np.ndarray:
        q = _moved(make_transform(np.eye(3), p), tw, dt)[:3, 3]
        return q[:2] / q[2]

    analytic = point_interaction(p[0] / p[2], p[1] / p[2], p[2])
    assert np.abs(_fd_interaction(features, 2) - analytic).max() < FD_TOL


def test_circle_pose_interaction_matches_reprojection(circle) -> None:
    centre, normal = circle

    def features(tw: np.ndarray, dt: float) -> np.ndarray:
        c_T_c2 = invert_transform(twist_exp(tw, dt))
        return circle_pose_features(c_T_c2[:3, :3] @ centre + c_T_c2[:3, 3],
                                    c_T_c2[:3, :3] @ normal)

    err = np.abs(_fd_interaction(features, 5) - circle_pose_interaction(centre, normal)).max()
    assert err < FD_TOL


def test_ellipse_interaction_matches_projected_circle(circle) -> None:
    centre, normal = circle

    def features(tw: np.ndarray, dt: float) -> np.ndarray:
        c_T_c2 = invert_transform(twist_exp(tw, dt))
        ellipse = project_circle(c_T_c2[:3, :3] @ centre + c_T_c2[:3, 3],
                                 c_T_c2[:3, :3] @ normal, RADIUS, INTRINSICS)
        return ellipse_moments(ellipse, INTRINSICS)

    s = features(np.zeros(6), 0.0)
    analytic = ellipse_interaction(s, plane_coefficients(centre, normal))
    assert np.abs(_fd_interaction(features, 5) - analytic).max() < FD_TOL


def test_goal_rank_pose_features_full_ellipse_moments_deficient() -> None:
    """Why the servo uses the pose features: at a square-on centred circle, tilt is invisible
    to the ellipse moments to first order (rank 3), while the pose features keep rank 5."""
    centre, normal = np.array([0.0, 0.0, 0.25]), np.array([0.0, 0.0, 1.0])
    s = ellipse_moments(project_circle(centre, normal, RADIUS, INTRINSICS), INTRINSICS)
    l_ellipse = ellipse_interaction(s, plane_coefficients(centre, normal))
    assert np.linalg.matrix_rank(l_ellipse, tol=1e-9) == 3
    assert np.linalg.matrix_rank(circle_pose_interaction(centre, normal), tol=1e-9) == 5


def test_desired_features_put_face_on_tool_axis() -> None:
    cam_T_tool = make_transform(_rot(np.array([1.0, 0.0, 0.0]), 0.1), [0.05, 0.0, 0.02])
    s_star = desired_circle_pose_features(cam_T_tool, 0.1)
    centre = cam_T_tool[:3, :3] @ np.array([0.0, 0.0, 0.1]) + cam_T_tool[:3, 3]
    assert np.allclose(s_star, circle_pose_features(centre, cam_T_tool[:3, 2]))
    # Either sign of the normal gives the same features (inward normal convention).
    assert np.allclose(circle_pose_features(centre, -cam_T_tool[:3, 2]), s_star)
    # A tool pressing 5 mm past the face: still the face centre on the tool axis.
    behind = desired_circle_pose_features(cam_T_tool, -0.005)
    centre = cam_T_tool[:3, :3] @ np.array([0.0, 0.0, -0.005]) + cam_T_tool[:3, 3]
    assert np.allclose(behind, circle_pose_features(centre, cam_T_tool[:3, 2]))


@pytest.mark.parametrize(("call", "match"), [
    (lambda: point_interaction(0.0, 0.0, -0.1), "depth must be >="),
    (lambda: circle_pose_features(np.array([0, 0, 0.3]), np.array([1.0, 0, 0])), "edge-on"),
    (lambda: velocity_twist_matrix(np.eye(3)), r"\(4, 4\)"),
    (lambda: desired_circle_pose_features(np.eye(4), -0.1), "in front of the camera"),
])
def test_bad_inputs_raise_control_error(call, match: str) -> None:
    with pytest.raises(ControlError, match=match):
        call()


@pytest.mark.parametrize("package", ["stackpick_sim.control", "stackpick_sim.estimation"])
def test_every_exported_name_exists(package: str) -> None:
    import importlib

    module = importlib.import_module(package)
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert module.__all__ and not missing

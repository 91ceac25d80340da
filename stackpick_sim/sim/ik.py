"""Inverse kinematics of the arm with mink: reach a frame pose, or the camera look pose.

:func:`solve_ik` iterates mink's differential IK (one :class:`mink.FrameTask` under
:class:`mink.ConfigurationLimit`) to a pose tolerance. The arm has exactly six joints for a
six-dimensional task, so there is no null space to regularise: a posture task would pull the
answer off the target, so we use Levenberg-Marquardt damping instead, which vanishes as the
error does. Speed limits (:data:`stackpick_sim.sim.robot.VELOCITY_LIMITS`) bound motion in
time, not IK solutions, so they are left to whoever executes the motion.

Which of the arm's solution branches (elbow up/down, wrist flipped) comes out is decided by
``q_init``; the default start, :data:`LOOK_SEED_Q`, is elbow up with the tool pointing down.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import mink
import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from stackpick_sim.exceptions import IKError
from stackpick_sim.sim.robot import ARM_JOINTS, CAMERA_SITE

FloatArray = NDArray[np.float64]
FrameType = Literal["body", "geom", "site"]

#: QP backend of mink (qpsolvers' daqp: the one installed with mink here).
QP_SOLVER = "daqp"
#: mink FrameTask Levenberg-Marquardt damping (multiplies |error|^2, so it fades out at the
#: solution). Not critical: 0.1, 1 and 10 reached the same look pose and pick-grid points,
#: within 15 % of each other's time.
LM_DAMPING = 1.0
#: Constant QP damping on every dof: tiny, only keeps the QP strictly convex (free objects in a
#: cell have zero task Jacobian).
QP_DAMPING = 1e-9
#: Default iteration cap. Measured: the look pose converges in 2 iterations from
#: LOOK_SEED_Q, the tests' pick grid in 3-6 from the look pose (about 1.3 ms per solve).
MAX_ITERS = 100
#: Start for IK when none is given, rad: elbow up, tool pointing down (J2 + J3 + J5 = pi).
LOOK_SEED_Q: FloatArray = np.array([0.0, 0.3, 1.6, 0.0, np.pi - 1.9, np.pi / 2])


def arm_qpos_indices(model: mujoco.MjModel) -> NDArray[np.int_]:
    """(6,) indices into qpos of the arm joints, ARM_JOINTS order."""
    try:
        return np.array([model.joint(name).qposadr[0] for name in ARM_JOINTS])
    except KeyError as exc:
        raise IKError(f"model lacks arm joint {exc}; expected joints {', '.join(ARM_JOINTS)}")\
            from None


def _full_qpos(model: mujoco.MjModel, q_init: ArrayLike | None) -> FloatArray:
    """(nq,) start configuration from a full qpos, an arm q or None (LOOK_SEED_Q)."""
    idx = arm_qpos_indices(model)
    q = np.asarray(LOOK_SEED_Q if q_init is None else q_init, dtype=float).ravel()
    if q.shape == (model.nq,):
        return q.copy()
    if q.shape == (len(idx),):
        full = model.qpos0.copy()
        full[idx] = q
        return full
    raise IKError(f"q_init must have shape ({model.nq},) (full qpos) or ({len(idx)},) (arm q); "
                  f"got {q.shape}")


def _pose_error(world_T_frame: FloatArray, world_T_target: FloatArray) -> tuple[float, float]:
    """(position error m, rotation error rad) between two (4, 4) poses."""
    pos_err = float(np.linalg.norm(world_T_frame[:3, 3] - world_T_target[:3, 3]))
    r = world_T_target[:3, :3].T @ world_T_frame[:3, :3]
    cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    return pos_err, float(np.arccos(cos))


def solve_ik(model: mujoco.MjModel, q_init: ArrayLike | None, frame_name: str,
             frame_type: FrameType, world_T_target: ArrayLike, *, pos_tol: float = 1e-5,
             rot_tol: float = 1e-4, max_iters: int = MAX_ITERS) -> FloatArray:
    """Full configuration putting a frame at a target pose, within the joint ranges.

    Args:
        model: any model containing the arm (the arm alone, the robot, or a whole cell).
        q_init: start, (nq,) full qpos or (6,) arm joint angles in rad (other coordinates
            from ``model.qpos0``), or None for :data:`LOOK_SEED_Q`. It picks the branch.
        frame_name: name of the body, geom or site to place.
        frame_type: "body", "geom" or "site".
        world_T_target: (4, 4) homogeneous target pose of the frame in the world, metres.
        pos_tol: position tolerance, m.
        rot_tol: rotation tolerance (angle of the residual rotation), rad.
        max_iters: iteration cap.

    Returns:
        (nq,) full qpos; only the arm joints differ from the start.

    Raises:
        IKError: bad inputs, an unknown frame, a QP failure, or no convergence within
            ``max_iters`` (the message gives the residual).
    """
    target = np.asarray(world_T_target, dtype=float)
    if target.shape != (4, 4):
        raise IKError(f"world_T_target must be a (4, 4) pose; got shape {target.shape}")
    rot = target[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0.0:
        raise IKError(f"world_T_target's rotation block is not a rotation: {rot.tolist()}")
    configuration = mink.Configuration(model)
    configuration.update(_full_qpos(model, q_init))
    try:
        task = mink.FrameTask(frame_name, frame_type, position_cost=1.0, orientation_cost=1.0,
                              lm_damping=LM_DAMPING)
        configuration.get_transform_frame_to_world(frame_name, frame_type)
    except (mink.InvalidFrame, ValueError, KeyError) as exc:
        raise IKError(f"unknown {frame_type} {frame_name!r}: {exc}") from None
    task.set_target(mink.SE3.from_matrix(target))
    limits: Sequence[mink.Limit] = [mink.ConfigurationLimit(model)]
    pos_err = rot_err = float("inf")
    for _ in range(max_iters + 1):
        frame = configuration.get_transform_frame_to_world(frame_name, frame_type).as_matrix()
        pos_err, rot_err = _pose_error(frame, target)
        if pos_err <= pos_tol and rot_err <= rot_tol:
            return configuration.q.copy()
        try:
            # dt = 1: the QP's step is a full Gauss-Newton step on the task error.
            v = mink.solve_ik(configuration, [task], 1.0, QP_SOLVER, damping=QP_DAMPING,
                              limits=limits)
        except (mink.NoSolutionFound, mink.NotWithinConfigurationLimits) as exc:
            raise IKError(f"IK for {frame_type} {frame_name!r} failed: {exc}") from None
        configuration.integrate_inplace(v, 1.0)
    raise IKError(
        f"IK for {frame_type} {frame_name!r} did not converge in {max_iters} iterations: "
        f"residual {pos_err:.3g} m (tol {pos_tol:.3g}), {rot_err:.3g} rad (tol {rot_tol:.3g})")


def look_rotation(image_u_world: ArrayLike = (0.0, 1.0, 0.0)) -> FloatArray:
    """(3, 3) world rotation of a MuJoCo camera frame looking straight down.

    The optical axis (camera -z) is -world z; the image +u axis (camera x, OpenCV x) is
    ``image_u_world`` projected onto the horizontal plane; camera y = z cross x.
    """
    u = np.asarray(image_u_world, dtype=float).ravel()
    if u.shape != (3,):
        raise IKError(f"image_u_world must be a 3-vector; got shape {u.shape}")
    u = u - np.array([0.0, 0.0, u[2]])
    norm = float(np.linalg.norm(u))
    if norm < 1e-9:
        raise IKError(f"image_u_world must have a horizontal component; got {u.tolist()}")
    x = u / norm
    z = np.array([0.0, 0.0, 1.0])
    return np.column_stack([x, np.cross(z, x), z])


def look_pose_q(model: mujoco.MjModel, look_point_world: ArrayLike, camera_height_m: float,
                image_u_world: ArrayLike = (0.0, 1.0, 0.0), *,
                q_init: ArrayLike | None = None) -> FloatArray:
    """(6,) arm joint angles (rad) of the look pose.

    The camera site ends ``camera_height_m`` (m) straight above ``look_point_world`` (3,)
    (m, world), looking straight down (optical axis = -world z), with the image's +u axis
    along ``image_u_world`` (made horizontal). ``q_init`` as in :func:`solve_ik`. Raises
    IKError if the pose is out of reach or the inputs are malformed.
    """
    point = np.asarray(look_point_world, dtype=float).ravel()
    if point.shape != (3,):
        raise IKError(f"look_point_world must be a 3-vector; got shape {point.shape}")
    if not camera_height_m > 0.0:
        raise IKError(f"camera_height_m must be > 0 m; got {camera_height_m}")
    world_T_cam = np.eye(4)
    world_T_cam[:3, :3] = look_rotation(image_u_world)
    world_T_cam[:3, 3] = point + np.array([0.0, 0.0, camera_height_m])
    q = solve_ik(model, q_init, CAMERA_SITE, "site", world_T_cam)
    return q[arm_qpos_indices(model)]


def tool_down_pose(tip_world: ArrayLike, yaw_rad: float = 0.0) -> FloatArray:
    """(4, 4) pose of the tool site with its +z (approach) along -world z at ``tip_world`` (m).

    At ``yaw_rad`` = 0 the tool is turned as at the look pose: tool +x (the camera image's +u)
    along +world y, tool +y along +world x, so the camera (offset along tool +y) sits on the
    side away from the robot. ``yaw_rad`` turns the tool about +world z from there.
    """
    tip = np.asarray(tip_world, dtype=float).ravel()
    if tip.shape != (3,):
        raise IKError(f"tip_world must be a 3-vector; got shape {tip.shape}")
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = np.eye(4)
    out[:3, :3] = yaw @ np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    out[:3, 3] = tip
    return out

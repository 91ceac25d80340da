"""The arm's controller: approach with a mink FrameTask, servo with the image Jacobian.

Both produce arm joint velocities within the joint ranges and the VS-060's speed limits
(mink ``ConfigurationLimit`` + ``VelocityLimit``). They are integrated into the position
actuators' targets ``q_cmd``; the actuators are PD servos (``kp (q_cmd - q) - kv qdot``), which
follow a ramp ``(kv + b) / kp`` seconds late (``b`` the joint damping), so the commanded rate
is added ahead of the target by that much (velocity feed-forward).

Servo features are the 2.5-D circle-pose features of :mod:`stackpick_sim.control.interaction`
(face-centre projection, log depth, lateral normal components) computed from the tracked face
*predicted to the control instant* by the Kalman filter: the camera gives a pose every 33 ms,
``camera.latency_s`` late; the controller runs every ``episode.control_period``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mink
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.control import (
    EyeInHand,
    JointVelocityExecutor,
    ServoConfig,
    circle_pose_features,
    circle_pose_interaction,
    desired_circle_pose_features,
    invert_transform,
    saturated_servo_velocity,
    servo_velocity,
    target_feature_rate,
)
from stackpick_sim.control.reach import tool_pose_on_axis
from stackpick_sim.pipeline import TargetState
from stackpick_sim.sim.cell import Cell
from stackpick_sim.sim.robot import ARM_JOINTS, CAMERA, TOOL_SITE, VELOCITY_LIMITS

FloatArray = NDArray[np.float64]

#: QP backend of mink (the one installed with it here).
QP_SOLVER = "daqp"
#: A joint this close to an end of its range counts as "at the limit", rad.
LIMIT_MARGIN = 0.02
#: Orientation weight of the approach FrameTask relative to position (1/m per rad): the
#: approach only needs to bring the face into the servo's basin.
APPROACH_ORIENTATION_COST = 0.5
#: Levenberg-Marquardt damping of the approach task (see stackpick_sim/sim/ik.py).
APPROACH_LM_DAMPING = 1e-3


@dataclass(frozen=True, kw_only=True)
class ServoErrors:
    """Where the tool stands relative to the goal: metres and degrees."""

    lateral: float
    """Face centre's distance from the tool axis, m."""
    depth: float
    """Face centre's distance along the tool axis minus the commanded standoff, m."""
    tilt_deg: float
    """Angle between the tool axis and the face normal, degrees."""
    feature_norm: float
    """Infinity norm of the feature error (normalised units)."""


class ArmController:
    """Integrates joint-velocity commands into the arm's position targets."""

    def __init__(self, cell: Cell, servo: ServoConfig | None = None) -> None:
        model = cell.model
        self.cell = cell
        self.eih = EyeInHand(model, site=TOOL_SITE, camera=CAMERA, joints=ARM_JOINTS)
        limits = dict(zip(ARM_JOINTS, (float(v) for v in VELOCITY_LIMITS), strict=True))
        self.executor = JointVelocityExecutor(model, self.eih, limits)
        self.servo = servo or ServoConfig()
        self._config = mink.Configuration(model)
        self._task = mink.FrameTask(TOOL_SITE, "site", position_cost=1.0,
                                    orientation_cost=APPROACH_ORIENTATION_COST,
                                    lm_damping=APPROACH_LM_DAMPING)
        self._ik_limits: list[mink.Limit] = [mink.ConfigurationLimit(model),
                                             mink.VelocityLimit(model, limits)]
        ids = cell.arm_actuator_ids
        kp = model.actuator_gainprm[ids, 0]
        kv = -model.actuator_biasprm[ids, 2]
        self.lag = (kv + model.dof_damping[cell.arm_dof_adr]) / kp
        """(6,) ramp-following delay of each joint's PD servo, s."""
        jnt = [model.joint(n).id for n in ARM_JOINTS]
        self._lo = model.jnt_range[jnt, 0]
        self._hi = model.jnt_range[jnt, 1]
        self.q_cmd = np.asarray(cell.look_q, dtype=float).copy()
        self.qdot_cmd = np.zeros(6)
        data = cell.data
        self.cam_T_tool = self.eih.cam_T_ee(data)
        """(4, 4) tool frame in the camera frame (fixed by the mount)."""

    def full_qpos(self) -> FloatArray:
        """(nq,) the cell's configuration with the arm at its commanded joint angles."""
        q = self.cell.data.qpos.copy()
        q[self.eih.qpos_indices] = self.q_cmd
        return q

    def at_limit(self) -> bool:
        """Whether a commanded joint is within LIMIT_MARGIN of its range."""
        return bool(np.any(self.q_cmd < self._lo + LIMIT_MARGIN)
                    or np.any(self.q_cmd > self._hi - LIMIT_MARGIN))

    def apply(self, qdot: FloatArray, dt: float) -> None:
        """Integrate (6,) joint rates (rad/s) over ``dt`` s into the actuator targets."""
        self.qdot_cmd = np.asarray(qdot, dtype=float)
        self.q_cmd = np.clip(self.q_cmd + self.qdot_cmd * dt, self._lo, self._hi)
        self.cell.data.ctrl[self.cell.arm_actuator_ids] = self.q_cmd + self.lag * self.qdot_cmd

    def hold(self) -> None:
        """Keep the current targets, at rest."""
        self.apply(np.zeros(6), 1.0)

    def pose_rate(self, world_T_target: FloatArray, gain: float, dt: float) -> FloatArray:
        """(6,) joint rates moving the tool towards a pose: mink FrameTask within limits.

        ``gain`` (1/s) is the share of the pose error corrected per second; the task runs
        on the commanded configuration (the reference trajectory).
        """
        self._config.update(self.full_qpos())
        self._task.gain = min(1.0, gain * dt)
        self._task.set_target(mink.SE3.from_matrix(world_T_target))
        v = mink.solve_ik(self._config, [self._task], dt, QP_SOLVER, damping=1e-9,
                          limits=self._ik_limits)
        return np.asarray(v[self.eih.dof_indices], dtype=float)

    def command_world_T_tool(self) -> FloatArray:
        """(4, 4) tool pose at the commanded joint angles."""
        self._config.update(self.full_qpos())
        return np.asarray(self._config.get_transform_frame_to_world(TOOL_SITE, "site")
                          .as_matrix())

    def servo_rate(self, target: TargetState, standoff: float, standoff_rate: float,
                   dt: float) -> FloatArray:
        """(6,) joint rates of the servo law.

        ``u = -lambda J^+ e - J^+ (de/dt_target - ds*/dt)`` with ``J = L cVe eJe`` at the
        measured joint angles, ``e = s - s*``; ``s*`` puts the tool axis on the face normal
        through its centre, ``standoff`` m away, changing at ``standoff_rate`` m/s (descent).
        """
        data = self.cell.data
        world_T_cam = self.eih.world_T_cam(data)
        r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
        c_cam = r.T @ (target.centre - p)
        n_cam = r.T @ target.normal
        s = circle_pose_features(c_cam, n_cam)
        s_star = desired_circle_pose_features(self.cam_T_tool, standoff)
        # The goal's own motion, unclamped: the standoff goes below 0 at the end of a descent
        # and in the grasp's preload, and a goal rate computed against a clamped next goal
        # asked the arm to back off at up to overtravel / dt (0.6 m/s) there.
        s_next = desired_circle_pose_features(self.cam_T_tool, standoff + standoff_rate * dt)
        ds_star = (s_next - s_star) / dt
        interaction = circle_pose_interaction(c_cam, n_cam)
        jac = self.eih.image_jacobian(interaction, data)
        rate = target_feature_rate(interaction, r.T, target.velocity) - ds_star
        error = s - s_star
        qdot = servo_velocity(jac, error, self.servo, rate)
        limit = self.executor.speed_limit
        if np.any(np.abs(qdot) > limit):  # the face centre first, the tool's turn after it
            qdot = saturated_servo_velocity(jac, error, self.servo, limit, rate)
        return self.executor.feasible_velocity(self.full_qpos(), qdot, dt)

    def servo_errors(self, target: TargetState, standoff: float) -> ServoErrors:
        """Where the tool stands relative to the face ``target`` at ``standoff`` m."""
        data = self.cell.data
        world_T_cam = self.eih.world_T_cam(data)
        r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
        s = circle_pose_features(r.T @ (target.centre - p), r.T @ target.normal)
        error = s - desired_circle_pose_features(self.cam_T_tool, standoff)
        tool = self.eih.world_T_ee(data)
        c_tool = invert_transform(tool) @ np.r_[target.centre, 1.0]
        cos = float(np.clip(tool[:3, 2] @ target.normal, -1.0, 1.0))
        return ServoErrors(lateral=float(np.hypot(c_tool[0], c_tool[1])),
                           depth=float(c_tool[2] - standoff),
                           tilt_deg=math.degrees(math.acos(cos)),
                           feature_norm=float(np.max(np.abs(error))))


def approach_pose(target: TargetState, standoff: float, world_T_tool: FloatArray) -> FloatArray:
    """(4, 4) tool pose on the face normal ``standoff`` m above the face, yaw kept.

    Tool +z (approach) along the inward normal; tool +x is the current +x made
    perpendicular to it, so the tool turns as little as possible about the approach axis.
    """
    return tool_pose_on_axis(target.centre, target.normal, standoff, world_T_tool)


def pose_error(a: FloatArray, b: FloatArray) -> tuple[float, float]:
    """(position error m, rotation angle degrees) between two (4, 4) poses."""
    pos = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    r = a[:3, :3].T @ b[:3, :3]
    cos = float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))
    return pos, math.degrees(math.acos(cos))

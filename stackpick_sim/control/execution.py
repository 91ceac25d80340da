"""Execute servo joint velocities through mink within joint-position and velocity limits.

The servo law gives a desired arm joint velocity ``qdot_des``. Executing it as is could drive
a joint through its range or past its speed limit. :class:`JointVelocityExecutor` solves
mink's differential-IK QP with one task, :class:`JointVelocityTask` (``min |dq - qdot_des dt|^2``),
under ``ConfigurationLimit`` and ``VelocityLimit``. With no limit active the result is
``qdot_des`` exactly. Before the QP, ``qdot_des`` is scaled uniformly so the fastest joint
is at its speed limit: scaling keeps the camera's direction of motion (so the image error
still decreases), where clipping joint by joint would bend it; the QP is left to handle only
joints near their position limits.
"""

from __future__ import annotations

from collections.abc import Mapping

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.control.eye_in_hand import EyeInHand
from stackpick_sim.exceptions import ControlError

FloatArray = NDArray[np.float64]

#: QP solver: the only backend installed with mink here (qpsolvers' daqp).
QP_SOLVER = "daqp"

#: mink ConfigurationLimit gain: the share of the remaining distance to a position limit a
#: joint may cover in one step (mink's default 0.95).
POSITION_LIMIT_GAIN = 0.95


class JointVelocityTask(mink.Task):
    """mink task ``e(q) = -qdot_des * dt`` with ``J = I`` on the model's tangent space.

    Its QP term ``|dq + e|^2`` is smallest at ``dq = qdot_des * dt``; dofs outside the arm
    (free objects in the scene) are asked to stay still.
    """

    def __init__(self, nv: int) -> None:
        super().__init__(cost=np.ones(nv), gain=1.0, lm_damping=0.0)
        self._nv = nv
        self._target_dq = np.zeros(nv)

    def set_target_displacement(self, dq: FloatArray) -> None:
        """Set the (nv,) displacement ``qdot_des * dt`` (rad or m) the next solve tracks."""
        self._target_dq = np.asarray(dq, dtype=float).reshape(self._nv).copy()

    def compute_error(self, configuration: mink.Configuration) -> FloatArray:
        """(nv,) task error ``-qdot_des * dt``."""
        return -self._target_dq

    def compute_jacobian(self, configuration: mink.Configuration) -> FloatArray:
        """(nv, nv) identity."""
        return np.eye(self._nv)


class JointVelocityExecutor:
    """Turns a desired arm joint velocity into a feasible one, and integrates it.

    ``velocity_limits`` maps arm joint names to their speed limits (rad/s or m/s); joints not
    named have no speed limit. Position limits are the model's joint ranges.
    """

    def __init__(self, model: mujoco.MjModel, arm: EyeInHand,
                 velocity_limits: Mapping[str, float]) -> None:
        unknown = sorted(set(velocity_limits) - set(arm.joint_names))
        if unknown:
            raise ControlError(f"velocity limits given for non-arm joints {unknown}; arm joints: "
                               f"{', '.join(arm.joint_names)}")
        self.arm = arm
        self.configuration = mink.Configuration(model)
        self.task = JointVelocityTask(model.nv)
        self.limits: list[mink.Limit] = [
            mink.ConfigurationLimit(model, gain=POSITION_LIMIT_GAIN),
            mink.VelocityLimit(model, dict(velocity_limits)),
        ]
        self._speed_limit = np.array([velocity_limits.get(n, np.inf) for n in arm.joint_names])

    @property
    def speed_limit(self) -> FloatArray:
        """(n,) joint speed limits, rad/s, in the arm's joint order (inf where none)."""
        return self._speed_limit.copy()

    def feasible_velocity(self, qpos: FloatArray, qdot_des: FloatArray, dt: float) -> FloatArray:
        """(n,) arm joint velocity closest to ``qdot_des`` (n,) within limits over ``dt`` s.

        ``qpos`` (nq,) is the full model configuration. Raises ControlError when the QP has
        no solution (e.g. the arm starts outside its joint ranges).
        """
        qd = np.asarray(qdot_des, dtype=float)
        if qd.shape != self.arm.dof_indices.shape:
            raise ControlError(f"qdot_des must have shape {self.arm.dof_indices.shape}; "
                               f"got {qd.shape}")
        if dt <= 0.0:
            raise ControlError(f"dt must be > 0 s; got {dt}")
        ratio = float(np.max(np.abs(qd) / self._speed_limit)) if qd.size else 0.0
        if ratio > 1.0:
            qd = qd / ratio
        self.configuration.update(np.asarray(qpos, dtype=float))
        target = np.zeros(self.configuration.nv)
        target[self.arm.dof_indices] = qd * dt
        self.task.set_target_displacement(target)
        try:
            v = mink.solve_ik(self.configuration, [self.task], dt, QP_SOLVER, damping=1e-12,
                              limits=self.limits)
        except mink.NoSolutionFound as exc:
            raise ControlError(f"no feasible joint velocity for qpos={np.round(qpos, 4)}: "
                               f"{exc}") from exc
        return np.asarray(v[self.arm.dof_indices], dtype=float)

    def step(self, qpos: FloatArray, qdot_des: FloatArray, dt: float) -> FloatArray:
        """(nq,) configuration after executing the feasible velocity for ``dt`` s (kinematic)."""
        v = np.zeros(self.configuration.nv)
        v[self.arm.dof_indices] = self.feasible_velocity(qpos, qdot_des, dt)
        return np.asarray(self.configuration.integrate(v, dt))

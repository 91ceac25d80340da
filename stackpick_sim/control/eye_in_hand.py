"""MuJoCo kinematics of the wrist camera: poses, ``c_V_e``, ``e_J_e`` and the image Jacobian.

Frames: ``world``; ``ee``, the end-effector site (the tool point, e.g. ``attachment_site``,
approach axis +z); ``cam``, the wrist camera in OpenCV axes (``R_world_cam = cam_xmat @
MJ_CAM_TO_CV``). ``e_J_e`` (6, n) maps the arm's joint velocities to the ee twist (v, w)
expressed at the site origin in site axes, so that ``c_V_e @ e_J_e`` is the camera twist
in camera axes that the interaction matrices expect.

Every method reading ``data`` needs its kinematics current: ``mj_kinematics`` and
``mj_comPos`` (both run by ``mj_forward``, by mink's ``Configuration.update`` and by
:meth:`EyeInHand.forward`). The camera pose is composed from its body's pose so that
``mj_camlight`` is not needed (only fixed-mode cameras are accepted).
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.control.twist import (
    invert_transform,
    make_transform,
    rotate_twist_matrix,
    velocity_twist_matrix,
)
from stackpick_sim.exceptions import ControlError
from stackpick_sim.geometry import MJ_CAM_TO_CV

FloatArray = NDArray[np.float64]

_ONE_DOF_JOINTS = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


class EyeInHand:
    """Arm joints, tool site and wrist camera of one MuJoCo model; names are resolved once.

    ``joints`` are the arm's 1-dof (hinge or slide) joints in the order of the servo's joint
    vector; other dofs of the model (e.g. free objects on the belt) are ignored.
    """

    def __init__(self, model: mujoco.MjModel, *, site: str, camera: str,
                 joints: Sequence[str]) -> None:
        self.model = model
        self.site_id = _lookup(model, mujoco.mjtObj.mjOBJ_SITE, site, "site")
        self.camera_id = _lookup(model, mujoco.mjtObj.mjOBJ_CAMERA, camera, "camera")
        if int(model.cam_mode[self.camera_id]) != int(mujoco.mjtCamLight.mjCAMLIGHT_FIXED):
            raise ControlError(f"camera '{camera}' must be fixed to its body (mode 'fixed'); "
                               f"got mode {int(model.cam_mode[self.camera_id])}")
        self._camera_body = int(model.cam_bodyid[self.camera_id])
        cam_quat = np.asarray(model.cam_quat[self.camera_id], dtype=float)
        mj_rot = np.zeros(9)
        mujoco.mju_quat2Mat(mj_rot, cam_quat)
        #: (4, 4) camera (OpenCV axes) in its body's frame, fixed at build time.
        self.body_T_cam = make_transform(mj_rot.reshape(3, 3) @ MJ_CAM_TO_CV,
                                         model.cam_pos[self.camera_id])
        ids = [_lookup(model, mujoco.mjtObj.mjOBJ_JOINT, name, "joint") for name in joints]
        for name, jid in zip(joints, ids, strict=True):
            if int(model.jnt_type[jid]) not in _ONE_DOF_JOINTS:
                raise ControlError(f"joint '{name}' is not a hinge or slide joint; the arm "
                                   f"joints must be 1-dof")
        self.joint_names = tuple(joints)
        #: (n,) indices of the arm joints in qvel / the Jacobian columns.
        self.dof_indices = np.array([model.jnt_dofadr[j] for j in ids], dtype=int)
        #: (n,) indices of the arm joints in qpos.
        self.qpos_indices = np.array([model.jnt_qposadr[j] for j in ids], dtype=int)
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))

    def world_T_ee(self, data: mujoco.MjData) -> FloatArray:
        """(4, 4) pose of the tool site in the world (needs mj_kinematics on ``data``)."""
        return make_transform(data.site_xmat[self.site_id].reshape(3, 3),
                              data.site_xpos[self.site_id])

    def forward(self, data: mujoco.MjData, q: FloatArray) -> None:
        """Write the (n,) arm joint positions into ``data`` and update its kinematics."""
        data.qpos[self.qpos_indices] = np.asarray(q, dtype=float)
        mujoco.mj_kinematics(self.model, data)
        mujoco.mj_comPos(self.model, data)

    def world_T_cam(self, data: mujoco.MjData) -> FloatArray:
        """(4, 4) pose of the wrist camera in the world, OpenCV camera axes."""
        world_T_body = make_transform(data.xmat[self._camera_body].reshape(3, 3),
                                      data.xpos[self._camera_body])
        return world_T_body @ self.body_T_cam

    def cam_T_ee(self, data: mujoco.MjData) -> FloatArray:
        """(4, 4) tool site in the camera frame (constant for a rigid wrist mount)."""
        return invert_transform(self.world_T_cam(data)) @ self.world_T_ee(data)

    def cam_V_ee(self, data: mujoco.MjData) -> FloatArray:
        """(6, 6) ``c_V_e``: ee twist (at/in the site) to camera twist (at/in the camera)."""
        return velocity_twist_matrix(self.cam_T_ee(data))

    def ee_jacobian(self, data: mujoco.MjData) -> FloatArray:
        """(6, n) ``e_J_e``: arm joint rates to the site twist (v, w) in site axes.

        mj_jacSite gives the site origin's linear and the body's angular velocity in world
        axes; rotating both by ``R_world_site^T`` expresses them in the site frame.
        """
        mujoco.mj_jacSite(self.model, data, self._jacp, self._jacr, self.site_id)
        w_j = np.vstack([self._jacp[:, self.dof_indices], self._jacr[:, self.dof_indices]])
        site_R_world = data.site_xmat[self.site_id].reshape(3, 3).T
        return rotate_twist_matrix(site_R_world) @ w_j

    def image_jacobian(self, interaction: FloatArray, data: mujoco.MjData) -> FloatArray:
        """(k, n) ``J = L @ c_V_e @ e_J_e`` for a (k, 6) interaction matrix ``L``."""
        return np.asarray(np.asarray(interaction, dtype=float)
                          @ self.cam_V_ee(data) @ self.ee_jacobian(data))

    def arm_q(self, data: mujoco.MjData) -> FloatArray:
        """(n,) the arm's joint positions (rad or m) read from ``data.qpos``."""
        return np.asarray(data.qpos[self.qpos_indices], dtype=float).copy()


def _lookup(model: mujoco.MjModel, obj: mujoco.mjtObj, name: str, kind: str) -> int:
    idx = int(mujoco.mj_name2id(model, obj, name))
    if idx < 0:
        count = {"site": model.nsite, "camera": model.ncam, "joint": model.njnt}[kind]
        known = [mujoco.mj_id2name(model, obj, i) for i in range(count)]
        raise ControlError(f"unknown {kind} '{name}'; the model has: {', '.join(map(str, known))}")
    return idx

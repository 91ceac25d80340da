"""How much of a face's tilt the tool can take at the servo standoff, within joint margins.

The VS-060 has a spherical wrist (J4, J5, J6 axes meet at one point) and the suction cup
sits on the J6 axis, so for a given tool position and approach axis the wrist centre, and
with it J1-J5, are fixed: turning the tool about its approach axis (free for a circular
face) changes J6 only. It cannot relieve J5. What does relieve it is the wrist centre's
position: a face tilted away from the robot puts the tool, at the servo standoff, far out
and high, where the arm is nearly stretched and J5 (forearm to tool axis) passes its
2.094 rad limit (measured with :func:`stackpick_sim.sim.ik.solve_ik` for a face 0.4 m
out: tilt 30 deg needs J5 = 2.06 rad at a 0.15 m standoff, and no solution at 0.19 m;
at the face itself J5 = 1.47 rad).

The wrist also meets itself before J5 meets its range end: the J4 link's capsule touches
the J6 link at J5 = 1.84 rad (the servo then stalls against that contact), and the camera
and bracket on the flange come closer with J6. The check therefore also requires a
clearance between the forearm links and the flange-side bodies (:data:`SELF_CLEARANCE`).

So the tool approaches along a *commanded* axis between straight down and the face
normal: :func:`tilted_axis` with share ``alpha`` of the tilt (1: the face normal). At the
servo standoff ``alpha`` is the largest share whose IK solution keeps every joint
:data:`JOINT_MARGIN` inside its range (:meth:`ReachChecker.tilt_share`); during the descent it
grows linearly to 1 a little above the face (:func:`descent_tilt_share`), so the cup meets
the face square-on, where the wrist centre has come close enough. On a fast belt the face travels
on during the descent (0.3 m/s: ~16 cm) to where even the face itself may be out of reach
square-on; the share at the face is then checked too, at the predicted grasp time and place
(with the smaller :data:`GRASP_JOINT_MARGIN`), and the descent grows to that share only.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import IKError
from stackpick_sim.sim.ik import arm_qpos_indices, solve_ik
from stackpick_sim.sim.robot import TOOL_SITE

FloatArray = NDArray[np.float64]

#: Margin kept between every arm joint and its range ends at the servo pose, rad. The face
#: drifts ~5 cm along the belt during servo and descent (0.1 m/s, ~0.5 s), which moves J5 by
#: up to ~0.1 rad; twice that, placeholder.
JOINT_MARGIN = 0.2
#: Clearance kept between the forearm (J3, J4 links) and the flange-side bodies at the servo
#: pose, m: J5 drifting by ~0.1 rad moves the J6 link ~5 mm at its ~50 mm lever; with
#: margin, placeholder.
SELF_CLEARANCE = 0.012
#: Margins at the grasp pose itself, rad and m: no servo drift is left to come there, only
#: the tracking error of the last millimetres. Placeholders, a quarter and a third of the
#: servo pose's.
GRASP_JOINT_MARGIN = 0.05
GRASP_SELF_CLEARANCE = 0.004
#: Bodies on either side of the wrist whose collision geoms must keep SELF_CLEARANCE apart.
FOREARM_BODIES = ("j3_link", "j4_link")
FLANGE_BODIES = ("j6_link", "bracket_link", "cup_link", "camera_link")
#: Shares of the tilt tried, best first (the last, 0, is straight down).
TILT_SHARES: tuple[float, ...] = (1.0, 0.8, 0.6, 0.4, 0.2, 0.0)
#: IK tolerance for the reach check: a feasibility test, not a motion target (m, rad).
IK_POS_TOL, IK_ROT_TOL = 1e-4, 1e-3
#: IK iterations for the reach check (converges in 3-6 from a nearby posture).
IK_MAX_ITERS = 30
#: World direction of a tool pointing straight down (approach axis).
DOWN: FloatArray = np.array([0.0, 0.0, -1.0])


def tilted_axis(normal: FloatArray, share: float) -> FloatArray:
    """(3,) unit axis between straight down (``share`` 0) and ``normal`` (1), world frame.

    ``normal`` (3,) is the face's unit inward normal (pointing down into the object); the
    axis turns from -z towards it by ``share`` of the angle between them (a slerp).
    """
    n = np.asarray(normal, dtype=float)
    n = n / float(np.linalg.norm(n))
    angle = math.acos(max(-1.0, min(1.0, float(n @ DOWN))))
    if angle < 1e-9 or share >= 1.0:
        return n
    s = max(0.0, share)
    a = (math.sin((1.0 - s) * angle) * DOWN + math.sin(s * angle) * n) / math.sin(angle)
    return np.asarray(a / float(np.linalg.norm(a)))


def descent_tilt_share(share_at_standoff: float, standoff: float, servo_standoff: float,
                       share_at_face: float = 1.0, turned_at: float = 0.0) -> float:
    """Share of the tilt at a tool-to-face distance ``standoff`` m during the descent.

    Linear in the distance: ``share_at_standoff`` at ``servo_standoff`` m, ``share_at_face``
    (1 unless the arm cannot take the whole tilt where the face will be grasped) from
    ``turned_at`` m above the face on (the turn ends there, so that a tool lagging its
    command meets the face at the planned angle).
    """
    span = servo_standoff - max(0.0, turned_at)
    if span <= 0.0:
        return share_at_face
    frac = min(1.0, max(0.0, (standoff - max(0.0, turned_at)) / span))
    return share_at_face - (share_at_face - share_at_standoff) * frac


def tool_pose_on_axis(centre: FloatArray, axis: FloatArray, standoff: float,
                      world_T_tool: FloatArray) -> FloatArray:
    """(4, 4) tool pose with +z along ``axis`` (3,), ``standoff`` m short of ``centre`` (3,).

    The tool's +x is the current one (``world_T_tool`` (4, 4)) made perpendicular to the
    axis: the tool turns as little as possible about the approach axis (J6 only, see the
    module docstring).
    """
    z = np.asarray(axis, dtype=float) / float(np.linalg.norm(axis))
    x = world_T_tool[:3, 0] - (world_T_tool[:3, 0] @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = world_T_tool[:3, 1] - (world_T_tool[:3, 1] @ z) * z
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    out[:3, 3] = np.asarray(centre, dtype=float) - standoff * z
    return out


class ReachChecker:
    """Checks tool poses for joint margin and wrist self-clearance; build once per model."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self._data = mujoco.MjData(model)
        self._idx = arm_qpos_indices(model)
        jnt = [int(np.flatnonzero(model.jnt_qposadr == i)[0]) for i in self._idx]
        self._lo, self._hi = model.jnt_range[jnt, 0], model.jnt_range[jnt, 1]

        def geoms(bodies: tuple[str, ...]) -> list[int]:
            ids = {model.body(b).id for b in bodies}
            return [g for g in range(model.ngeom) if model.geom_bodyid[g] in ids
                    and (model.geom_contype[g] or model.geom_conaffinity[g])]

        self._pairs = [(a, b) for a in geoms(FOREARM_BODIES) for b in geoms(FLANGE_BODIES)]
        self._fromto = np.zeros(6)

    def joint_margin(self, q_arm: FloatArray) -> float:
        """Smallest distance (rad) of the (6,) arm joints from their range ends."""
        return float(np.min(np.minimum(q_arm - self._lo, self._hi - q_arm)))

    def self_clearance(self, qpos: FloatArray) -> float:
        """Smallest distance (m) between forearm and flange-side collision geoms at ``qpos``.

        Capped at 0.05 m (farther is as good); negative when they overlap.
        """
        d = self._data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, d)
        return min(mujoco.mj_geomDistance(self.model, d, a, b, 0.05, self._fromto)
                   for a, b in self._pairs)

    def tilt_share(self, qpos: FloatArray, centre: FloatArray, normal: FloatArray,
                   standoff: float, world_T_tool: FloatArray, margin: float = JOINT_MARGIN,
                   clearance: float = SELF_CLEARANCE) -> tuple[float, float, float]:
        """(share, joint margin rad, clearance m) of the largest tilt share reachable.

        ``qpos`` (nq,) the current configuration (it picks the IK branch); ``centre`` (3,)
        m and ``normal`` (3,) the face (world frame, inward normal) where the pick is
        expected, ``standoff`` m the tool's distance from it; ``world_T_tool`` (4, 4) the
        current tool pose (for the yaw). Tries :data:`TILT_SHARES` in order and returns
        the first whose IK solution keeps ``margin`` rad from every joint limit and
        ``clearance`` m inside the wrist; if none does, the one doing best (share 0 and
        -inf when IK fails everywhere).
        """
        best = (0.0, -math.inf, -math.inf)
        q = np.asarray(qpos, dtype=float)
        for share in TILT_SHARES:
            pose = tool_pose_on_axis(centre, tilted_axis(normal, share), standoff, world_T_tool)
            try:
                sol = solve_ik(self.model, q, TOOL_SITE, "site", pose, pos_tol=IK_POS_TOL,
                               rot_tol=IK_ROT_TOL, max_iters=IK_MAX_ITERS)
            except IKError:
                continue
            m, c = self.joint_margin(sol[self._idx]), self.self_clearance(sol)
            if m >= margin and c >= clearance:
                return share, m, c
            if min(m / margin, c / clearance) > min(best[1] / margin, best[2] / clearance):
                best = (share, m, c)
        return best

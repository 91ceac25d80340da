"""sim/robot.py and sim/ik.py: the arm and tool models, composition, IK, servos, suction."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import pytest

from stackpick_sim.exceptions import IKError, ModelError
from stackpick_sim.paths import model_path
from stackpick_sim.sim import ik, robot

# The VS-060's joint table from Denso's vs060.urdf (DENSORobot/denso_robot_ros, see
# models/vs060/README.md): origin in parent (m), axis,
# range (rad), speed limit (rad/s).
URDF_TABLE = (
    ((0.0, 0.0, 0.1815), (0, 0, 1), (-2.96706, 2.96706), 3.927),
    ((0.0, 0.0, 0.1635), (0, 1, 0), (-2.094395, 2.094395), 2.618),
    ((0.0, 0.0, 0.305), (0, 1, 0), (-2.181662, 2.70526), 2.858),
    ((-0.010, 0.0, 0.1645), (0, 0, 1), (-4.712389, 4.712389), 3.927),
    ((0.0, 0.0, 0.1355), (0, 1, 0), (-2.094395, 2.094395), 3.022),
    ((0.0, 0.0, 0.070), (0, 0, 1), (-6.283185, 6.283185), 6.283),
)
FLANGE_AT_ZERO = np.array([-0.010, 0.0, 1.020])
# The cell: belt centre line x = 0.40 m (conveyor.x default), belt top z = 0.10 m.
LOOK_POINT = np.array([0.40, 0.0, 0.10])
LOOK_HEIGHT = 0.30
# Saving the composed spec to MJCF keeps 6 significant digits (robot.py): joint ranges such as
# 2.094395 come back as 2.0944, 5e-6 rad off.
MJCF_ROUNDING = 5e-6


@pytest.fixture(scope="module")
def arm_model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(model_path("vs060")))


@pytest.fixture(scope="module")
def tool_model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(model_path("suction_cup")))


@pytest.fixture(scope="module")
def robot_model() -> mujoco.MjModel:
    return robot.robot_spec().compile()


@pytest.fixture(scope="module")
def look_q(robot_model: mujoco.MjModel) -> np.ndarray:
    return ik.look_pose_q(robot_model, LOOK_POINT, LOOK_HEIGHT)


def site_pose(model: mujoco.MjModel, qpos: np.ndarray, site: str) -> np.ndarray:
    """(4, 4) world pose of a site at configuration ``qpos``."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out = np.eye(4)
    out[:3, :3] = data.site(site).xmat.reshape(3, 3)
    out[:3, 3] = data.site(site).xpos
    return out


def rotation_angle(r1: np.ndarray, r2: np.ndarray) -> float:
    """Angle (rad) of the rotation between two (3, 3) rotations."""
    return float(np.arccos(np.clip((np.trace(r1.T @ r2) - 1.0) / 2.0, -1.0, 1.0)))


# --- models -------------------------------------------------------------------------------


def test_models_compile_alone_and_composed(arm_model: mujoco.MjModel,
                                           tool_model: mujoco.MjModel,
                                           robot_model: mujoco.MjModel) -> None:
    assert (arm_model.nq, arm_model.nu) == (6, 6)
    assert (tool_model.nq, tool_model.nu, tool_model.ncam) == (0, 1, 1)
    assert robot_model.nq == 6
    assert robot_model.nu == 7
    # Tool attached under the J6 link, no prefix: every public name resolves.
    bracket = robot_model.body(robot.TOOL_ROOT_BODY)
    assert robot_model.body(int(bracket.parentid[0])).name == "j6_link"
    for name in robot.ARM_JOINTS:
        robot_model.joint(name)
    for name in (*robot.ARM_ACTUATORS, robot.SUCTION_ACTUATOR):
        robot_model.actuator(name)
    for name in (robot.FLANGE_SITE, robot.TOOL_SITE, robot.CAMERA_SITE):
        robot_model.site(name)
    robot_model.camera(robot.CAMERA)
    robot_model.body(robot.CAMERA_BODY)
    robot_model.body(robot.CUP_BODY)


@pytest.mark.parametrize("name", ["vs060", "suction_cup"])
def test_every_body_has_an_explicit_inertial(name: str) -> None:
    spec = mujoco.MjSpec.from_file(str(model_path(name)))
    bodies = [b for b in spec.bodies if b.name != "world"]
    assert bodies
    assert all(b.explicitinertial for b in bodies)


def test_masses_are_plausible_and_gravity_compensated(robot_model: mujoco.MjModel) -> None:
    arm = ["base_link", *(f"j{i}_link" for i in range(1, 7))]
    total = sum(robot_model.body(name).mass[0] for name in arm)
    assert 30.0 < total < 40.0  # the real VS-060: about 35 kg
    assert np.all(robot_model.body_mass[1:] > 0.0)
    assert np.all(robot_model.body_inertia[1:] > 0.0)
    # Gravity compensated on every moving body (arm links and tool), not on the fixed base.
    base = robot_model.body("base_link").id
    assert robot_model.body_gravcomp[base] == 0.0
    moving = np.arange(base + 1, robot_model.nbody)
    np.testing.assert_array_equal(robot_model.body_gravcomp[moving], 1.0)


def test_geom_classes(robot_model: mujoco.MjModel) -> None:
    groups = robot_model.geom_group
    visual = groups == 2
    collision = groups == 3
    assert np.all(visual | collision)
    assert np.all(robot_model.geom_contype[visual] == 0)
    assert np.all(robot_model.geom_conaffinity[visual] == 0)
    primitives = {mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER,
                  mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_SPHERE}
    assert all(int(t) in {int(p) for p in primitives} for t in robot_model.geom_type[collision])


def test_robot_spec_round_trips_through_mjcf() -> None:
    spec = robot.robot_spec()
    again = mujoco.MjSpec.from_string(spec.to_xml()).compile()
    first = spec.compile()
    assert (again.nbody, again.ngeom, again.nu, again.ncam) == (
        first.nbody, first.ngeom, first.nu, first.ncam)
    np.testing.assert_array_equal(again.jnt_range, first.jnt_range)


def test_missing_or_broken_model_raises_model_error(monkeypatch: pytest.MonkeyPatch,
                                                    tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "vs060.xml"
    monkeypatch.setattr(robot, "model_path", lambda name: missing)
    with pytest.raises(ModelError, match="nowhere"):
        robot.robot_spec()
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><geom type='sphere'/></worldbody>")
    monkeypatch.setattr(robot, "model_path", lambda name: broken)
    with pytest.raises(ModelError, match=r"broken\.xml"):
        robot.robot_spec()


@pytest.mark.parametrize("which", ["arm_model", "tool_model", "robot_model"])
def test_noisy_controls_one_second_without_warnings(which: str,
                                                    request: pytest.FixtureRequest) -> None:
    model: mujoco.MjModel = request.getfixturevalue(which)
    data = mujoco.MjData(model)
    if model.nkey:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    rng = np.random.default_rng(0)
    low, high = model.actuator_ctrlrange.T
    steps = round(1.0 / model.opt.timestep)
    for _ in range(steps):
        data.ctrl[:] = rng.uniform(low, high)
        mujoco.mj_step(model, data)
    counts = {mujoco.mjtWarning(i).name: data.warning[i].number
              for i in range(len(data.warning)) if data.warning[i].number}
    assert counts == {}
    assert np.all(np.isfinite(data.qpos))


# --- kinematics -----------------------------------------------------------------------------


def test_joints_match_the_notes_table(arm_model: mujoco.MjModel,
                                      robot_model: mujoco.MjModel) -> None:
    for i, (origin, axis, rng_, _) in enumerate(URDF_TABLE):
        joint = arm_model.joint(robot.ARM_JOINTS[i])
        body = arm_model.body(int(joint.bodyid[0]))
        np.testing.assert_allclose(body.pos, origin, atol=1e-12)
        np.testing.assert_allclose(body.quat, [1, 0, 0, 0], atol=1e-12)
        np.testing.assert_allclose(joint.axis, axis, atol=1e-12)
        np.testing.assert_array_equal(joint.range, rng_)
        composed = robot_model.joint(robot.ARM_JOINTS[i])
        np.testing.assert_allclose(composed.range, rng_, atol=MJCF_ROUNDING)
        actuator = robot_model.actuator(robot.ARM_ACTUATORS[i])
        assert actuator.trnid[0] == composed.id
        np.testing.assert_allclose(actuator.ctrlrange, rng_, atol=MJCF_ROUNDING)
    np.testing.assert_array_equal(robot.VELOCITY_LIMITS, [row[3] for row in URDF_TABLE])


def test_fk_at_zero_puts_flange_at_the_urdf_figure(robot_model: mujoco.MjModel) -> None:
    flange = site_pose(robot_model, np.zeros(6), robot.FLANGE_SITE)
    np.testing.assert_allclose(flange[:3, 3], FLANGE_AT_ZERO, atol=1e-12)
    np.testing.assert_allclose(flange[:3, :3], np.eye(3), atol=1e-12)


def test_tool_and_camera_geometry(robot_model: mujoco.MjModel) -> None:
    q = np.zeros(6)
    flange = site_pose(robot_model, q, robot.FLANGE_SITE)
    tip = np.linalg.inv(flange) @ site_pose(robot_model, q, robot.TOOL_SITE)
    cam_site = np.linalg.inv(flange) @ site_pose(robot_model, q, robot.CAMERA_SITE)
    # Tip on the approach axis (flange +z), 0.10-0.13 m out, same orientation.
    np.testing.assert_allclose(tip[:2, 3], 0.0, atol=1e-12)
    assert 0.10 <= tip[2, 3] <= 0.13
    np.testing.assert_allclose(tip[:3, :3], np.eye(3), atol=1e-12)
    # Camera looks along its -z = the approach axis, offset 5-7 cm sideways, behind the tip.
    np.testing.assert_allclose(-cam_site[:3, 2], [0.0, 0.0, 1.0], atol=1e-12)
    assert 0.05 <= np.hypot(cam_site[0, 3], cam_site[1, 3]) <= 0.07
    assert cam_site[2, 3] < tip[2, 3]
    # camera_site has exactly the camera's pose.
    data = mujoco.MjData(robot_model)
    mujoco.mj_forward(robot_model, data)
    cam = data.cam(robot.CAMERA)
    np.testing.assert_allclose(cam.xpos, data.site(robot.CAMERA_SITE).xpos, atol=1e-12)
    np.testing.assert_allclose(cam.xmat, data.site(robot.CAMERA_SITE).xmat, atol=1e-12)
    assert robot_model.camera(robot.CAMERA).fovy[0] == pytest.approx(45.0)


# --- IK -------------------------------------------------------------------------------------


def look_target(image_u: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = ik.look_rotation(image_u)
    out[:3, 3] = LOOK_POINT + np.array([0.0, 0.0, LOOK_HEIGHT])
    return out


@pytest.mark.parametrize("image_u", [(0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.3)])
def test_look_pose_reaches_the_camera_target(robot_model: mujoco.MjModel,
                                             image_u: tuple[float, float, float]) -> None:
    q = ik.look_pose_q(robot_model, LOOK_POINT, LOOK_HEIGHT, image_u)
    assert q.shape == (6,)
    pose = site_pose(robot_model, q, robot.CAMERA_SITE)
    target = look_target(image_u)
    assert np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= 1e-5
    assert rotation_angle(pose[:3, :3], target[:3, :3]) <= 1e-4
    # Optical axis (MuJoCo camera -z) straight down; image +u (camera x) horizontal.
    np.testing.assert_allclose(-pose[:3, 2], [0.0, 0.0, -1.0], atol=1e-4)
    u = np.array(image_u[:2]) / np.linalg.norm(image_u[:2])
    np.testing.assert_allclose(pose[:2, 0], u, atol=1e-4)


def test_home_keyframe_is_the_look_pose(robot_model: mujoco.MjModel,
                                        look_q: np.ndarray) -> None:
    key = robot_model.key(robot.HOME_KEY)
    np.testing.assert_allclose(key.ctrl[:6], key.qpos, atol=0.0)
    assert key.ctrl[6] == 0.0  # suction off
    pose = site_pose(robot_model, key.qpos, robot.CAMERA_SITE)
    target = look_target()
    assert np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= 1e-5
    assert rotation_angle(pose[:3, :3], target[:3, :3]) <= 1e-4
    np.testing.assert_allclose(key.qpos, look_q, atol=2e-5)


# Tool-down pick grid over the belt, within the arm's reach (see README "Reach"): the wrist
# centre is at most 0.605 m from the shoulder, so belt corners beyond ~0.58 m from the base
# axis are out of reach with a vertical tool.
PICK_GRID = [(x, y, z) for x in (0.33, 0.45, 0.54) for y in (-0.15, 0.0, 0.15)
             for z in (0.11, 0.20, 0.30)]
#: Smallest singular value of the 6x6 tool Jacobian ([m; rad] rows) accepted as "away from
#: singularities"; the grid's worst is ~0.07, the stretched-out boundary goes to 0.
MIN_SINGULAR_VALUE = 0.05


def test_ik_reaches_the_pick_grid(robot_model: mujoco.MjModel, look_q: np.ndarray) -> None:
    data = mujoco.MjData(robot_model)
    jac = np.zeros((6, robot_model.nv))
    low, high = robot_model.jnt_range.T
    for tip in PICK_GRID:
        target = ik.tool_down_pose(tip)
        q = ik.solve_ik(robot_model, look_q, robot.TOOL_SITE, "site", target)
        pose = site_pose(robot_model, q, robot.TOOL_SITE)
        assert np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= 1e-5, tip
        assert rotation_angle(pose[:3, :3], target[:3, :3]) <= 1e-4, tip
        assert np.all(q >= low) and np.all(q <= high), tip
        data.qpos[:] = q
        mujoco.mj_kinematics(robot_model, data)
        mujoco.mj_comPos(robot_model, data)
        mujoco.mj_jacSite(robot_model, data, jac[:3], jac[3:], robot_model.site(robot.TOOL_SITE).id)
        assert np.linalg.svd(jac, compute_uv=False)[-1] > MIN_SINGULAR_VALUE, tip


def test_ik_out_of_reach_raises_with_residual(robot_model: mujoco.MjModel,
                                              look_q: np.ndarray) -> None:
    with pytest.raises(IKError, match="residual"):
        ik.solve_ik(robot_model, look_q, robot.TOOL_SITE, "site",
                    ik.tool_down_pose((0.57, 0.30, 0.11)))


def test_ik_rejects_bad_inputs(robot_model: mujoco.MjModel) -> None:
    with pytest.raises(IKError, match="shape"):
        ik.solve_ik(robot_model, np.zeros(5), robot.TOOL_SITE, "site", np.eye(4))
    with pytest.raises(IKError, match="4, 4"):
        ik.solve_ik(robot_model, None, robot.TOOL_SITE, "site", np.eye(3))
    with pytest.raises(IKError, match="not a rotation"):
        ik.solve_ik(robot_model, None, robot.TOOL_SITE, "site", np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(IKError, match="no_such_site"):
        ik.solve_ik(robot_model, None, "no_such_site", "site", np.eye(4))
    with pytest.raises(IKError, match="horizontal"):
        ik.look_rotation((0.0, 0.0, 1.0))


def test_ik_in_a_model_with_free_bodies_leaves_them_alone() -> None:
    spec = robot.robot_spec()
    body = spec.worldbody.add_body(name="box", pos=[0.3, 0.3, 0.5])
    body.add_freejoint()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.02, 0.02])
    model = spec.compile()
    start = model.qpos0.copy()
    start[:6] = ik.LOOK_SEED_Q
    q = ik.solve_ik(model, start, robot.TOOL_SITE, "site", ik.tool_down_pose((0.45, 0.0, 0.2)))
    assert q.shape == (model.nq,)
    np.testing.assert_array_equal(q[6:], start[6:])
    np.testing.assert_array_equal(ik.arm_qpos_indices(model), np.arange(6))


# --- servo tracking -------------------------------------------------------------------------

#: Step size, rad: about one 33 ms camera tick at 0.6 rad/s, inside the linear (unsaturated)
#: range of every axis.
STEP_RAD = 0.02
#: 2 % settling-time bound, s. Design: critically damped at omega = 60 rad/s settles in
#: 5.83 / 60 = 0.097 s; axes whose inertia is below the design maximum are overdamped and
#: slower: measured 0.092-0.114 s at the look pose and across the pick grid. The bound is the
#: worst measured plus ~30 %.
SETTLE_BOUND_S = 0.15
#: Overshoot bound, fraction of the step: none by design (damping ratio >= 1); measured < 0.02 %.
OVERSHOOT_BOUND = 0.01


@pytest.mark.parametrize("joint", range(6))
def test_position_servo_settles_without_overshoot(robot_model: mujoco.MjModel,
                                                  look_q: np.ndarray, joint: int) -> None:
    model, data = robot_model, mujoco.MjData(robot_model)
    data.qpos[:6] = look_q
    data.ctrl[:6] = look_q
    data.ctrl[6] = 0.0
    data.ctrl[joint] += STEP_RAD
    steps = round(0.5 / model.opt.timestep)
    response = np.empty(steps)
    for i in range(steps):
        mujoco.mj_step(model, data)
        response[i] = (data.qpos[joint] - look_q[joint]) / STEP_RAD
    outside = np.flatnonzero(np.abs(response - 1.0) > 0.02)
    settle_s = (outside[-1] + 1) * model.opt.timestep if outside.size else 0.0
    assert settle_s <= SETTLE_BOUND_S
    assert response.max() - 1.0 <= OVERSHOOT_BOUND
    assert abs(response[-1] - 1.0) <= 0.002


# --- suction --------------------------------------------------------------------------------

HEAVY_MASS = 0.6  # kg, the heaviest cylinder of the project
CYL_HEIGHT = 0.06  # m
TABLE_TOP = 0.10  # m, like the belt top
#: Commanded lift acceleration, m/s^2: 10 % above the 3 m/s^2 requirement, so that the
#: cylinder's *measured* acceleration (behind the servo lag) still reaches 3 m/s^2.
LIFT_ACC_CMD = 3.3
LIFT_ACC_REQUIRED = 3.0
LIFT_ACC_TIME = 0.25  # s
IK_WAYPOINT_DT = 0.01  # s between IK waypoints of the lift
#: Held means the cup tip stays within this of the cylinder's top face, m.
HELD_GAP = 0.002


@dataclass
class PickOutcome:
    held: bool
    """Cylinder stayed on the cup through the lift."""
    rise_m: float
    """Cylinder rise during the lift, m."""
    sustained_acc: float
    """Largest mean upward acceleration of the cylinder over a 0.1 s window, m/s^2."""
    released: bool
    """Cylinder back on the table after suction off."""


def build_pick_scene(radius: float) -> tuple[mujoco.MjModel, int]:
    spec = robot.robot_spec()
    spec.worldbody.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_BOX,
                            size=[0.2, 0.2, TABLE_TOP / 2], pos=[0.45, 0.0, TABLE_TOP / 2])
    body = spec.worldbody.add_body(name="cyl", pos=[0.45, 0.0, TABLE_TOP + CYL_HEIGHT / 2])
    body.add_freejoint()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius, CYL_HEIGHT / 2, 0.0],
                  mass=HEAVY_MASS, friction=[0.8, 0.005, 0.0001], condim=4)
    model = spec.compile()
    return model, model.body("cyl").id


def run_pick(model: mujoco.MjModel, cyl: int, look_q: np.ndarray, gain_scale: float) -> PickOutcome:
    """Approach, press 1 mm, suck, lift at LIFT_ACC_CMD, release; real contact physics."""
    suction = model.actuator(robot.SUCTION_ACTUATOR).id
    nominal_gain = model.actuator_gainprm[suction, 0]
    model.actuator_gainprm[suction, 0] = nominal_gain * gain_scale
    try:
        data = mujoco.MjData(model)
        dt = model.opt.timestep
        tip_site = model.site(robot.TOOL_SITE).id
        top = TABLE_TOP + CYL_HEIGHT

        def arm_q(tip_z: float, start: np.ndarray) -> np.ndarray:
            target = ik.tool_down_pose((0.45, 0.0, tip_z))
            return ik.solve_ik(model, start, robot.TOOL_SITE, "site", target)[:6]

        def run(seconds: float,
                ctrl_at: Callable[[float], np.ndarray] | None = None) -> np.ndarray:
            log = []
            for i in range(round(seconds / dt)):
                if ctrl_at is not None:
                    data.ctrl[:6] = ctrl_at(i * dt)
                mujoco.mj_step(model, data)
                log.append((data.xpos[cyl, 2], data.site_xpos[tip_site, 2]))
            return np.array(log)

        q_above = arm_q(top + 0.03, look_q)
        q_press = arm_q(top - 0.001, q_above)
        data.qpos[:6] = data.ctrl[:6] = q_above
        mujoco.mj_forward(model, data)
        run(0.2)
        run(0.5, lambda t: q_above + (q_press - q_above) * min(1.0, t / 0.4))
        data.ctrl[suction] = 1.0
        run(0.2)
        # Lift: constant acceleration, then brake to rest over 0.15 s; IK waypoints every
        # 10 ms, linearly interpolated position targets in between.
        v_top = LIFT_ACC_CMD * LIFT_ACC_TIME
        z_acc_end = 0.5 * LIFT_ACC_CMD * LIFT_ACC_TIME**2

        def tip_z(t: float) -> float:
            if t <= LIFT_ACC_TIME:
                return top - 0.001 + 0.5 * LIFT_ACC_CMD * t**2
            s = min(t - LIFT_ACC_TIME, 0.15)
            return top - 0.001 + z_acc_end + v_top * s - 0.5 * (v_top / 0.15) * s**2

        times = np.arange(0.0, LIFT_ACC_TIME + 0.15 + 1e-9, IK_WAYPOINT_DT)
        waypoints = [q_press]
        for t in times[1:]:
            waypoints.append(arm_q(tip_z(t), waypoints[-1]))
        way = np.array(waypoints)

        def lift_ctrl(t: float) -> np.ndarray:
            k = min(t / IK_WAYPOINT_DT, len(way) - 1.0 - 1e-9)
            i = int(k)
            return way[i] + (way[i + 1] - way[i]) * (k - i)

        log = run(0.6, lift_ctrl)
        cyl_z, tip = log[:, 0], log[:, 1]
        gap = tip - (cyl_z + CYL_HEIGHT / 2)
        vel = np.gradient(cyl_z, dt)
        window = round(0.1 / dt)
        sustained = float(np.max((vel[window:] - vel[:-window]) / 0.1))
        held = bool(np.max(np.abs(gap)) <= HELD_GAP)
        data.ctrl[suction] = 0.0
        run(0.5)
        released = abs(data.xpos[cyl, 2] - (TABLE_TOP + CYL_HEIGHT / 2)) < 0.002
        return PickOutcome(held=held, rise_m=float(cyl_z[-1] - cyl_z[0]),
                           sustained_acc=sustained, released=released)
    finally:
        model.actuator_gainprm[suction, 0] = nominal_gain


@pytest.fixture(scope="module", params=[0.035, 0.025], ids=["r35mm", "r25mm"])
def pick_scene(request: pytest.FixtureRequest) -> tuple[mujoco.MjModel, int]:
    return build_pick_scene(request.param)


@pytest.mark.parametrize("gain_scale", [1.0, 0.5])
def test_suction_holds_heavy_cylinder_through_lift_and_releases(
        pick_scene: tuple[mujoco.MjModel, int], look_q: np.ndarray, gain_scale: float) -> None:
    # At half the suction force too: a safety factor of at least 2 on m (g + a).
    outcome = run_pick(*pick_scene, look_q, gain_scale)
    assert outcome.held
    assert outcome.sustained_acc >= LIFT_ACC_REQUIRED
    assert outcome.rise_m > 0.15
    assert outcome.released


def test_weak_suction_loses_the_cylinder(pick_scene: tuple[mujoco.MjModel, int],
                                         look_q: np.ndarray) -> None:
    # Negative control: 1/5 of the force (7 N) is below m (g + a) = 0.6 * 12.8 = 7.7 N, so the
    # pick test above is not passing for a reason other than the suction force.
    outcome = run_pick(*pick_scene, look_q, 0.2)
    assert not outcome.held

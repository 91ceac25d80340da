"""Eye-in-hand chain, servo law and mink execution on an inline 6-DOF arm (and the VS-060).

The inline arm copies the VS-060's joint table (Denso's vs060.urdf, see models/vs060) with a
wrist camera 60 mm beside the approach axis, looking along it.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from stackpick_sim.control.execution import JointVelocityExecutor
from stackpick_sim.control.eye_in_hand import EyeInHand
from stackpick_sim.control.interaction import (
    circle_pose_features,
    circle_pose_interaction,
    desired_circle_pose_features,
)
from stackpick_sim.control.servo import (
    AdaptiveGain,
    ServoConfig,
    damped_pinv,
    saturated_servo_velocity,
    servo_velocity,
    target_feature_rate,
)
from stackpick_sim.control.twist import invert_transform
from stackpick_sim.exceptions import ConfigError, ControlError
from stackpick_sim.geometry import CameraIntrinsics, project_circle

ARM_XML = """
<mujoco model="arm6">
  <compiler angle="radian" autolimits="true"/>
  <option integrator="implicitfast"/>
  <default>
    <geom type="capsule" size="0.03" contype="0" conaffinity="0" density="1000"/>
  </default>
  <worldbody>
    <body name="link1" pos="0 0 0.1815">
      <joint name="joint1" axis="0 0 1" range="-2.96706 2.96706"/>
      <geom fromto="0 0 0 0 0 0.1635"/>
      <body name="link2" pos="0 0 0.1635">
        <joint name="joint2" axis="0 1 0" range="-2.094395 2.094395"/>
        <geom fromto="0 0 0 0 0 0.305"/>
        <body name="link3" pos="0 0 0.305">
          <joint name="joint3" axis="0 1 0" range="-2.181662 2.70526"/>
          <geom fromto="0 0 0 -0.01 0 0.1645"/>
          <body name="link4" pos="-0.010 0 0.1645">
            <joint name="joint4" axis="0 0 1" range="-4.712389 4.712389"/>
            <geom fromto="0 0 0 0 0 0.1355"/>
            <body name="link5" pos="0 0 0.1355">
              <joint name="joint5" axis="0 1 0" range="-2.094395 2.094395"/>
              <geom fromto="0 0 0 0 0 0.07"/>
              <body name="link6" pos="0 0 0.070">
                <joint name="joint6" axis="0 0 1" range="-6.283185 6.283185"/>
                <geom fromto="0 0 0 0 0 0.1"/>
                <site name="attachment_site" pos="0 0 0.10"/>
                <camera name="wrist_cam" pos="0.06 0 0.03" quat="0 1 0 0" fovy="45"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
JOINTS = tuple(f"joint{i}" for i in range(1, 7))
#: rad/s, from Denso's vs060.urdf
SPEED_LIMITS = dict(zip(JOINTS, (3.927, 2.618, 2.858, 3.927, 3.022, 6.283), strict=True))
#: Tool pointing straight down at (0.427, -0.142, 0.22) m: joint 1 turned upstream by 0.32 rad
#: (found once with a mink FrameTask); the object starts up-belt of the tool.
LOOK_Q = np.array([-0.32, 0.7514, 1.487, 0.0, 0.9032, 0.0])
INTRINSICS = CameraIntrinsics.from_fovy(45.0, 320, 240)
RADIUS = 0.03  # m, top-face radius
STANDOFF = 0.10  # m, tool point to face centre at the servo goal
CAMERA_DT = 1.0 / 30.0  # s, one servo step per camera frame
FD_STEP = 1e-6  # rad
FD_TOL = 1e-7  # analytic vs FD agree to ~5e-10 (max |J| ~ 3)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(ARM_XML)


@pytest.fixture(scope="module")
def arm(model: mujoco.MjModel) -> EyeInHand:
    return EyeInHand(model, site="attachment_site", camera="wrist_cam", joints=JOINTS)


def _face_in_cam(arm: EyeInHand, data: mujoco.MjData, centre_w: np.ndarray,
                 normal_w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre_cam, normal_cam, cam_R_world) of a world face seen from the current camera."""
    cam_T_world = invert_transform(arm.world_T_cam(data))
    r = cam_T_world[:3, :3]
    return r @ centre_w + cam_T_world[:3, 3], r @ normal_w, r


def _chain_fd_error(arm: EyeInHand, data: mujoco.MjData, q: np.ndarray) -> float:
    centre_w = np.array([0.47, -0.12, 0.0])
    normal_w = np.array([0.1, 0.2, -1.0]) / np.linalg.norm([0.1, 0.2, -1.0])

    def features(qq: np.ndarray) -> np.ndarray:
        arm.forward(data, qq)
        c, n, _ = _face_in_cam(arm, data, centre_w, normal_w)
        return circle_pose_features(c, n)

    arm.forward(data, q)
    c, n, _ = _face_in_cam(arm, data, centre_w, normal_w)
    analytic = arm.image_jacobian(circle_pose_interaction(c, n), data)
    fd = np.zeros_like(analytic)
    for j in range(len(q)):
        dq = np.zeros(len(q))
        dq[j] = FD_STEP
        fd[:, j] = (features(q + dq) - features(q - dq)) / (2 * FD_STEP)
    return float(np.abs(fd - analytic).max())


@pytest.mark.parametrize("offset", [0.0, 0.05, -0.1])
def test_image_jacobian_chain_matches_finite_differences(model, arm, offset: float) -> None:
    assert _chain_fd_error(arm, mujoco.MjData(model), LOOK_Q + offset) < FD_TOL


def test_ee_jacobian_is_site_frame_twist(model, arm) -> None:
    data = mujoco.MjData(model)
    q = LOOK_Q + 0.03
    arm.forward(data, q)
    e_j_e = arm.ee_jacobian(data)
    world_T_ee = arm.world_T_ee(data)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = FD_STEP
        arm.forward(data, q + dq)
        plus = arm.world_T_ee(data)
        arm.forward(data, q - dq)
        minus = arm.world_T_ee(data)
        delta = invert_transform(world_T_ee) @ (plus - minus) / (2 * FD_STEP)  # e_T_e' rate
        twist = np.r_[delta[:3, 3], delta[2, 1], delta[0, 2], delta[1, 0]]
        assert np.allclose(twist, e_j_e[:, j], atol=FD_TOL)


def test_unknown_names_are_listed(model) -> None:
    with pytest.raises(ControlError, match="unknown camera 'nope'; the model has: wrist_cam"):
        EyeInHand(model, site="attachment_site", camera="nope", joints=JOINTS)


def test_damped_pinv_is_eq17_when_regular_and_bounded_when_singular() -> None:
    rng = np.random.default_rng(3)
    j = rng.normal(size=(5, 6))
    assert np.allclose(damped_pinv(j), np.linalg.pinv(j), atol=1e-12)
    singular = j.copy()
    singular[4] = singular[3]  # rank 4
    singular[4, 0] += 1e-9
    gain = np.linalg.norm(damped_pinv(singular, threshold=0.02, max_damping=0.02), 2)
    assert gain <= 1.0 / (2 * 0.02) + 1e-9  # max of s / (s^2 + rho^2) is 1 / (2 rho)


def test_adaptive_gain_limits() -> None:
    gain = AdaptiveGain(at_zero=4.0, at_infinity=0.4, slope_at_zero=30.0)  # ViSP's tutorial
    assert gain(0.0) == pytest.approx(4.0)
    assert gain(1e3) == pytest.approx(0.4)
    eps = 1e-7
    assert (gain(eps) - gain(0.0)) / eps == pytest.approx(-30.0, rel=1e-4)
    with pytest.raises(ConfigError, match="0 < at_infinity <= at_zero"):
        AdaptiveGain(at_zero=1.0, at_infinity=2.0)


def test_executor_passes_feasible_velocity_and_enforces_limits(model, arm) -> None:
    ex = JointVelocityExecutor(model, arm, SPEED_LIMITS)
    qpos = np.zeros(model.nq)
    qpos[arm.qpos_indices] = LOOK_Q
    qd = np.array([0.2, -0.1, 0.3, 0.0, -0.2, 0.5])
    assert np.allclose(ex.feasible_velocity(qpos, qd, CAMERA_DT), qd, atol=1e-6)
    # Too fast: scaled uniformly (direction kept) to the tightest speed limit.
    fast = qd * 30.0
    out = ex.feasible_velocity(qpos, fast, CAMERA_DT)
    limits = np.array(list(SPEED_LIMITS.values()))
    assert np.max(np.abs(out) / limits) == pytest.approx(1.0, abs=1e-6)
    assert np.allclose(out / np.linalg.norm(out), fast / np.linalg.norm(fast), atol=1e-6)
    # Near the joint-3 upper limit the QP stops the joint short of it.
    qpos[arm.qpos_indices[2]] = 2.70526 - 0.01
    out = ex.feasible_velocity(qpos, np.array([0, 0, 2.0, 0, 0, 0]), CAMERA_DT)
    assert qpos[arm.qpos_indices[2]] + out[2] * CAMERA_DT <= 2.70526
    with pytest.raises(ControlError, match="non-arm joints"):
        JointVelocityExecutor(model, arm, {"elbow": 1.0})


def _servo_run(model, arm, *, speed: float, feed_forward: bool, duration: float,
               look_q: np.ndarray = LOOK_Q) -> np.ndarray:
    """Kinematic servo loop; rows (t, lateral mm, depth mm, tilt deg, centre px, u, v)."""
    data = mujoco.MjData(model)
    arm.forward(data, look_q)
    cam_T_tool = invert_transform(arm.world_T_cam(data)) @ arm.world_T_ee(data)
    s_star = desired_circle_pose_features(cam_T_tool, STANDOFF)
    tool0 = arm.world_T_ee(data)[:3, 3]
    # Face centre 40 mm across (towards the image centre) and 30 mm up-belt of the tool, on
    # the plane z = 0.1 m,
    # tilted 15 deg about x (the top cylinder leans on the one below).
    centre0 = np.array([tool0[0] - 0.04, tool0[1] - 0.03, 0.1])
    tilt = np.radians(15.0)
    normal_w = np.array([0.0, np.sin(tilt), -np.cos(tilt)])  # inward: into the object
    belt_v = np.array([0.0, speed, 0.0])
    ex = JointVelocityExecutor(model, arm, SPEED_LIMITS)
    config = ServoConfig(feed_forward=feed_forward)
    qpos = data.qpos.copy()
    rows = []
    for k in range(round(duration / CAMERA_DT)):
        t = k * CAMERA_DT
        centre_w = centre0 + belt_v * t
        arm.forward(data, qpos[arm.qpos_indices])
        c, n, cam_R_world = _face_in_cam(arm, data, centre_w, normal_w)
        ellipse = project_circle(c, n, RADIUS, INTRINSICS)  # raises if behind the camera
        error = circle_pose_features(c, n) - s_star
        interaction = circle_pose_interaction(c, n)
        qd = servo_velocity(arm.image_jacobian(interaction, data), error, config,
                            target_feature_rate(interaction, cam_R_world, belt_v))
        ee = arm.world_T_ee(data)
        face_in_tool = invert_transform(ee) @ np.r_[centre_w, 1.0]
        tilt_err = np.degrees(np.arccos(np.clip(ee[:3, 2] @ normal_w, -1.0, 1.0)))
        rows.append((t, 1e3 * np.linalg.norm(face_in_tool[:2]),
                     1e3 * (face_in_tool[2] - STANDOFF), tilt_err,
                     INTRINSICS.fx * np.abs(error[:2]).max(), ellipse.cx, ellipse.cy))
        qpos = ex.step(qpos, qd, CAMERA_DT)
    return np.array(rows)


def _converged(rows: np.ndarray) -> np.ndarray:
    """Goal reached: face centre < 1 mm off the tool axis, standoff within 1 mm, tilt < 0.5 deg."""
    return (rows[:, 1] < 1.0) & (np.abs(rows[:, 2]) < 1.0) & (rows[:, 3] < 0.5)


# Convergence budget: the 2.5 s pick cycle leaves ~1 s for the final servo.
CONVERGE_BY_S = 1.0


@pytest.mark.parametrize("speed", [0.1, 0.3])
def test_servo_converges_on_moving_belt(model, arm, speed: float) -> None:
    rows = _servo_run(model, arm, speed=speed, feed_forward=True, duration=1.3)
    ok = _converged(rows)
    first = int(np.argmax(ok))
    assert ok[first] and rows[first, 0] <= CONVERGE_BY_S
    assert ok[first:].all()  # and stays converged while tracking
    assert (rows[:, 5] >= 0).all() and (rows[:, 5] <= 319).all()  # centre stays in view
    assert (rows[:, 6] >= 0).all() and (rows[:, 6] <= 239).all()


@pytest.mark.parametrize("speed", [0.1, 0.3])
def test_feed_forward_removes_tracking_lag(model, arm, speed: float) -> None:
    with_ff = _servo_run(model, arm, speed=speed, feed_forward=True, duration=1.2)
    without = _servo_run(model, arm, speed=speed, feed_forward=False, duration=1.2)
    tail = slice(-6, None)  # the last 0.2 s, after the transient
    lag_ff, lag_no = with_ff[tail, 1].mean(), without[tail, 1].mean()
    # Without feed-forward a first-order loop lags v / lambda behind (>= 7 mm at lambda <= 10
    # 1/s and 0.1 m/s); with it the residual is the discretisation error (< 1 mm).
    assert lag_no >= 1e3 * speed / ServoConfig().gain.at_zero * 0.7
    assert lag_ff < 1.0
    assert lag_ff < 0.1 * lag_no


def test_vs060_chain_matches_finite_differences() -> None:
    from stackpick_sim.sim import robot

    vs060 = robot.robot_spec().compile()
    vs_arm = EyeInHand(vs060, site=robot.TOOL_SITE, camera=robot.CAMERA, joints=robot.ARM_JOINTS)
    data = mujoco.MjData(vs060)
    assert _chain_fd_error(vs_arm, data, LOOK_Q) < FD_TOL
    # The wrist camera looks along the approach axis (paper, sec. 4): optical z || tool z.
    assert vs_arm.cam_T_ee(data)[:3, 2] @ np.array([0.0, 0.0, 1.0]) > 0.999


def test_saturated_servo_keeps_the_face_centre_and_cuts_the_turn_first() -> None:
    # A wrist near its singularity: the normal's rows ask one joint for far more than its
    # speed limit. Scaling the whole law would slow the centre's rows with it; the
    # saturated law keeps them exact and takes what the limits leave for the normal.
    rng = np.random.default_rng(5)
    j = rng.normal(size=(5, 6))
    j[3:] *= 0.02  # the normal's rows nearly singular: a turn costs fast joints
    e = rng.normal(size=5) * 0.1
    cfg = ServoConfig()
    free = servo_velocity(j, e, cfg)
    limit = np.full(6, 0.5 * np.max(np.abs(free)))
    q = saturated_servo_velocity(j, e, cfg, limit)
    assert np.all(np.abs(q) <= limit + 1e-12)
    lam = cfg.gain(float(np.max(np.abs(e))))
    assert np.allclose(j[:3] @ q, -lam * e[:3], atol=1e-9)  # the centre's rows exact
    scaled = free / np.max(np.abs(free) / limit)
    assert np.linalg.norm(j[:3] @ scaled + lam * e[:3]) > 0.1 * np.linalg.norm(lam * e[:3])
    # Some joint is at its limit: the normal got the largest share the limits allow.
    assert np.isclose(np.max(np.abs(q) / limit), 1.0)
    # Within the limits (and undamped) the two tasks are both met.
    undamped = ServoConfig(damping_threshold=1e-9, max_damping=0.0)
    q_free = saturated_servo_velocity(j, e, undamped, np.full(6, 1e6))
    assert np.allclose(j @ q_free, -lam * e, atol=1e-9)
    # A primary task beyond the limits on its own is scaled as a whole.
    tiny = saturated_servo_velocity(j, e, cfg, np.full(6, 1e-6))
    assert np.isclose(np.max(np.abs(tiny)), 1e-6)
    assert np.allclose(np.cross(j[:3] @ tiny, -lam * e[:3]), 0.0, atol=1e-15)
    with pytest.raises(ControlError, match="disagree"):
        saturated_servo_velocity(j, e, cfg, np.ones(5))

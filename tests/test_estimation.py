"""Back-projection and the constant-velocity Kalman tracker (belt and image frames)."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.control.twist import make_transform
from stackpick_sim.estimation.backproject import (
    backproject_at_depth,
    backproject_to_plane,
    plane_backprojection_jacobian,
    project_to_pixels,
    transfer_via_plane,
)
from stackpick_sim.estimation.kalman import (
    PRIOR_RESTART,
    ConstantVelocityTracker,
    TrackerConfig,
    belt_accel_psd,
    relaxed_transition,
    transition,
)
from stackpick_sim.exceptions import ConfigError, EstimationError
from stackpick_sim.geometry import CameraIntrinsics

INTRINSICS = CameraIntrinsics.from_fovy(45.0, 320, 240)
BELT_Z = 0.1  # m, plane of the tracked face centres
CAMERA_HEIGHT = 0.4  # m, camera above the world origin -> depth 0.3 m to the plane
DOWN = np.diag([1.0, -1.0, -1.0])  # camera looking down: x along world x, y along world -y
FRAME_DT = 1.0 / 30.0  # s
JITTER = 0.003  # s, +- uniform frame-time jitter
PIXEL_STD = 0.5  # px
BELT_SPEED = 0.2  # m/s along world +y


def _camera(t: float, moving: bool) -> np.ndarray:
    """world_T_cam: still, or swaying like a servoing wrist (0.1 m/s, 1.5 Hz, both axes)."""
    offset = np.zeros(3)
    if moving:
        w = 2 * np.pi * 1.5
        offset[:2] = 0.1 / w * (1.0 - np.cos(w * t)), 0.1 / w * np.sin(w * t)
    return make_transform(DOWN, np.array([0.0, 0.0, CAMERA_HEIGHT]) + offset)


def test_backprojection_round_trips_and_jacobian_matches_fd() -> None:
    rng = np.random.default_rng(0)
    world_T_cam = make_transform(DOWN @ make_transform(np.eye(3), [0, 0, 0])[:3, :3],
                                 [0.02, -0.03, CAMERA_HEIGHT])
    pixels = rng.uniform([0, 0], [319, 239], size=(20, 2))
    points = backproject_to_plane(pixels, INTRINSICS, world_T_cam, [0, 0, BELT_Z])
    assert np.allclose(points[:, 2], BELT_Z)
    assert np.allclose(project_to_pixels(points, INTRINSICS, world_T_cam), pixels, atol=1e-9)
    at_depth = backproject_at_depth(pixels, INTRINSICS, world_T_cam, CAMERA_HEIGHT - BELT_Z)
    assert np.allclose(at_depth, points, atol=1e-12)
    # Oblique view: tilt the camera 20 deg; analytic d(point)/d(pixel) vs central FD.
    c, s = np.cos(0.35), np.sin(0.35)
    tilted = make_transform(DOWN @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                            [0.0, 0.0, CAMERA_HEIGHT])
    px = np.array([100.0, 150.0])
    g = plane_backprojection_jacobian(px, INTRINSICS, tilted, [0, 0, BELT_Z])
    h = 1e-4
    fd = np.column_stack([
        (backproject_to_plane(px + d, INTRINSICS, tilted, [0, 0, BELT_Z])[0]
         - backproject_to_plane(px - d, INTRINSICS, tilted, [0, 0, BELT_Z])[0]) / (2 * h)
        for d in (np.array([h, 0.0]), np.array([0.0, h]))])
    assert np.abs(fd - g).max() < 1e-9  # m/px; entries ~1e-3


def test_backprojection_rejects_impossible_geometry() -> None:
    with pytest.raises(EstimationError, match="behind the camera"):
        backproject_to_plane(np.array([[160.0, 120.0]]), INTRINSICS, _camera(0, False),
                             [0, 0, CAMERA_HEIGHT + 0.1])
    with pytest.raises(EstimationError, match="grazes the plane"):
        backproject_to_plane(np.array([[160.0, 120.0]]), INTRINSICS, _camera(0, False),
                             [0, 0, BELT_Z], plane_normal=np.array([1.0, 0.0, 0.0]))


def _track(rng: np.random.Generator, *, moving: bool, frames: int,
           trackers: list[tuple[str, ConstantVelocityTracker]]) -> float:
    """Feed ``frames`` noisy, jittered detections of a belt object; return the last time."""
    start = np.array([0.01, -0.04, BELT_Z])
    t = 0.0
    for _ in range(frames):
        t += FRAME_DT + rng.uniform(-JITTER, JITTER)
        world_T_cam = _camera(t, moving)
        truth = start + np.array([0.0, BELT_SPEED, 0.0]) * t
        pixel = project_to_pixels(truth, INTRINSICS, world_T_cam)[0]
        pixel = pixel + rng.normal(0.0, PIXEL_STD, 2)
        for frame, tracker in trackers:
            if frame == "belt":
                z = backproject_to_plane(pixel, INTRINSICS, world_T_cam, [0, 0, BELT_Z])[0, :2]
            else:
                z = pixel
            tracker.update(t, z)
    return t


def _truth(t: float) -> np.ndarray:
    return np.array([0.01, -0.04 + BELT_SPEED * t, BELT_Z])


BELT_CONFIG = TrackerConfig.belt(depth=CAMERA_HEIGHT - BELT_Z, focal_px=INTRINSICS.fx,
                                 pixel_std=PIXEL_STD)
HORIZON = 0.3  # s from the last frame to the pick


def test_belt_prediction_error_matches_noise_bound() -> None:
    """On an exactly constant-velocity track (q = 0, the model matches the truth) the RMS
    pick-time error over seeds equals the filter's predicted std within sampling error, and
    that std is the least-squares line-fit bound sigma*sqrt(1/N + (t*-tbar)^2/Sxx)."""
    runs, frames = 300, 15
    exact = TrackerConfig.belt(depth=CAMERA_HEIGHT - BELT_Z, focal_px=INTRINSICS.fx,
                               pixel_std=PIXEL_STD, accel_psd=0.0)
    errors, predicted_var, default_errors = [], [], []
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        tracker = ConstantVelocityTracker(exact)
        default = ConstantVelocityTracker(BELT_CONFIG)
        t_last = _track(rng, moving=False, frames=frames,
                        trackers=[("belt", tracker), ("belt", default)])
        pred = tracker.predict_at(t_last + HORIZON)
        errors.append(pred.position - _truth(t_last + HORIZON)[:2])
        predicted_var.append(np.diag(pred.covariance)[:2])
        default_errors.append(default.predict_at(t_last + HORIZON).position
                              - _truth(t_last + HORIZON)[:2])
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    predicted = np.sqrt(np.mean(predicted_var, axis=0))
    # 600 squared errors: the RMS estimate has ~3 % std; +-15 % is 5 sigma.
    assert np.all(np.abs(rms / predicted - 1.0) < 0.15)
    times = np.arange(1, frames + 1) * FRAME_DT
    sigma = BELT_CONFIG.measurement_std
    ls_bound = sigma * np.sqrt(1 / frames + (times[-1] + HORIZON - times.mean()) ** 2
                               / np.sum((times - times.mean()) ** 2))
    # Frame-time jitter (+-3 ms) moves Sxx by ~1 %; 5 % covers it.
    assert np.all(np.abs(predicted / ls_bound - 1.0) < 0.05)
    # With the default belt-jitter q the filter trusts old frames less: still < 1 mm (target).
    assert np.median(np.linalg.norm(default_errors, axis=1)) < 1e-3


def test_belt_frame_beats_image_frame_when_camera_moves() -> None:
    """Paper Fig. 9: image motion = belt + camera. Tracking in the belt plane removes the
    camera part; the image-frame filter, even at its best process noise, cannot."""
    runs, frames = 40, 15
    image_psds = [1e2, 1e3, 1e4, 1e5, 1e6]  # px^2/s^3, swept to give the image filter its best
    belt_err: list[float] = []
    image_err: dict[float, list[float]] = {q: [] for q in image_psds}
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        trackers = {"belt": ConstantVelocityTracker(BELT_CONFIG)}
        images = {q: ConstantVelocityTracker(TrackerConfig.image(accel_psd=q,
                                                                  pixel_std=PIXEL_STD))
                  for q in image_psds}
        t_last = _track(rng, moving=True, frames=frames,  # one detection stream for all
                        trackers=[*trackers.items(), *(("image", f) for f in images.values())])
        t_pick = t_last + HORIZON
        cam = _camera(t_pick, moving=True)  # planned camera pose at the pick
        truth_px = project_to_pixels(_truth(t_pick), INTRINSICS, cam)[0]
        belt_xy = trackers["belt"].predict_at(t_pick).position
        belt_px = project_to_pixels(np.r_[belt_xy, BELT_Z], INTRINSICS, cam)[0]
        belt_err.append(float(np.linalg.norm(belt_px - truth_px)))
        for q, tracker in images.items():
            image_err[q].append(float(np.linalg.norm(tracker.predict_at(t_pick).position
                                                     - truth_px)))
    best_image = min(float(np.median(v)) for v in image_err.values())
    assert np.median(belt_err) < 1.0  # the < 1 px prediction target
    assert np.median(belt_err) < 0.2 * best_image


def test_gate_rejects_outlier_and_counts_to_lost_track() -> None:
    rng = np.random.default_rng(5)
    tracker = ConstantVelocityTracker(BELT_CONFIG)
    t = _track(rng, moving=False, frames=10, trackers=[("belt", tracker)])
    before = tracker.predict_at(t + FRAME_DT)
    wild = _truth(t + FRAME_DT)[:2] + np.array([0.05, 0.0])  # 50 mm off: a wrong ellipse
    result = tracker.update(t + FRAME_DT, wild)
    assert not result and result.reason.startswith("gated")
    assert result.mahalanobis_sq > BELT_CONFIG.gate_chi2
    assert np.allclose(tracker.predict_at(t + FRAME_DT).position, before.position)
    assert not tracker.lost_track
    for k in range(2, BELT_CONFIG.max_consecutive_rejections + 1):
        assert not tracker.update(t + k * FRAME_DT, wild)
    assert tracker.lost_track
    good = tracker.update(t + 6 * FRAME_DT, tracker.predict_at(t + 6 * FRAME_DT).position)
    assert good and not tracker.lost_track


def test_predict_at_does_not_mutate_and_stale_frames_are_dropped() -> None:
    tracker = ConstantVelocityTracker(BELT_CONFIG)
    with pytest.raises(EstimationError, match="initialised"):
        tracker.predict_at(1.0)
    first = tracker.update(0.0, [0.0, 0.0])
    assert not first and "first measurement" in first.reason
    assert tracker.update(FRAME_DT, [0.0, BELT_SPEED * FRAME_DT])
    # The paper's initial state: position of the newest, speed from the pair.
    assert np.allclose(tracker.predict_at(FRAME_DT).velocity, [0.0, BELT_SPEED])
    state = tracker.predict_at(0.5)
    tracker.predict_at(2.0)
    assert np.allclose(tracker.predict_at(0.5).position, state.position)
    assert np.allclose(state.position, [0.0, BELT_SPEED * 0.5])  # Eq. 4
    stale = tracker.update(0.0, [0.0, 0.0])
    assert not stale and stale.reason.startswith("stale")


def test_wild_initial_pair_restarts_initialisation() -> None:
    tracker = ConstantVelocityTracker(BELT_CONFIG)
    tracker.update(0.0, [0.5, 0.5])  # a spurious first detection half a metre away
    restart = tracker.update(FRAME_DT, [0.0, 0.0])
    assert not restart and "max_speed" in restart.reason
    assert tracker.update(2 * FRAME_DT, [0.0, BELT_SPEED * FRAME_DT])
    assert tracker.initialised


def test_config_validation_and_noise_conversion() -> None:
    assert belt_accel_psd(0.005, 0.5) == pytest.approx(1e-4)  # 2 sigma^2 / tau, m^2/s^3
    assert BELT_CONFIG.measurement_std == pytest.approx(PIXEL_STD * 0.3 / INTRINSICS.fx)
    with pytest.raises(ConfigError, match="unknown tracker frame 'world'; known: belt, image"):
        TrackerConfig(frame="world", accel_psd=1.0, measurement_std=1.0,  # type: ignore[arg-type]
                      max_speed=1.0)


def test_restart_takes_the_new_motion_from_two_measurements() -> None:
    tracker = ConstantVelocityTracker(BELT_CONFIG)
    tracker.update(0.0, [0.0, 0.0])
    tracker.update(FRAME_DT, [0.0, BELT_SPEED * FRAME_DT])
    for _ in range(3):  # a run of gated-out measurements bumps the rejection count
        tracker.update(2 * FRAME_DT, [0.02, 0.0])
    assert tracker.consecutive_rejections > 0
    # The object shifted: it now moves at 1.2 x the belt speed from x = 2 mm.
    z0, z1 = np.array([0.002, 0.010]), np.array([0.002, 0.010 + 1.2 * BELT_SPEED * FRAME_DT])
    r = np.eye(2) * 1e-8
    result = tracker.restart(3 * FRAME_DT, z0, r, 4 * FRAME_DT, z1, r)
    assert result and tracker.initialised and tracker.consecutive_rejections == 0
    pred = tracker.predict_at(5 * FRAME_DT)
    assert np.allclose(pred.velocity, [0.0, 1.2 * BELT_SPEED])
    assert np.allclose(pred.position, z1 + np.array([0.0, 1.2 * BELT_SPEED * FRAME_DT]))


def test_plane_transfer_matches_projection_and_fd_jacobian() -> None:
    c, s = np.cos(0.3), np.sin(0.3)
    a = _camera(0.1, moving=True)
    b = make_transform(DOWN @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                       [0.03, 0.02, CAMERA_HEIGHT - 0.1])
    px = np.array([120.0, 90.0])
    moved, jac = transfer_via_plane(px, INTRINSICS, a, b, [0, 0, BELT_Z])
    point = backproject_to_plane(px, INTRINSICS, a, [0, 0, BELT_Z])
    assert np.allclose(moved, project_to_pixels(point, INTRINSICS, b)[0], atol=1e-9)
    h = 1e-4
    fd = np.column_stack([
        (transfer_via_plane(px + d, INTRINSICS, a, b, [0, 0, BELT_Z])[0]
         - transfer_via_plane(px - d, INTRINSICS, a, b, [0, 0, BELT_Z])[0]) / (2 * h)
        for d in (np.array([h, 0.0]), np.array([0.0, h]))])
    assert np.abs(fd - jac).max() < 1e-6  # px/px; entries ~1
    with pytest.raises(EstimationError, match="behind"):
        transfer_via_plane(px, INTRINSICS, a, make_transform(DOWN, [0, 0, BELT_Z - 0.1]),
                           [0, 0, BELT_Z])


def test_image_frame_with_camera_motion_carried_through_the_plane_matches_belt() -> None:
    """The image-frame filter whose state is carried into each new view's image (transform)
    predicts as well as the belt frame; uncompensated it gates out a swaying camera."""
    runs, frames = 40, 15
    q_px = BELT_CONFIG.accel_psd * (INTRINSICS.fx / (CAMERA_HEIGHT - BELT_Z)) ** 2
    belt_err, image_err, plain_rejections = [], [], 0
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        belt = ConstantVelocityTracker(BELT_CONFIG)
        image = ConstantVelocityTracker(TrackerConfig.image(accel_psd=q_px, pixel_std=PIXEL_STD))
        plain = ConstantVelocityTracker(TrackerConfig.image(accel_psd=q_px, pixel_std=PIXEL_STD))
        ref = None
        t = 0.0
        for _ in range(frames):
            t += FRAME_DT + rng.uniform(-JITTER, JITTER)
            cam = _camera(t, moving=True)
            pixel = project_to_pixels(_truth(t), INTRINSICS, cam)[0] + rng.normal(0, PIXEL_STD, 2)
            belt.update(t, backproject_to_plane(pixel, INTRINSICS, cam, [0, 0, BELT_Z])[0, :2])
            if image.initialised and ref is not None:
                assert image.advance(t)
                moved, jac = transfer_via_plane(image.predict_at(t).position, INTRINSICS, ref,
                                                cam, [0, 0, BELT_Z])
                image.transform(moved, jac)
            if image.initialised or ref is None or np.allclose(ref, cam):
                image.update(t, pixel)
            else:  # the two-point start differences pixels of one view
                prev = project_to_pixels(_truth(t - FRAME_DT), INTRINSICS, cam)[0]
                image.restart(t - FRAME_DT, prev, np.eye(2) * PIXEL_STD**2, t, pixel,
                              np.eye(2) * PIXEL_STD**2)
            ref = cam
            plain_rejections += not plain.update(t, pixel).accepted
        t_pick = t + HORIZON
        cam = _camera(t, moving=True)  # the filter's pixels are those of the last view
        truth_px = project_to_pixels(_truth(t_pick), INTRINSICS, cam)[0]
        belt_px = project_to_pixels(np.r_[belt.predict_at(t_pick).position, BELT_Z],
                                    INTRINSICS, cam)[0]
        belt_err.append(float(np.linalg.norm(belt_px - truth_px)))
        image_err.append(float(np.linalg.norm(image.predict_at(t_pick).position - truth_px)))
    assert np.median(image_err) < 1.0  # the < 1 px prediction target
    assert np.median(image_err) < 1.5 * np.median(belt_err)
    assert plain_rejections > runs * (frames - 2) / 2  # most of the uncompensated ones


def test_transform_carries_velocity_and_covariance_through_the_jacobian() -> None:
    tracker = ConstantVelocityTracker(TrackerConfig.image(accel_psd=1.0, pixel_std=PIXEL_STD))
    with pytest.raises(EstimationError, match="initialised"):
        tracker.transform(np.zeros(2), np.eye(2))
    tracker.update(0.0, np.array([10.0, 20.0]))
    tracker.update(0.1, np.array([11.0, 22.0]))
    before = tracker.predict_at(0.1)
    jac = np.array([[2.0, 0.5], [0.0, 1.5]])
    tracker.transform(np.array([50.0, 60.0]), jac)
    after = tracker.predict_at(0.1)
    assert np.allclose(after.position, [50.0, 60.0])
    assert np.allclose(after.velocity, jac @ before.velocity)
    assert np.allclose(after.covariance[:2, :2], jac @ before.covariance[:2, :2] @ jac.T)
    assert not tracker.advance(0.05)  # older than the state
    assert tracker.advance(0.2) and tracker.time == 0.2


def _prior_config() -> TrackerConfig:
    return TrackerConfig.belt(depth=CAMERA_HEIGHT - BELT_Z, focal_px=INTRINSICS.fx,
                              pixel_std=PIXEL_STD, prior_velocity=(0.0, BELT_SPEED),
                              prior_velocity_std=0.01)


def test_belt_velocity_prior_tempers_a_noisy_two_point_start() -> None:
    """Two detections a frame apart 1.5 mm off each other across the belt imply a velocity
    45 mm/s off, inside the pair's own uncertainty (~22 mm/s) and the prior's: the belt's
    known speed pulls the start's velocity back, weighted by the two covariances."""
    belt_v = (0.0, BELT_SPEED)
    cfg = _prior_config()
    z0 = np.array([0.01, 0.0])
    z1 = z0 + np.array([0.0015, BELT_SPEED * FRAME_DT])
    plain, prior = ConstantVelocityTracker(BELT_CONFIG), ConstantVelocityTracker(cfg)
    for tracker in (plain, prior):
        tracker.update(0.0, z0)
        assert tracker.update(FRAME_DT, z1)
    v_plain = plain.predict_at(FRAME_DT).velocity
    v_prior = prior.predict_at(FRAME_DT).velocity
    assert v_plain[0] == pytest.approx(0.0015 / FRAME_DT)
    # Two-point std sqrt(2) sigma / dt (~15 mm/s here) against the prior's 10 mm/s.
    two_point_var = 2 * BELT_CONFIG.measurement_std**2 / FRAME_DT**2
    expected = v_plain[0] * 0.01**2 / (0.01**2 + two_point_var)
    assert v_prior[0] == pytest.approx(expected, rel=1e-6)
    assert abs(v_prior[0]) < 0.5 * abs(v_plain[0])
    assert v_prior[1] == pytest.approx(BELT_SPEED, abs=1e-9)
    # The prior also tightens the velocity covariance, never the other way.
    assert np.all(np.diag(prior.predict_at(FRAME_DT).covariance)[2:]
                  < np.diag(plain.predict_at(FRAME_DT).covariance)[2:])
    # A restart (a changed motion, seen in three consistent detections) is a two-point start
    # too: the prior weighs in against its own, here tighter, two-point covariance.
    prior.restart(0.0, z0, np.eye(2) * 1e-8, FRAME_DT, z1, np.eye(2) * 1e-8)
    tight_var = 2e-8 / FRAME_DT**2
    assert prior.predict_at(FRAME_DT).velocity[0] == pytest.approx(
        v_plain[0] * 0.01**2 / (0.01**2 + tight_var), rel=1e-6)
    with pytest.raises(ConfigError):
        TrackerConfig.belt(depth=0.2, focal_px=290.0, prior_velocity=belt_v,
                           prior_velocity_std=0.0)


@pytest.mark.parametrize("wrong", [0, 1])
def test_a_first_pair_off_the_belt_prior_is_not_a_start(wrong: int) -> None:
    """Two different ellipses of one face in the first two frames (a full-face fit and a
    partial one, 4 mm apart across the belt, paper seed 45) imply a velocity 120 mm/s off
    the belt's, beyond the gate: the pair is refused whichever of the two is wrong, and the
    filter starts from the first consistent pair, on the face's path at the belt's speed."""
    tracker = ConstantVelocityTracker(_prior_config())
    truth = [np.array([0.01, BELT_SPEED * i * FRAME_DT]) for i in range(4)]
    zs = [z.copy() for z in truth]
    zs[wrong] += np.array([0.004, 0.0])
    results = [tracker.update(i * FRAME_DT, z) for i, z in enumerate(zs)]
    assert not results[1] and results[1].reason.startswith(PRIOR_RESTART)
    start = 2 if wrong == 0 else 3  # a wrong newer one is refused again with the next
    assert all(not r for r in results[1:start])
    assert results[start] and results[start].reason.startswith("initialised")
    assert tracker.consecutive_rejections == 0
    pred = tracker.predict_at(3 * FRAME_DT)
    assert np.allclose(pred.position, truth[3], atol=1e-9)
    assert np.allclose(pred.velocity, [0.0, BELT_SPEED], atol=1e-9)
    # Fused as before, such a pair would have put the filter 4 mm off the face with a
    # sub-millimetre covariance: the next right detection is gated out.
    fused = ConstantVelocityTracker(_prior_config())
    r = np.eye(2) * fused.config.measurement_std**2
    assert fused.restart(0.0, truth[0], r, FRAME_DT, truth[1] + np.array([0.004, 0.0]), r)
    assert not fused.update(2 * FRAME_DT, truth[2])


def test_a_restart_is_not_refused_by_the_belt_prior() -> None:
    """A restart's pair is the caller's (three collinear detections of a face that changed
    its motion): taken even when it disagrees with the belt's speed."""
    tracker = ConstantVelocityTracker(_prior_config())
    r = np.eye(2) * 1e-8
    z0, z1 = np.array([0.0, 0.0]), np.array([0.004, BELT_SPEED * FRAME_DT])
    assert tracker.restart(0.0, z0, r, FRAME_DT, z1, r)
    assert tracker.initialised


def test_relaxed_transition_decays_the_deviation_and_composes() -> None:
    """The velocity's deviation from the prior decays as exp(-t / time); the position
    integrates that velocity; two steps equal one step of their sum; a long time constant
    is the constant-velocity model."""
    vp = np.array([0.0, BELT_SPEED])
    s = np.array([0.01, 0.02, 0.03, BELT_SPEED - 0.02])
    f, c = relaxed_transition(0.2, vp, 0.2)
    out = f @ s + c
    assert out[2:] == pytest.approx(vp + np.exp(-1.0) * (s[2:] - vp), abs=1e-12)
    assert out[:2] == pytest.approx(s[:2] + vp * 0.2 + 0.2 * (1 - np.exp(-1.0)) * (s[2:] - vp),
                                    abs=1e-12)
    f1, c1 = relaxed_transition(0.07, vp, 0.2)
    f2, c2 = relaxed_transition(0.13, vp, 0.2)
    assert f2 @ (f1 @ s + c1) + c2 == pytest.approx(out, abs=1e-12)
    f_long, c_long = relaxed_transition(0.1, vp, 1e9)
    assert f_long @ s + c_long == pytest.approx(transition(0.1) @ s, abs=1e-8)


HELD_Q = 8e-5  # m^2/s^3: a belt jittering by 2 mm/s every 0.1 s (the paper scene's)


def _held_pair() -> tuple[ConstantVelocityTracker, ConstantVelocityTracker]:
    """A tracker with the belt's velocity prior at the start only, and one holding it."""
    def config(time: float) -> TrackerConfig:
        return TrackerConfig.belt(depth=CAMERA_HEIGHT - BELT_Z, focal_px=290.0,
                                  pixel_std=PIXEL_STD, accel_psd=HELD_Q,
                                  prior_velocity=(0.0, BELT_SPEED), prior_velocity_std=0.01,
                                  prior_velocity_time=time)

    return ConstantVelocityTracker(config(0.0)), ConstantVelocityTracker(config(0.2))


def _feed(tracker: ConstantVelocityTracker, seed: int, *, slide: float, burst: float,
          frames: int = 24) -> float:
    """``frames`` detections of a face on the belt that slides across it at ``slide`` m/s
    from 0.3 s on; the last four are off by 1, 2, 3, 4 times ``burst`` m across the belt (a
    fit that takes in more and more of a side wall). Returns the last capture time."""
    rng = np.random.default_rng(seed)
    t = 0.0
    for k in range(frames):
        t = (k + 1) * FRAME_DT
        z = (np.array([slide * max(t - 0.3, 0.0), BELT_SPEED * t])
             + rng.normal(0.0, tracker.config.measurement_std, 2))
        z[0] += burst * max(0, k - frames + 5)
        tracker.update(t, z)
    return t


def _blind_error(tracker: ConstantVelocityTracker, t: float, slide: float) -> float:
    """Extrapolation error (m) 0.5 s after ``t``: a blind descent's length."""
    te = t + 0.5
    truth = np.array([slide * (te - 0.3), BELT_SPEED * te])
    return float(np.linalg.norm(tracker.predict_at(te).position - truth))


def test_held_belt_prior_keeps_a_biased_burst_out_of_the_blind_extrapolation() -> None:
    """Biased fits at the end of a track pull a free velocity off the belt's and the blind
    extrapolation with it; the held prior does not follow them (the few that the gate lets
    in are too little evidence of a motion of the object's own)."""
    plain_err, held_err = [], []
    for seed in range(8):
        plain, held = _held_pair()
        t = _feed(plain, seed, slide=0.0, burst=0.0015)
        _feed(held, seed, slide=0.0, burst=0.0015)
        assert held.on_prior
        plain_err.append(_blind_error(plain, t, 0.0))
        held_err.append(_blind_error(held, t, 0.0))
    assert np.mean(held_err) < 0.4 * np.mean(plain_err)
    assert max(held_err) < 0.003


def test_held_belt_prior_lets_a_sliding_object_go() -> None:
    """A face sliding across the belt at 20 mm/s: the innovation test releases the prior,
    and the held tracker follows the slide as the one without it does (to 0.1 mm: the
    free filter started without the prior's start-up fusion)."""
    for seed in range(8):
        plain, held = _held_pair()
        t = _feed(plain, seed, slide=0.02, burst=0.0)
        _feed(held, seed, slide=0.02, burst=0.0)
        assert not held.on_prior
        assert held.predict_at(t).velocity[0] > 0.012
        assert _blind_error(held, t, 0.02) == pytest.approx(_blind_error(plain, t, 0.02),
                                                            abs=1e-4)
        assert _blind_error(held, t, 0.02) < 0.004

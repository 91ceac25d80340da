"""The phase machine's logic: what each phase commands and when it hands over or fails.

See :mod:`stackpick_sim.episodes.episode` for the loop that drives it. Phase durations are
logged in sim time; the record is filled in as the phases pass.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from stackpick_sim.episodes.arm import ServoErrors, approach_pose, pose_error
from stackpick_sim.episodes.outcome import face_in_view, match_object, touching, view_pose
from stackpick_sim.episodes.record import FAILURES, PHASES, PoseErrors
from stackpick_sim.episodes.sensing import Candidate, Observation, oracle_candidate
from stackpick_sim.episodes.verdict import judge
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.geometry import tilt_angles
from stackpick_sim.sim.ground_truth import FrameTruth, frame_truth

if TYPE_CHECKING:
    from stackpick_sim.episodes.episode import Episode

#: The approach hands over to the servo within this distance (m) and angle (deg) of its goal.
APPROACH_DONE = (0.01, 5.0)
#: The servo must meet its tolerances on this many consecutive ticks.
SERVO_SETTLE_TICKS = 3
#: Longest time without a fused detection while the face should be in view, s (track,
#: approach, servo; the descent may go blind).
MAX_BLIND_S = 0.4
#: The tool keeps pressing this far (m) past where it touched while the suction takes hold.
GRASP_PRELOAD = 0.002


class PhaseLogic:
    """Per-tick decisions of one episode."""

    def __init__(self, episode: Episode) -> None:
        self.ep = episode
        self.phase = PHASES[0]
        self.phase_start = 0.0
        self.failure: str | None = None
        self.done = False
        self._truths: dict[float, FrameTruth] = {}
        self._oracle_first: dict[float, dict[str, Candidate | None]] = {}
        self._settled = 0
        self._standoff = episode.scene.cell.cfg.episode.standoff
        self._lift_from: np.ndarray | None = None
        self._start_z: dict[str, float] = {}
        self._grasped: list[str] = []
        self._look_T_cam = episode.scene.cell.world_T_cam()
        self._cycle_end: float | None = None
        self._now = 0.0

    # -- bookkeeping ---------------------------------------------------------------------
    def _enter(self, phase: str, t: float) -> None:
        self.ep.record.phases[self.phase] = round(t - self.phase_start, 6)
        self.phase, self.phase_start = phase, t

    def fail(self, reason: str, detail: str) -> None:
        """End the episode with ``reason`` (one of FAILURES)."""
        if reason not in FAILURES:
            raise EpisodeError(f"unknown failure reason {reason!r}; known: {', '.join(FAILURES)}")
        if self.failure is None:
            self.failure = reason
            self.ep.record.failure = reason
            self.ep.record.failure_detail = detail
            self.ep.record.failed_phase = self.phase

    def finish(self) -> None:
        """Close the last phase's log and judge the outcome."""
        rec = self.ep.record
        rec.phases[self.phase] = round(self._now - self.phase_start, 6)
        rec.cycle_time_s = self._cycle_end
        if self.done:
            judge(self.ep, self._start_z, self._grasped)

    def before_capture(self, t: float) -> None:
        """Ground truth of frames the first detection may come from (needs segmentation)."""
        if self.phase in ("look", "detect"):
            start = time.perf_counter()
            assert self.ep.camera is not None
            truth = frame_truth(self.ep.scene.cell, self.ep.camera.segmentation())
            self._truths[t] = truth
            if self.ep.sensor.detector == "oracle":  # the oracle's pose must be of capture time
                cell = self.ep.scene.cell
                cam = self.ep.arm.eih.world_T_cam(cell.data)
                self._oracle_first[t] = {o.name: oracle_candidate(cell, o, cam)
                                         for o in cell.objects if o.name in truth.top_objects}
            self.ep.wall["truth"] += time.perf_counter() - start

    # -- the machine -----------------------------------------------------------------------
    def tick(self, t: float, dt: float, observations: list[Observation]) -> ServoErrors | None:
        """Advance the phase machine at sim time ``t`` s; returns the servo errors if servoing."""
        self._now = t
        cfg = self.ep.scene.cell.cfg.episode
        if self.phase not in ("look", "detect"):
            for obs in observations:
                self.ep.estimator.offer(obs)
        if t - self.phase_start > getattr(cfg, f"timeout_{self.phase}") + 1e-9:
            self._time_out(t)
            return None
        handler = getattr(self, f"_{self.phase}")
        result: ServoErrors | None = handler(t, dt, observations)
        self._update_sensor_hints()
        return result

    def _time_out(self, t: float) -> None:
        if self.phase == "detect":
            self.fail("no_detection", f"no top object detected in {t - self.phase_start:.2f} s")
        elif self.ep.arm.at_limit():
            self.fail("joint_limit", f"{self.phase} timed out with a joint at its limit")
        elif self.phase == "servo":
            self.fail("servo_diverged", "the servo did not converge in time")
        else:
            self.fail("timeout", f"{self.phase} took longer than its time-out")

    def _look(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        if self.ep.sensor.frames > 0:
            self._enter("detect", t)

    def _detect(self, t: float, dt: float, observations: list[Observation]) -> None:
        self.ep.arm.hold()
        for obs in observations:
            truth = self._truths.get(obs.capture_time)
            if truth is None:
                continue
            cand = self._first_candidate(obs, truth)
            if cand is None:
                continue
            self._start(obs, cand, truth)
            self._enter("track", t)
            return

    def _first_candidate(self, obs: Observation, truth: FrameTruth) -> Candidate | None:
        ep = self.ep
        if ep.sensor.detector == "oracle":
            tops = [o for o in truth.objects if o.is_top]
            if not tops:
                return None
            # Oracle policy: the flattest top face (the easiest pick).
            best = min(tops, key=lambda o: (o.tilt_deg, o.name))
            obj = next(o for o in ep.scene.cell.objects if o.name == best.name)
            ep.sensor.target = obj
            return self._oracle_first.get(obs.capture_time, {}).get(obj.name)
        return next((c for c in obs.candidates if c.is_top and c.normal_cam is not None), None)

    def _start(self, obs: Observation, cand: Candidate, truth: FrameTruth) -> None:
        ep, rec = self.ep, self.ep.record
        cell = ep.scene.cell
        rec.top_objects = truth.top_objects
        rec.target_object = match_object(truth, cand.pixel)
        self._start_z = {o.name: float(cell.data.xpos[o.body_id][2]) for o in cell.objects}
        if rec.target_object is not None:
            t_obj = next(o for o in truth.objects if o.name == rec.target_object)
            assert cand.normal_cam is not None
            rec.detection = PoseErrors(
                estimated=(float(cand.pixel[0]), float(cand.pixel[1]),
                           *tilt_angles(cand.normal_cam)),
                actual=(*t_obj.face_center_px, t_obj.theta_x_deg, t_obj.theta_y_deg))
        ep.estimator.start(obs, cand)

    def _update_sensor_hints(self) -> None:
        ep = self.ep
        if not ep.estimator.initialised:
            return
        world_T_cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        state = ep.estimator.state(self._now, world_T_cam)
        r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
        ep.sensor.expected_depth = float((r.T @ (state.centre - p))[2])
        ep.sensor.reference_normal_cam = r.T @ state.normal

    def _check_track(self, t: float) -> bool:
        est = self.ep.estimator
        if self.ep.arm.at_limit() and self.phase in ("approach", "servo"):
            # A joint stopped at its range end leaves the goal (and often the face) out of
            # reach: report the cause, not the symptom.
            self.fail("joint_limit", "a joint reached its range end before the servo goal")
            return False
        if est.lost:
            self.fail("lost_track", "too many detections in a row outside the tracking gate")
            return False
        if est.last_fused_time is not None and t - est.last_fused_time > MAX_BLIND_S:
            self.fail("lost_track", f"no detection fused for {t - est.last_fused_time:.2f} s")
            return False
        return True

    def _track(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        est = self.ep.estimator
        if not self._check_track(t):
            return
        if est.initialised and est.fused >= self.ep.scene.cell.cfg.episode.track_frames:
            self._enter("approach", t)

    def _approach(self, t: float, dt: float, obs: list[Observation]) -> None:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        if not self._check_track(t):
            return
        lead = 1.0 / cfg.approach_gain
        now_T_tool = ep.arm.command_world_T_tool()
        cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        goal = approach_pose(ep.estimator.state(t + lead, cam), cfg.standoff, now_T_tool)
        ep.arm.apply(ep.arm.pose_rate(goal, cfg.approach_gain, dt), dt)
        here = approach_pose(ep.estimator.state(t, cam), cfg.standoff, now_T_tool)
        pos, ang = pose_error(ep.arm.eih.world_T_ee(ep.scene.cell.data), here)
        if pos < APPROACH_DONE[0] and ang < APPROACH_DONE[1]:
            self._enter("servo", t)

    def _servo_step(self, t: float, dt: float, standoff: float,
                    rate: float) -> ServoErrors:
        ep = self.ep
        cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        qdot, err = ep.arm.servo_rate(ep.estimator.state(t, cam), standoff, rate, dt)
        ep.arm.apply(qdot, dt)
        return err

    def _servo(self, t: float, dt: float, obs: list[Observation]) -> ServoErrors | None:
        cfg = self.ep.scene.cell.cfg.episode
        if not self._check_track(t):
            return None
        err = self._servo_step(t, dt, cfg.standoff, 0.0)
        ok = (err.lateral < cfg.servo_lateral_tol and abs(err.depth) < cfg.servo_depth_tol
              and err.tilt_deg < cfg.servo_tilt_tol_deg)
        self._settled = self._settled + 1 if ok else 0
        if self._settled >= SERVO_SETTLE_TICKS:
            self._standoff = cfg.standoff
            self._enter("descend", t)
        return err

    def _descend(self, t: float, dt: float, obs: list[Observation]) -> ServoErrors | None:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        touched = touching(ep.scene.cell, ep.lips)
        if touched:
            self._pick_moment(t)
            ep.scene.cell.data.ctrl[ep.scene.cell.suction_actuator_id] = 1.0
            self._standoff = max(self._standoff, 0.0) - GRASP_PRELOAD
            self._enter("grasp", t)
            return self._servo_step(t, dt, self._standoff, 0.0)
        if self._standoff <= -cfg.overtravel:
            self.fail("missed_grasp", "the descent passed the predicted face without contact")
            return None
        self._standoff -= cfg.descend_speed * dt
        return self._servo_step(t, dt, self._standoff, -cfg.descend_speed)

    def _pick_moment(self, t: float) -> None:
        ep, rec = self.ep, self.ep.record
        cell = ep.scene.cell
        if rec.target_object is None:
            return
        obj = next(o for o in cell.objects if o.name == rec.target_object)
        k = cell.intrinsics
        actual, centre_w = face_in_view(cell, obj, self._look_T_cam, k)
        state = ep.estimator.state(t, ep.arm.eih.world_T_cam(cell.data))
        estimated = view_pose(state.centre, state.normal, self._look_T_cam, k)
        rec.pick_estimate = PoseErrors(estimated=estimated, actual=actual)
        rec.prediction_error_px = rec.pick_estimate.center_error_px
        rec.prediction_error_mm = 1e3 * float(np.linalg.norm(state.centre - centre_w))

    def _grasp(self, t: float, dt: float, obs: list[Observation]) -> ServoErrors | None:
        cfg = self.ep.scene.cell.cfg.episode
        err = self._servo_step(t, dt, self._standoff, 0.0)
        if t - self.phase_start >= cfg.grasp_dwell:
            self._grasped = [o.name for o in touching(self.ep.scene.cell, self.ep.lips)]
            self._lift_from = self.ep.arm.command_world_T_tool()
            self._enter("lift", t)
        return err

    def _lift(self, t: float, dt: float, obs: list[Observation]) -> None:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        assert self._lift_from is not None
        rise = min(cfg.lift_speed * (t - self.phase_start), cfg.lift_height)
        goal = self._lift_from.copy()
        goal[2, 3] += rise
        ep.arm.apply(ep.arm.pose_rate(goal, cfg.approach_gain * 2, dt), dt)
        tool_z = ep.arm.eih.world_T_ee(ep.scene.cell.data)[2, 3]
        if tool_z >= self._lift_from[2, 3] + cfg.lift_height - 0.003:
            self._cycle_end = t
            self._enter("verify", t)

    def _verify(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        if t - self.phase_start >= self.ep.scene.cell.cfg.episode.verify_time:
            self.done = True

"""The tracked face: Kalman position/velocity, face height and normal, from late detections.

Two variants of the paper's constant-velocity filter (Eq. 5-7), chosen by
``episode.tracker_frame``:

* ``belt`` (default): each detection's face-centre pixel is back-projected, with the camera
  pose of its capture (forward kinematics), onto the horizontal plane at the face's height;
  the filter runs on world (x, y) in metres. The arm's own motion drops out (paper Fig. 9).
* ``image``: the paper's variant: the filter runs on the pixel itself. The camera's motion
  enters as unmodelled acceleration; to act on the estimate it is back-projected with the
  *current* camera pose.

Noise (documented in :mod:`stackpick_sim.estimation.kalman`): the belt's speed is redrawn
every ``conveyor.jitter_period`` s with std ``conveyor.speed_jitter``; a speed jumping by
``sigma sqrt(2)`` every ``T`` s diffuses like white acceleration of density
``2 sigma^2 / T`` (:func:`belt_accel_psd` with ``tau = T``). R is the detector's pixel noise
mapped through the plane back-projection Jacobian (belt) or ``sigma_px^2 I`` (image).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.sensing import Candidate, Observation, ellipse_inside
from stackpick_sim.estimation import (
    ConstantVelocityTracker,
    TrackerConfig,
    backproject_to_plane,
    belt_accel_psd,
    plane_backprojection_jacobian,
)
from stackpick_sim.exceptions import EstimationError
from stackpick_sim.geometry import CameraIntrinsics, project_circle

FloatArray = NDArray[np.float64]

#: Face-centre pixel noise of the vision pipeline, px std: placeholder of the order of the
#: look-frame centre errors measured on paper scenes (0.1-0.3 px), with margin for frames
#: taken while the camera moves.
VISION_PIXEL_STD = 0.5
#: Oracle detections are exact; a tiny R keeps the filter well posed.
ORACLE_PIXEL_STD = 0.05
#: Unmodelled motion of a face about its constant-velocity path, m std: the top object of
#: a pile rocks on the jittering belt (paper scene seed 2: +-0.2 mm in x at ~15 Hz, 9 mm/s
#: peaks), which an exact detector reports and a 0.05 px R would gate out. Added to R.
#: Measured in simulation, a placeholder for a real pile.
FACE_WOBBLE_STD = 3e-4
#: The face height is the median of this many latest detections' heights: a pile settles
#: under the running belt (paper seed 0: the top face sank 0.5 mm in 0.5 s), so old
#: heights go stale; the median outvotes single bad depths. Placeholder.
FACE_Z_WINDOW = 9
#: Lower bound of the belt speed jitter the filter assumes, m/s: the object can also creep
#: on the belt or settle in its pile, which the configured jitter does not cover.
#: Placeholder, not identified.
MIN_SPEED_JITTER = 5e-4
#: Image-frame filter's acceleration density, px^2/s^3: it must absorb the camera's motion,
#: ~5 m/s^2 at ~0.2 m depth and f ~ 290 px is ~7000 px/s^2 over ~30 ms frames: placeholder.
IMAGE_ACCEL_PSD = 1.5e6
#: Fastest plausible image speed of a face, px/s (camera and belt together).
IMAGE_MAX_SPEED = 4000.0
#: A radius hypothesis takes over when its summed NIS is this much below the active one's
#: (two measurements at the edge of a 2-dof 1-sigma ellipse): hysteresis against flapping.
NIS_SWITCH_MARGIN = 4.0
#: Faces whose ellipse comes this close to the image border are not used, px.
EDGE_MARGIN_PX = 2.0
#: Before the filter has a velocity, a detection is associated with the track only within
#: this distance of where the nominal belt speed puts the first one (m, belt frame; px,
#: image frame): a few times the detector's centre noise.
INIT_GATE = {"belt": 0.004, "image": 6.0}
#: After this many gated-out measurements in a row, the last three are checked for a changed
#: motion (the object shifted in its pile: paper seed 38, +20 mm/s in 0.1 s): if the third
#: lies within REACQUIRE_TOLERANCE (m; px for the image frame) of the line through the
#: other two, and they are near the prediction (REACQUIRE_GATE, same units), the filter
#: restarts from the last two. Three collinear detections of one face, not clutter.
REACQUIRE_AFTER = 3
REACQUIRE_TOLERANCE = {"belt": 0.001, "image": 3.0}
REACQUIRE_GATE = {"belt": 0.008, "image": 25.0}
#: A candidate farther than this from the predicted face centre is another object's face
#: (m, belt frame; px, image frame): it is not offered to the filter's gate at all, so it
#: does not count towards a lost track (the tracked face may be cut by the image border
#: while a neighbour is in view). Half the small face radius; in the image frame, the
#: camera motion the image filter does not model makes its predictions looser (25 px).
ASSOCIATION_MAX = {"belt": 0.0125, "image": 25.0}
#: Two face normals within this angle (deg) agree; the normal estimate is the mean of the
#: largest agreeing group, so an occasional flip of the pose's two-fold ambiguity is outvoted.
NORMAL_AGREEMENT_DEG = 10.0


@dataclass(frozen=True, kw_only=True)
class TargetState:
    """The face at one instant: centre (3,) m, velocity (3,) m/s, unit inward normal (3,)."""

    centre: FloatArray
    velocity: FloatArray
    normal: FloatArray


class TargetEstimator:
    """Fuses the tracked face's detections; :meth:`state` predicts it at any time."""

    def __init__(self, cfg: SceneConfig, intrinsics: CameraIntrinsics, *, oracle: bool) -> None:
        self.frame = cfg.episode.tracker_frame
        self.k = intrinsics
        self.pixel_std = ORACLE_PIXEL_STD if oracle else VISION_PIXEL_STD
        self._belt_v = np.array([0.0, cfg.conveyor.speed])
        jitter = max(cfg.conveyor.speed_jitter, MIN_SPEED_JITTER)
        if self.frame == "belt":
            focal = 0.5 * (intrinsics.fx + intrinsics.fy)
            q = belt_accel_psd(jitter, cfg.conveyor.jitter_period)
            config = TrackerConfig.belt(depth=cfg.camera.look_height, focal_px=focal,
                                        pixel_std=self.pixel_std, accel_psd=q)
        else:
            config = TrackerConfig.image(accel_psd=IMAGE_ACCEL_PSD, pixel_std=self.pixel_std,
                                         max_speed=IMAGE_MAX_SPEED)
        self.tracker = ConstantVelocityTracker(config)
        focal = 0.5 * (intrinsics.fx + intrinsics.fy)
        self._wobble_px = FACE_WOBBLE_STD * focal / cfg.camera.look_height
        self._normals: list[FloatArray] = []
        self._zs: list[float] = []
        self._normal = np.array([0.0, 0.0, -1.0])
        self.correct_centres = not oracle
        self.radius: float | None = None
        self._last: tuple[float, FloatArray] | None = None
        self.fused = 0
        self.reacquired = 0
        """How many times the filter restarted on a changed motion."""
        self._rejected: list[tuple[float, FloatArray, FloatArray]] = []
        self.last_fused_time: float | None = None
        self.nis = 0.0
        """Sum of the measurements' normalised innovations squared (capped at the gate)."""

    @property
    def initialised(self) -> bool:
        """True once two measurements set the filter."""
        return self.tracker.initialised

    @property
    def lost(self) -> bool:
        """True after too many gated-out measurements in a row."""
        return self.tracker.lost_track

    @property
    def normal(self) -> FloatArray:
        """Unit inward face normal, world frame (consensus of the detections' normals)."""
        return self._normal

    @property
    def face_z(self) -> float:
        """Height of the face centre, world z, m (median of the last detections' heights)."""
        return float(np.median(self._zs[-FACE_Z_WINDOW:])) if self._zs else 0.0

    def start(self, obs: Observation, cand: Candidate, radius: float | None = None) -> None:
        """Begin with the first detection of the face to pick (its pose must be known).

        ``radius`` (m) overrides the detection's face radius: a monocular pose is known up
        to scale, so the face centre (and its height) is rescaled to that radius.
        """
        if cand.normal_cam is None or cand.centre_cam is None:
            raise EstimationError("the first detection must carry a pose (normal and centre)")
        if radius and cand.radius > 0:
            cand = replace(cand, centre_cam=cand.centre_cam * (radius / cand.radius),
                           radius=radius)
        self.radius = cand.radius
        self.nis = 0.0
        self._fuse(obs, cand)

    def offer(self, obs: Observation) -> bool:
        """Associate the nearest candidate of ``obs`` with the track and fuse it; True if used."""
        if not obs.candidates:
            return False
        predicted = self._predicted_measurement(obs.capture_time)
        shift = self._centre_shift(obs) if self.correct_centres else None
        scored = []
        for cand in obs.candidates:
            e = cand.ellipse
            if e is not None and not ellipse_inside(e, self.k, EDGE_MARGIN_PX):
                continue  # a face cut by the image border gives a biased ellipse
            if shift is not None and cand.ellipse is not None:
                cand = replace(cand, pixel=np.array([cand.ellipse.cx, cand.ellipse.cy]) + shift)
            try:
                z = self._measurement(obs, cand.pixel)
            except EstimationError:
                continue
            scored.append((float(np.linalg.norm(z - predicted)), cand))
        if not scored:
            return False
        distance, best = min(scored, key=lambda s: s[0])
        if not self.tracker.initialised and distance > INIT_GATE[self.frame]:
            return False
        if distance > ASSOCIATION_MAX[self.frame]:
            return False  # another object's face: neither a measurement nor a rejection
        return self._fuse(obs, best)

    def _centre_shift(self, obs: Observation) -> FloatArray | None:
        """(2,) px from the face's ellipse centre to its centre's image, from the estimate.

        Perspective moves an ellipse's centre off the image of the circle's centre; with
        the tracked normal (a consensus over frames) this shift is steadier than each
        frame's own pose.
        """
        if not self.tracker.initialised or self.radius is None:
            return None
        state = self.state(obs.capture_time, obs.world_T_cam)
        r, p = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        c_cam, n_cam = r.T @ (state.centre - p), r.T @ state.normal
        try:
            e = project_circle(c_cam, n_cam, self.radius, self.k)
        except ValueError:
            return None
        return np.asarray(self.k.project(c_cam)[0] - np.array([e.cx, e.cy]))

    def state(self, t: float, world_T_cam_now: FloatArray) -> TargetState:
        """The face predicted at sim time ``t`` s (Eq. 4); needs :attr:`initialised`."""
        pred = self.tracker.predict_at(t)
        z = self.face_z
        if self.frame == "belt":
            centre = np.array([pred.position[0], pred.position[1], z])
            velocity = np.array([pred.velocity[0], pred.velocity[1], 0.0])
        else:
            plane = np.array([0.0, 0.0, z])
            centre = backproject_to_plane(pred.position.reshape(1, 2), self.k, world_T_cam_now,
                                          plane)[0]
            g = plane_backprojection_jacobian(pred.position, self.k, world_T_cam_now, plane)
            velocity = g @ pred.velocity
        return TargetState(centre=centre, velocity=velocity, normal=self.normal)

    def _predicted_measurement(self, t: float) -> FloatArray:
        if self.tracker.initialised:
            return np.asarray(self.tracker.predict_at(t).position)
        if self._last is None:
            raise EstimationError("no measurement yet to associate with")
        t0, z0 = self._last
        return z0 + (self._belt_v * (t - t0) if self.frame == "belt" else 0.0)

    def _measurement(self, obs: Observation, pixel: FloatArray) -> FloatArray:
        if self.frame == "image":
            return np.asarray(pixel, dtype=float)
        plane = np.array([0.0, 0.0, self.face_z])
        return backproject_to_plane(np.reshape(pixel, (1, 2)), self.k, obs.world_T_cam,
                                    plane)[0, :2]

    def _fuse(self, obs: Observation, cand: Candidate) -> bool:
        first = not self._zs and cand.centre_cam is not None
        if first:
            self._add_pose(obs, cand)  # the plane height is needed to back-project
        z = self._measurement(obs, cand.pixel)
        if self.frame == "belt":
            g = plane_backprojection_jacobian(cand.pixel, self.k, obs.world_T_cam,
                                              np.array([0.0, 0.0, self.face_z]))[:2]
            r = self.pixel_std**2 * g @ g.T + FACE_WOBBLE_STD**2 * np.eye(2)
        else:
            r = np.eye(2) * (self.pixel_std**2 + self._wobble_px**2)
        result = self.tracker.update(obs.capture_time, z, r)
        self.nis += min(result.mahalanobis_sq, self.tracker.config.gate_chi2)
        accepted = bool(result) or result.reason.startswith("initialising: first")
        if result.reason.startswith("gated"):
            self._rejected = [*self._rejected[-(REACQUIRE_AFTER - 1):], (obs.capture_time, z, r)]
            accepted = self._reacquire()
        else:
            self._rejected = []
        if accepted:
            self._last = (obs.capture_time, z)
            self.fused += 1
            self.last_fused_time = obs.capture_time
            if not first:
                self._add_pose(obs, cand)
        return accepted

    def _reacquire(self) -> bool:
        """Restart the filter on a consistent run of gated-out measurements; True if done."""
        if len(self._rejected) < REACQUIRE_AFTER:
            return False
        (t0, z0, _), (t1, z1, r1), (t2, z2, r2) = self._rejected[-3:]
        line = z1 + (z1 - z0) * (t2 - t1) / max(t1 - t0, 1e-9)
        predicted = self.tracker.predict_at(t2).position
        if (np.linalg.norm(z2 - line) > REACQUIRE_TOLERANCE[self.frame]
                or np.linalg.norm(z2 - predicted) > REACQUIRE_GATE[self.frame]):
            return False
        self.tracker.restart(t1, z1, r1, t2, z2, r2)
        self._rejected = []
        self.reacquired += 1
        return self.tracker.initialised

    def _add_pose(self, obs: Observation, cand: Candidate) -> None:
        r_wc, p_wc = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        if cand.centre_cam is not None:
            # A monocular pose is known up to scale: put the face at this track's radius.
            scale = self.radius / cand.radius if self.radius and cand.radius > 0 else 1.0
            self._zs.append(float((r_wc @ (cand.centre_cam * scale) + p_wc)[2]))
        if cand.normal_cam is not None:
            self._add_normal(r_wc @ cand.normal_cam)

    def _add_normal(self, n: FloatArray) -> None:
        self._normals.append(n / float(np.linalg.norm(n)))
        normals = np.array(self._normals)
        agree = normals @ normals.T >= np.cos(np.radians(NORMAL_AGREEMENT_DEG))
        best = int(np.argmax(agree.sum(axis=1)))  # first of the largest group: deterministic
        mean = normals[agree[best]].sum(axis=0)
        self._normal = mean / float(np.linalg.norm(mean))

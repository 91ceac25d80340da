"""The tracked face: Kalman position/velocity, face height and normal, from late detections.

Two variants of the paper's constant-velocity filter (Eq. 5-7), chosen by
``episode.tracker_frame``:

* ``belt`` (default): each detection's face-centre pixel is back-projected, with the camera
  pose of its capture (forward kinematics), onto the horizontal plane at the face's height;
  the filter runs on world (x, y) in metres. The arm's own motion drops out (paper Fig. 9).
* ``image``: the paper's variant: the filter runs on the pixel itself, in the image of one
  camera pose (that of the last measurement). Before each update the state is predicted
  in that image and carried into the new frame's image through the face plane's
  homography (:func:`transfer_via_plane`), so the arm's own motion does not enter the
  state as acceleration (uncompensated, every detection of a moving camera was gated
  out). To act on it the estimate is back-projected with the pose it is expressed in.
  Gates are the belt frame's distances on the face plane, measured in px through the
  local scale (m/px) at the frame's pose.

Noise (documented in :mod:`stackpick_sim.estimation.kalman`): the belt's speed is redrawn
every ``conveyor.jitter_period`` s with std ``conveyor.speed_jitter``; a speed jumping by
``sigma sqrt(2)`` every ``T`` s diffuses like white acceleration of density
``2 sigma^2 / T`` (:func:`belt_accel_psd` with ``tau = T``). R is the detector's pixel noise
mapped through the plane back-projection Jacobian (belt) or ``sigma_px^2 I`` (image). The
belt frame holds the belt's nominal velocity as a prior: fused with the two-point start,
then relaxed towards between measurements unless the measurements show the face moving on
its own (``episode.belt_velocity_std``, ``belt_velocity_time``, ``belt_velocity_evidence``;
:class:`~stackpick_sim.estimation.kalman.TrackerConfig`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.sensing import Candidate, Observation, ellipse_inside
from stackpick_sim.estimation import (
    PRIOR_RESTART,
    ConstantVelocityTracker,
    EstimationError,
    TrackerConfig,
    UpdateResult,
    backproject_to_plane,
    belt_accel_psd,
    plane_backprojection_jacobian,
    project_to_pixels,
    transfer_via_plane,
)
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle
from stackpick_sim.pipeline import TargetState
from stackpick_sim.vision import circle_poses

FloatArray = NDArray[np.float64]

#: Face-centre pixel noise of the vision pipeline, px std: placeholder of the order of the
#: look-frame centre errors measured on paper scenes (0.1-0.3 px), with margin for frames
#: taken while the camera moves.
VISION_PIXEL_STD = 0.5
#: Oracle detections are exact; a tiny R keeps the filter well posed.
ORACLE_PIXEL_STD = 0.05
#: Unmodelled motion of a face about its constant-velocity path, m std: the top object of
#: a pile rocks on the jittering belt (on the paper scene +-0.2 mm in x at ~15 Hz, 9 mm/s
#: peaks), which an exact detector reports and a 0.05 px R would gate out. Added to R.
#: Measured in simulation, a placeholder for a real pile.
FACE_WOBBLE_STD = 3e-4
#: Until enough heights agree (``episode.face_height_views``), the face height is the median
#: of this many latest detections' heights: a pile settles under the running belt (measured
#: on the paper scene: a top face sinks 0.5 mm in 0.5 s), so old heights go stale; the median
#: outvotes single bad depths. Placeholder.
FACE_Z_WINDOW = 9
#: Lower bound of the belt speed jitter the filter assumes, m/s: the object can also creep
#: on the belt or settle in its pile, which the configured jitter does not cover.
#: Placeholder, not identified.
MIN_SPEED_JITTER = 5e-4
#: Fastest plausible image speed of a face, px/s, for the image frame's two-point start
#: (the camera's motion is compensated; 1 m/s at the closest ~0.05 m depth, f ~ 290 px).
IMAGE_MAX_SPEED = 6000.0
#: A radius hypothesis takes over when its summed NIS is this much below the active one's
#: (two measurements at the edge of a 2-dof 1-sigma ellipse): hysteresis against flapping.
NIS_SWITCH_MARGIN = 4.0
#: Faces whose ellipse comes this close to the image border are not used, px.
EDGE_MARGIN_PX = 2.0
#: Before the filter has a velocity, a detection is associated with the track only within
#: this distance of where the nominal belt speed puts the first one (m on the face plane):
#: a few times the detector's centre noise.
INIT_GATE = 0.004
#: After this many gated-out measurements in a row, the last three are checked for a changed
#: motion (the object shifts in its pile: +20 mm/s within 0.1 s on the paper scene): if the third
#: lies within REACQUIRE_TOLERANCE (m) of the line through the other two, and they are
#: near the prediction (REACQUIRE_GATE, m), the filter restarts from the last two. Three
#: collinear detections of one face, not clutter.
REACQUIRE_AFTER = 3
REACQUIRE_TOLERANCE = 0.001
REACQUIRE_GATE = 0.008
#: A candidate farther than this (m on the face plane) from the predicted face centre is
#: another object's face: it is not offered to the filter's gate at all, so it does not
#: count towards a lost track (the tracked face may be cut by the image border while a
#: neighbour is in view). Half the small face radius.
ASSOCIATION_MAX = 0.0125
#: A whole candidate ellipse whose semi-major axis differs from the tracked face's predicted
#: one by more than this share is another face (a smaller one, a side wall, a fragment of an
#: outline, a fit that took in a neighbour's arc): the major axis is set by the face's radius
#: and depth, which the track knows to a few per cent. Measured on the whole faces offered
#: to the right radius hypothesis in 100 cluttered-scene episodes: the tracked face's own
#: fits (centre within 0.5 px of its true image) differ by under 3 % in 99 % of frames and
#: by over 10 % in 2 of 1619; of the fits of other outlines near the prediction (3 px or
#: more off the face, within 10 px of the prediction) 59 % differ by over 10 %, only 21 % by
#: over 25 % (CUT_SIZE_TOLERANCE's share). Such a fit, 3-6 px off and 12-18 % too large, can
#: lie nearer the prediction than the face itself and pull the track off it (a fit of a top
#: face that takes in the outline of a face of its colour beside it).
SIZE_TOLERANCE = 0.10
#: The share for a face cut by the image border, fitted on part of its outline: looser, as
#: too few such frames were measured to support SIZE_TOLERANCE's tighter share.
CUT_SIZE_TOLERANCE = 0.25
#: Once tracked, a face cut by the image border is still used while its ellipse's centre is
#: in the image, with this many times the pixel noise: a fit on a partial outline, its size
#: checked against the track's (CUT_SIZE_TOLERANCE). The approach and the servo often carry
#: a face near the border. Placeholder.
CUT_STD_FACTOR = 3.0
#: Two face normals within this angle (deg) agree; the normal estimate is the mean of the
#: largest agreeing group over the views' pose solutions (see ``_add_normals``).
NORMAL_AGREEMENT_DEG = 10.0
#: A view votes on the normal's two-fold ambiguity only if its line of sight to the face is
#: this far (deg) from every earlier voter's: views along one line of sight (the still look
#: pose, the servo's and descent's views along the tool axis) see the wrong solution as
#: steadily as the right one. Placeholder.
VOTE_SIGHT_DEG = 5.0


@dataclass(frozen=True, kw_only=True)
class NormalView:
    """One view's pose of the tracked face, for the vote on its normal."""

    normals: FloatArray
    """(2, 3) the two unit normal solutions, world."""
    chosen: int | None
    """Which of them the detector picked (None: it gave no pose)."""
    height: float
    """The view's monocular face height, world z, m."""
    sight: FloatArray
    """(3,) unit line of sight to the face, world."""


def normal_voters(views: list[NormalView], face_z: float, tol: float) -> list[NormalView]:
    """The views that vote on the normal: those whose height lies within ``tol`` m of
    ``face_z`` m (none: the nearest one), of each line of sight (within VOTE_SIGHT_DEG) the
    first."""
    if not views:
        return []
    off = np.array([abs(v.height - face_z) for v in views])
    agreeing = [v for v, d in zip(views, off, strict=True) if d <= tol]
    cos_min = math.cos(math.radians(VOTE_SIGHT_DEG))
    voters: list[NormalView] = []
    for v in agreeing or [views[int(np.argmin(off))]]:
        if all(float(v.sight @ u.sight) <= cos_min for u in voters):
            voters.append(v)
    return voters


def agreed_low_height(heights: list[float], agreement: float, views: int) -> float | None:
    """The lowest height (m) on which ``views`` of ``heights`` (m) agree, or None.

    The median of the first run of ``views`` sorted heights that spans at most
    ``agreement`` m, from the lowest up. A monocular height's large errors are one-sided
    (too high, see ``episode.face_height_agreement``), so the lowest agreeing group is the
    face; a single fit that reads too low has no others agreeing with it.
    """
    if len(heights) < views:
        return None
    z = np.sort(np.asarray(heights, dtype=float))
    spans = z[views - 1:] - z[: len(z) - views + 1]
    ok = np.flatnonzero(spans <= agreement)
    if ok.size == 0:
        return None
    first = int(ok[0])
    return float(np.median(z[first:first + views]))


class TargetEstimator:
    """Fuses the tracked face's detections; :meth:`state` predicts it at any time."""

    def __init__(self, cfg: SceneConfig, intrinsics: CameraIntrinsics, *, oracle: bool,
                 frame: str | None = None) -> None:
        self.frame = frame or cfg.episode.tracker_frame
        """``belt`` or ``image`` (default: the scene's ``episode.tracker_frame``)."""
        self.k = intrinsics
        self.pixel_std = ORACLE_PIXEL_STD if oracle else VISION_PIXEL_STD
        self._belt_v = np.array([0.0, cfg.conveyor.speed])
        jitter = max(cfg.conveyor.speed_jitter, MIN_SPEED_JITTER)
        self._accel_psd = belt_accel_psd(jitter, cfg.conveyor.jitter_period)
        focal = 0.5 * (intrinsics.fx + intrinsics.fy)
        if self.frame == "belt":
            config = TrackerConfig.belt(
                depth=cfg.camera.look_height, focal_px=focal, pixel_std=self.pixel_std,
                accel_psd=self._accel_psd, prior_velocity=(0.0, cfg.conveyor.speed),
                prior_velocity_std=max(cfg.conveyor.speed_jitter, cfg.episode.belt_velocity_std),
                prior_velocity_time=cfg.episode.belt_velocity_time,
                prior_velocity_evidence=cfg.episode.belt_velocity_evidence)
        else:  # q in px^2/s^3 at the look depth; each step rescales it to its own depth
            scale = focal / cfg.camera.look_height
            config = TrackerConfig.image(accel_psd=self._accel_psd * scale**2,
                                         pixel_std=self.pixel_std, max_speed=IMAGE_MAX_SPEED)
        self.tracker = ConstantVelocityTracker(config)
        self._ref_T_cam: FloatArray | None = None
        """Image frame: the camera pose whose image the filter's pixels are in."""
        self._first: tuple[float, FloatArray, FloatArray, FloatArray] | None = None
        self._normals: list[FloatArray] = []
        self._normal_views: list[NormalView] = []
        """Every view's pose solutions, for the normal's vote (:meth:`_add_normals`)."""
        self._zs: list[float] = []
        self._height_agreement = cfg.episode.face_height_agreement
        self._height_views = cfg.episode.face_height_views
        self._vote_height_tol = cfg.episode.normal_vote_height_tol
        self._normal = np.array([0.0, 0.0, -1.0])
        self.correct_centres = not oracle
        self.radius: float | None = None
        self._last: tuple[float, FloatArray] | None = None
        self.fused = 0
        self.reacquired = 0
        """How many times the filter restarted on a changed motion."""
        self._rejected: list[tuple[float, FloatArray, FloatArray, FloatArray]] = []
        self.last_fused_time: float | None = None
        self.nis = 0.0
        """Sum of the measurements' normalised innovations squared (capped at the gate)."""
        self.missed_last = False
        """The last :meth:`offer` found faces in the frame but none to associate."""
        self.last_candidate: Candidate | None = None
        """The candidate of the latest measurement fused (None before the first)."""

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
        """Height of the face centre, world z, m: :func:`agreed_low_height` of the track's
        monocular heights (the median of the latest ones while too few agree)."""
        if not self._zs:
            return 0.0
        low = agreed_low_height(self._zs, self._height_agreement, self._height_views)
        return float(np.median(self._zs[-FACE_Z_WINDOW:])) if low is None else low

    @property
    def lowest_face_z(self) -> float:
        """Lowest monocular height of the face centre over the whole track, world z, m (0
        before any detection).

        The large errors of a monocular height are one-sided: an outline that takes in more
        than the face (the side wall of the face's colour, seen obliquely as the camera
        approaches; a neighbour's rim) is larger, so read as nearer: too high. Measured on
        paper scenes: the look pose's heights within 0.3 mm while the approach's and
        servo's are 10-18 mm too high; a look-pose outline that takes in the wall, 20 mm
        too high. So the face is expected at or above this bound, whatever height the
        heights agree on (:attr:`face_z`).
        """
        return min(self._zs) if self._zs else 0.0

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
        """Associate the nearest candidate of ``obs`` with the track and fuse it; True if used.

        :attr:`missed_last` tells afterwards whether usable faces were in the frame but none
        near enough the prediction to be associated (the NIS did not count that frame).
        """
        self.missed_last = False
        if not obs.candidates:
            return False
        try:
            predicted = self._predicted_measurement(obs)
        except EstimationError:
            return False
        expected = self.expected_ellipse(obs)
        shift = None
        if expected is not None and self.correct_centres:
            shift = np.asarray(expected[1] - np.array([expected[0].cx, expected[0].cy]))
        scored = [score for cand in obs.candidates
                  if (score := self._scored(obs, cand, expected, shift, predicted)) is not None]
        if not scored:
            return False
        distance, cut, best = min(scored, key=lambda s: s[0])
        distance *= self._metres_per_unit(obs.world_T_cam, predicted)
        if not self.tracker.initialised and distance > INIT_GATE:
            self.missed_last = True
            return False
        if distance > ASSOCIATION_MAX:
            self.missed_last = True
            return False  # another object's face: neither a measurement nor a rejection
        return self._fuse(obs, best, CUT_STD_FACTOR * self.pixel_std if cut else None)

    def _scored(self, obs: Observation, cand: Candidate,
                expected: tuple[Ellipse, FloatArray] | None, shift: FloatArray | None,
                predicted: FloatArray) -> tuple[float, bool, Candidate] | None:
        """``cand``'s distance from the ``predicted`` measurement, whether the image border
        cuts its ellipse, and the candidate as measured (its centre moved by ``shift``, px,
        to the image of the face centre); None if it cannot be the tracked face.

        ``expected``: the tracked face's ellipse and centre pixel in ``obs``
        (:meth:`expected_ellipse`), or None.
        """
        e = cand.ellipse
        cut = e is not None and not ellipse_inside(e, self.k, EDGE_MARGIN_PX)
        if cut and (e is None or expected is None or not self._usable_cut(e)):
            return None  # a face cut by the image border gives a biased ellipse
        tolerance = CUT_SIZE_TOLERANCE if cut else SIZE_TOLERANCE
        if (e is not None and expected is not None
                and abs(e.a - expected[0].a) > tolerance * expected[0].a):
            return None  # not the tracked face's size: a smaller face, a wall, a fragment
        # Before the filter is set the normal is one view's (two-fold ambiguous): a
        # candidate with a pose of its own keeps its own centre.
        if (shift is not None and e is not None
                and (self.tracker.initialised or cand.centre_cam is None)):
            cand = replace(cand, pixel=np.array([e.cx, e.cy]) + shift)
        try:
            z = self._measurement(obs, cand.pixel)
        except EstimationError:
            return None
        return float(np.linalg.norm(z - predicted)), cut, cand

    def expected_ellipse(self, obs: Observation) -> tuple[Ellipse, FloatArray] | None:
        """The tracked face as ``obs``'s camera should see it: its ellipse and the (2,) pixel
        of its centre, from the estimate; None before the first detection (belt frame) or
        before the filter is set (image frame).

        The ellipse's size tells the tracked face from other faces near the prediction.
        Perspective moves an ellipse's centre off the image of the circle's centre; with
        the tracked normal (a consensus over frames) this shift is steadier than each
        frame's own pose. Before the filter is set (belt frame) the face is where the belt
        carries the first detection: later frames see a tilted face's ellipse centre
        several mm off its centre (on a fast belt the later views may all be cut by the
        border, without a pose of their own, and would then never be associated).
        """
        if self.radius is None:
            return None
        if self.tracker.initialised:
            state = self.state(obs.capture_time, obs.world_T_cam)
            centre, normal = state.centre, state.normal
        elif self.frame == "belt" and self._last is not None:
            t0, z0 = self._last
            xy = z0 + self._belt_v * (obs.capture_time - t0)
            centre, normal = np.array([xy[0], xy[1], self.face_z]), self.normal
        else:
            return None
        r, p = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        c_cam, n_cam = r.T @ (centre - p), r.T @ normal
        try:
            e = project_circle(c_cam, n_cam, self.radius, self.k)
        except ValueError:
            return None
        return e, np.asarray(self.k.project(c_cam)[0])

    def state(self, t: float, world_T_cam_now: FloatArray) -> TargetState:
        """The face predicted at sim time ``t`` s (Eq. 4); needs :attr:`initialised`."""
        pred = self.tracker.predict_at(t)
        z = self.face_z
        if self.frame == "belt":
            centre = np.array([pred.position[0], pred.position[1], z])
            velocity = np.array([pred.velocity[0], pred.velocity[1], 0.0])
        else:  # the pixels are those of the reference pose, not of the camera now
            assert self._ref_T_cam is not None
            plane = np.array([0.0, 0.0, z])
            centre = backproject_to_plane(pred.position.reshape(1, 2), self.k, self._ref_T_cam,
                                          plane)[0]
            g = plane_backprojection_jacobian(pred.position, self.k, self._ref_T_cam, plane)
            velocity = g @ pred.velocity
        return TargetState(centre=centre, velocity=velocity, normal=self.normal)

    def _plane(self) -> FloatArray:
        return np.array([0.0, 0.0, self.face_z])

    def _metres_per_unit(self, world_T_cam: FloatArray, z: FloatArray) -> float:
        """Size of one measurement unit on the face plane, m: 1 (belt), m/px (image)."""
        if self.frame == "belt":
            return 1.0
        try:
            g = plane_backprojection_jacobian(z, self.k, world_T_cam, self._plane())[:2]
        except EstimationError:
            return float("inf")
        return float(np.sqrt(abs(np.linalg.det(g))))

    def _to_view(self, z: FloatArray, from_T_cam: FloatArray,
                 to_T_cam: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Image frame: pixel ``z`` of pose ``from_T_cam`` in the image of ``to_T_cam``."""
        return transfer_via_plane(z, self.k, from_T_cam, to_T_cam, self._plane())

    def _predicted_measurement(self, obs: Observation) -> FloatArray:
        t = obs.capture_time
        if self.tracker.initialised:
            pos = np.asarray(self.tracker.predict_at(t).position)
            if self.frame == "image":
                assert self._ref_T_cam is not None
                pos = self._to_view(pos, self._ref_T_cam, obs.world_T_cam)[0]
            return pos
        if self._last is None:
            raise EstimationError("no measurement yet to associate with")
        t0, z0 = self._last
        if self.frame == "belt":
            return z0 + self._belt_v * (t - t0)
        assert self._first is not None
        point = backproject_to_plane(z0.reshape(1, 2), self.k, self._first[3], self._plane())
        point[0, :2] += self._belt_v * (t - t0)
        return np.asarray(project_to_pixels(point, self.k, obs.world_T_cam)[0])

    def _into_view(self, obs: Observation) -> None:
        """Image frame: predict the filter to ``obs``'s capture and carry it into its image."""
        if not self.tracker.initialised or self._ref_T_cam is None:
            return
        pos = self.tracker.predict_at(obs.capture_time).position
        s = self._metres_per_unit(self._ref_T_cam, pos)
        if not self.tracker.advance(obs.capture_time, self._accel_psd / s**2):
            return
        pos, jac = self._to_view(self.tracker.predict_at(obs.capture_time).position,
                                 self._ref_T_cam, obs.world_T_cam)
        self.tracker.transform(pos, jac)
        self._ref_T_cam = obs.world_T_cam

    def _measurement(self, obs: Observation, pixel: FloatArray) -> FloatArray:
        if self.frame == "image":
            return np.asarray(pixel, dtype=float)
        plane = np.array([0.0, 0.0, self.face_z])
        return backproject_to_plane(np.reshape(pixel, (1, 2)), self.k, obs.world_T_cam,
                                    plane)[0, :2]

    def _usable_cut(self, e: Ellipse) -> bool:
        """Whether a face cut by the image border still has its centre well inside the image
        (at least about half its outline in view, enough for a fit of known size)."""
        m = EDGE_MARGIN_PX
        return (m <= e.cx <= self.k.width - 1 - m and m <= e.cy <= self.k.height - 1 - m)

    def _covariance(self, obs: Observation, cand: Candidate, sigma: float) -> FloatArray:
        """The measurement's covariance in the tracker's frame: the pixel noise ``sigma`` (px)
        and the face's wobble on the belt (``FACE_WOBBLE_STD``, m), one of them carried
        through the back-projection's Jacobian."""
        if self.frame == "belt":
            g = plane_backprojection_jacobian(cand.pixel, self.k, obs.world_T_cam,
                                              np.array([0.0, 0.0, self.face_z]))[:2]
            return sigma**2 * g @ g.T + FACE_WOBBLE_STD**2 * np.eye(2)
        px_per_m = np.linalg.inv(plane_backprojection_jacobian(
            cand.pixel, self.k, obs.world_T_cam, self._plane())[:2])
        return sigma**2 * np.eye(2) + FACE_WOBBLE_STD**2 * px_per_m @ px_per_m.T

    def _step(self, obs: Observation, z: FloatArray, r: FloatArray) -> UpdateResult:
        """One tracker step on measurement ``z`` (covariance ``r``): an update, or in the
        image frame the two-point start from the kept first measurement, carried into this
        frame's view; keeps or drops that first measurement by the step's outcome."""
        if self.frame == "image" and not self.tracker.initialised and self._first is not None:
            # The two-point start differences pixels: both must be of this frame's pose.
            t0, z0, r0, pose0 = self._first
            z0v, jac = self._to_view(z0, pose0, obs.world_T_cam)
            result = self.tracker.restart(t0, z0v, jac @ r0 @ jac.T, obs.capture_time, z, r)
        else:
            result = self.tracker.update(obs.capture_time, z, r)
        if self.frame == "image":
            if result.reason.startswith("initialised"):
                self._ref_T_cam = obs.world_T_cam
                self._first = None
            elif not result.reason.startswith("initialising: need"):
                self._first = (obs.capture_time, z, r, obs.world_T_cam)
        return result

    def _fuse(self, obs: Observation, cand: Candidate, pixel_std: float | None = None) -> bool:
        first = not self._zs and cand.centre_cam is not None
        if first:
            self._add_pose(obs, cand)  # the plane height is needed to back-project
        z = self._measurement(obs, cand.pixel)
        r = self._covariance(obs, cand, self.pixel_std if pixel_std is None else pixel_std)
        if self.frame == "image":
            self._into_view(obs)
        result = self._step(obs, z, r)
        self.nis += min(result.mahalanobis_sq, self.tracker.config.gate_chi2)
        # A measurement the tracker keeps as the first of its start is the track's latest.
        accepted = bool(result) or result.reason.startswith(("initialising: first",
                                                             PRIOR_RESTART))
        if result.reason.startswith("gated"):
            self._rejected = [*self._rejected[-(REACQUIRE_AFTER - 1):],
                              (obs.capture_time, z, r, obs.world_T_cam)]
            accepted = self._reacquire()
        else:
            self._rejected = []
        if accepted:
            self._last = (obs.capture_time, z)
            self.last_candidate = cand
            self.fused += 1
            self.last_fused_time = obs.capture_time
            if not first and pixel_std is None:  # a pose fitted on a partial outline is not
                self._add_pose(obs, cand)        # trusted for the face's height and normal
        return accepted

    def _reacquire(self) -> bool:
        """Restart the filter on a consistent run of gated-out measurements; True if done."""
        if len(self._rejected) < REACQUIRE_AFTER:
            return False
        (t0, z0, _, p0), (t1, z1, r1, p1), (t2, z2, r2, p2) = self._rejected[-3:]
        if self.frame == "image":  # all three in the newest frame's image
            try:
                z0 = self._to_view(z0, p0, p2)[0]
                z1, jac = self._to_view(z1, p1, p2)
            except EstimationError:
                return False
            r1 = jac @ r1 @ jac.T
        line = z1 + (z1 - z0) * (t2 - t1) / max(t1 - t0, 1e-9)
        predicted = self.tracker.predict_at(t2).position  # already in p2's image
        unit = self._metres_per_unit(p2, z2)
        if (np.linalg.norm(z2 - line) * unit > REACQUIRE_TOLERANCE
                or np.linalg.norm(z2 - predicted) * unit > REACQUIRE_GATE):
            return False
        self.tracker.restart(t1, z1, r1, t2, z2, r2)
        self._rejected = []
        self.reacquired += 1
        return self.tracker.initialised

    def _add_pose(self, obs: Observation, cand: Candidate) -> None:
        r_wc, p_wc = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        height = None
        if cand.centre_cam is not None:
            # A monocular pose is known up to scale: put the face at this track's radius.
            scale = self.radius / cand.radius if self.radius and cand.radius > 0 else 1.0
            height = float((r_wc @ (cand.centre_cam * scale) + p_wc)[2])
            self._zs.append(height)
        if not self.correct_centres or cand.ellipse is None or not self.radius:
            if cand.normal_cam is not None:  # exact normals (oracle): largest agreeing group
                self._add_normal(r_wc @ cand.normal_cam)
            return
        self._vote(obs.world_T_cam, cand, cand.ellipse, height)

    def _vote(self, world_T_cam: FloatArray, cand: Candidate, e: Ellipse,
              height: float | None) -> None:
        """Add the view ``world_T_cam`` of fit ``e`` to the normal's vote
        (:meth:`_add_normals`); ``height``: the detector's pose's face height (m), or None:
        the fit's own at the track's radius."""
        assert self.radius is not None
        r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
        sight = r_wc @ np.linalg.solve(self.k.K, np.array([e.cx, e.cy, 1.0]))
        try:
            poses = circle_poses(e, self.k, self.radius)
        except (ValueError, np.linalg.LinAlgError):
            return
        sols = [np.asarray(sol.normal_cam) for sol in poses]
        if height is None:  # both solutions' heights, nearly one
            height = float(np.mean([(r_wc @ np.asarray(sol.centre_cam) + p_wc)[2]
                                    for sol in poses]))
        chosen = None
        if cand.normal_cam is not None:
            chosen = int(np.argmax([float(n @ cand.normal_cam) for n in sols]))
        normals = np.array([r_wc @ n for n in sols])
        self._add_normals(NormalView(
            normals=normals / np.linalg.norm(normals, axis=1, keepdims=True), chosen=chosen,
            height=height, sight=sight / float(np.linalg.norm(sight))))

    def _add_normal(self, n: FloatArray) -> None:
        self._normals.append(n / float(np.linalg.norm(n)))
        normals = np.array(self._normals)
        agree = normals @ normals.T >= np.cos(np.radians(NORMAL_AGREEMENT_DEG))
        best = int(np.argmax(agree.sum(axis=1)))  # first of the largest group: deterministic
        mean = normals[agree[best]].sum(axis=0)
        self._normal = mean / float(np.linalg.norm(mean))

    def _add_normals(self, view: NormalView) -> None:
        """Add one view's two world normal solutions; update the consensus :attr:`normal`.

        A face's pose from one view is two-fold ambiguous. The right normal is the same
        from every line of sight; the wrong one turns with it. So, over views from lines of
        sight at least VOTE_SIGHT_DEG apart, the normal is the solution the most views
        share (within NORMAL_AGREEMENT_DEG), ties going to the one the detector picked most
        often (its wall-colour test), then to the earliest; the mean of each view's nearest
        agreeing solution. Only views whose height lies within
        ``episode.normal_vote_height_tol`` of the face height (:attr:`face_z`) vote (when
        none does, the one nearest it): a fit that reads the face too high takes in its side
        wall, and its outline's shape, tilted by the wall, gives both normal solutions off
        the face's. Of the views along one line of sight the first of them votes.
        """
        self._normal_views.append(view)
        voters = [(v.normals, v.chosen) for v in normal_voters(
            self._normal_views, self.face_z, self._vote_height_tol)]
        normals = view.normals
        cos_min = np.cos(np.radians(NORMAL_AGREEMENT_DEG))
        best_key: tuple[int, int] | None = None
        best_mean = normals[0]
        for cand in np.concatenate([v for v, _ in voters]):
            support = picked = 0
            total = np.zeros(3)
            for views, pick in voters:
                c = views @ cand
                j = int(np.argmax(c))
                if c[j] >= cos_min:
                    support += 1
                    picked += int(pick == j)
                    total += views[j]
            key = (support, picked)
            if best_key is None or key > best_key:
                best_key, best_mean = key, total
        self._normal = best_mean / float(np.linalg.norm(best_mean))

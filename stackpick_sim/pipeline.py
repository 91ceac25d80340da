"""The three seams of a pick episode: Detector, Estimator, Controller.

An episode (:mod:`stackpick_sim.episodes.episode`) captures a wrist-camera frame every
``1 / camera.fps`` s, hands it to a **Detector**, feeds the detector's face candidates, once
their latency has passed, to an **Estimator** that tracks the face to pick, and asks a
**Controller** for the arm's joint velocities during the approach, the servo and the
descent. The phase machine (transitions, time-outs, grasp, lift, verify) and the judging of
the outcome stay the episode's own.

Each stage is chosen by name (``stackpick run --detector NAME --estimator NAME
--controller NAME`` or the scene's ``[episode]`` section): a built-in, ``module:attr`` (a
class or factory taking the scene config) or an entry point of the groups
``stackpick_sim.detectors``, ``stackpick_sim.estimators``, ``stackpick_sim.controllers``
(:mod:`stackpick_sim.registry`). A stage's ``name`` and optional ``version`` go into every
record. Ground truth is never passed through these interfaces: only the built-in ``oracle``
detector is handed the cell's truth, through its constructor.

Frames: ``*_cam`` is the OpenCV camera frame (x right, y down, z forward, metres);
``world_T_cam`` (4, 4) the camera pose in the world at capture (forward kinematics); world
z is up, the belt runs along world +y.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse

if TYPE_CHECKING:
    from stackpick_sim.episodes.arm import ArmController

FloatArray = NDArray[np.float64]

__all__ = ["ControlGoal", "Controller", "Detections", "Detector", "Estimator", "FaceCandidate",
           "Frame", "Hints", "TargetState"]


@dataclass(frozen=True, kw_only=True)
class Frame:
    """What a detector may see of one capture."""

    image: NDArray[np.uint8] | None
    """(H, W, 3) RGB wrist-camera image with the scene's noise; None for a detector that
    does not need it (``needs_image = False``)."""
    intrinsics: CameraIntrinsics
    world_T_cam: FloatArray
    """(4, 4) camera pose at capture."""
    time: float
    """Capture time, s of sim time since the episode's first frame."""


@dataclass(frozen=True, kw_only=True)
class Hints:
    """What the episode already believes about the face it tracks (all None before)."""

    expected_depth_m: float | None = None
    """Predicted depth of the tracked face's centre in this frame, m."""
    reference_normal_cam: FloatArray | None = None
    """(3,) tracked face's unit inward normal, camera frame."""
    expected_ellipse: Ellipse | None = None
    """The tracked face's predicted ellipse in this frame, px."""
    target: FaceCandidate | None = None
    """The candidate the track started from (None while the episode looks for the top)."""


@dataclass(frozen=True, kw_only=True)
class FaceCandidate:
    """One face seen in a frame: centre pixel, optional pose, the ellipse it came from."""

    pixel: FloatArray
    """(2,) face-centre pixel (u, v) (perspective-corrected when a pose is known)."""
    normal_cam: FloatArray | None
    """(3,) unit inward face normal (pointing into the object), camera frame, or None."""
    centre_cam: FloatArray | None
    """(3,) face centre, camera frame, m, or None."""
    radius: float
    """Face radius the pose assumes, m (0 when unknown)."""
    is_top: bool
    """The detector's choice of the object to pick; the track starts from the first
    frame's top candidate that carries a pose (normal and centre)."""
    ellipse: Ellipse | None


@dataclass(frozen=True, kw_only=True)
class Detections:
    """A detector's answer for one frame; falsy (with a ``reason``) when it found nothing."""

    candidates: tuple[FaceCandidate, ...] = ()
    reason: str = ""
    """Why nothing (or nothing usable) was found; free text for the record and replays."""
    raw: object = None
    """The detector's own result object, kept for replays (e.g. our vision Detection)."""

    def __bool__(self) -> bool:
        return bool(self.candidates)


@dataclass(frozen=True, kw_only=True)
class TargetState:
    """The tracked face at one instant: centre (3,) m, velocity (3,) m/s, unit inward normal
    (3,), world frame."""

    centre: FloatArray
    velocity: FloatArray
    normal: FloatArray


@runtime_checkable
class Detector(Protocol):
    """Frame + hints -> face candidates.

    ``needs_image``: False lets a detector that does not look at pixels skip rendering.
    ``exact``: True for ground truth (the estimator then trusts its poses and radius
    exactly, and its top choice is not put to the vote of later frames).
    """

    name: str
    needs_image: bool
    exact: bool

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        """The faces in ``frame``; mark the one to pick ``is_top``."""
        ...


class Observation(Protocol):
    """What an estimator receives: a frame's candidates with its capture time and pose (see
    :class:`stackpick_sim.episodes.sensing.Observation`)."""

    @property
    def capture_time(self) -> float: ...

    @property
    def world_T_cam(self) -> FloatArray: ...

    @property
    def candidates(self) -> tuple[FaceCandidate, ...]: ...


@runtime_checkable
class Estimator(Protocol):
    """Tracks the face to pick from late, noisy detections and predicts it at any time."""

    name: str

    def start(self, obs: Observation, cand: FaceCandidate) -> None:
        """Begin a track on ``cand`` (a posed candidate of ``obs``)."""
        ...

    def offer(self, obs: Observation) -> bool:
        """Associate a candidate of a later frame with the track and fuse it; True if used."""
        ...

    def state(self, t: float, world_T_cam_now: FloatArray) -> TargetState:
        """The face predicted at sim time ``t`` s (valid once :attr:`initialised`)."""
        ...

    def reset(self) -> None:
        """Forget the track (the episode detects again)."""
        ...

    @property
    def initialised(self) -> bool:
        """A prediction is available (position and velocity known)."""
        ...

    @property
    def lost(self) -> bool:
        """The track is lost (the episode fails with ``lost_track``)."""
        ...

    @property
    def fused(self) -> int:
        """Detections fused so far (the approach starts after ``episode.track_frames``)."""
        ...

    @property
    def last_fused_time(self) -> float | None:
        """Capture time of the latest fused detection, s."""
        ...

    @property
    def radius(self) -> float | None:
        """Radius of the tracked face, m."""
        ...

    @property
    def face_z(self) -> float:
        """Predicted height of the face centre, world z, m."""
        ...

    @property
    def lowest_face_z(self) -> float:
        """Lowest height the face centre was seen at, world z, m (bounds the descent)."""
        ...


@dataclass(frozen=True, kw_only=True)
class ControlGoal:
    """Where the tool should go this control tick."""

    phase: str
    """``approach``, ``servo`` or ``descend``."""
    target: TargetState
    """The face predicted to now, its centre moved to the point the cup aims at (off a tape
    roll's hole: :mod:`stackpick_sim.control.pick_point`) and its normal replaced by the
    tool axis to take."""
    lead: TargetState | None
    """Approach only: the target, predicted ``1 / episode.approach_gain`` s ahead."""
    standoff: float
    """Commanded distance tool tip to the target's centre along the axis, m (falls in the
    descent)."""
    standoff_rate: float
    """Its rate of change, m/s (minus the descent speed while descending)."""
    dt: float
    """Control period, s."""


@runtime_checkable
class Controller(Protocol):
    """Goal + arm -> (6,) joint velocities, rad/s, for this control tick.

    ``arm`` is the episode's :class:`stackpick_sim.episodes.arm.ArmController`: joint
    angles (``q_cmd``, ``full_qpos()``), tool and camera poses (``command_world_T_tool()``,
    ``eih.world_T_cam(arm.cell.data)``), the image Jacobian (``eih``) and speed limits
    (``executor.speed_limit``). The episode clips the command to the joint ranges.
    """

    name: str

    def command(self, goal: ControlGoal, arm: ArmController) -> FloatArray:
        ...

"""The wrist camera as the controller sees it: frames at a fixed rate, detections that arrive late.

A frame is captured every ``1 / camera.fps`` s of sim time (at the first control tick at or
after its due time). Its detection becomes usable ``camera.latency_s`` later (the measured
vision latency, a constant: the wall clock never enters an episode). Two detectors:

* ``ours``: the rendered RGB frame (with the scene's pixel noise and light jitter) through
  :func:`stackpick_sim.vision.detect`; every detected ellipse is a candidate, the detector's
  top one carries its pose.
* ``oracle``: ground truth, no image needed: the face of the object being tracked, exact,
  whenever its face centre lies inside the image (a camera cannot see beyond its border; our
  detector, too, fits a face the border cuts); its first choice must lie wholly inside. It
  isolates control and estimation from vision.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, face_depth_range, project_circle
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.cell import Cell, ObjectInfo
from stackpick_sim.sim.ground_truth import top_face
from stackpick_sim.vision import Detection, DetectorConfig, circle_poses, detect
from stackpick_sim.vision.detector import object_kinds
from stackpick_sim.vision.limits import WorkLimits
from stackpick_sim.vision.moving_edges import track_outline
from stackpick_sim.vision.pose import CirclePose
from stackpick_sim.vision.undistort import undistort

FloatArray = NDArray[np.float64]

#: How far (px) the tracked face's outline is searched for around its predicted ellipse
#: (prediction error plus the face's motion between the tick of the prediction and the
#: capture: ~3 px at 0.3 m/s). Placeholder.
TRACKED_SEARCH_PX = 6.0
#: Faces smaller than this (semi-major axis, px) are not searched for: too few pixels.
MIN_TRACKED_AXIS_PX = 8.0
#: Once a face is tracked its depth is predicted; the detector is told this range around it.
TRACKED_DEPTH_MARGIN = 0.25


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """One face seen in a frame: centre pixel, optional pose, the ellipse it came from."""

    pixel: FloatArray
    """(2,) face-centre pixel (u, v) (perspective-corrected when a pose is known)."""
    normal_cam: FloatArray | None
    """(3,) unit inward face normal, camera frame, or None."""
    centre_cam: FloatArray | None
    """(3,) face centre, camera frame, m, or None."""
    radius: float
    """Face radius the pose assumes, m."""
    is_top: bool
    """The detector called it the top object."""
    ellipse: Ellipse | None


@dataclass(frozen=True, kw_only=True)
class Observation:
    """One frame's detections, with the camera pose and time of its capture."""

    capture_time: float
    available_time: float
    world_T_cam: FloatArray
    """(4, 4) camera pose at capture (forward kinematics), OpenCV axes."""
    candidates: tuple[Candidate, ...]
    detection: Detection | None
    """The vision result (``ours`` only)."""
    image: NDArray[np.uint8] | None
    """The RGB frame, when images are kept (replay) or rendered (``ours``)."""
    reason: str = ""


def oracle_candidate(cell: Cell, obj: ObjectInfo, world_T_cam: FloatArray,
                     whole: bool = True) -> Candidate | None:
    """The true face of ``obj`` seen from ``world_T_cam``, or None if its ellipse is not wholly
    in the image (``whole``) or, else, if its face centre is not."""
    k: CameraIntrinsics = cell.intrinsics
    r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
    centre_w, normal_w = top_face(cell, obj, p_wc)
    centre_c = r_wc.T @ (centre_w - p_wc)
    inward_c = -(r_wc.T @ normal_w)
    try:
        ellipse = project_circle(centre_c, inward_c, obj.radius, k)
    except ValueError:
        return None
    pixel = k.project(centre_c)[0]
    # The extent that must lie in the image: the whole ellipse, or the centre pixel alone.
    u0, v0, u1, v1 = ellipse.bounds() if whole else (*pixel, *pixel)
    if u0 < 0 or v0 < 0 or u1 > k.width - 1 or v1 > k.height - 1:
        return None
    return Candidate(pixel=pixel, normal_cam=inward_c, centre_cam=centre_c,
                     radius=obj.radius, is_top=True, ellipse=ellipse)


def detection_candidates(det: Detection, k: CameraIntrinsics, radius: float | None,
                         reference_normal_cam: FloatArray | None) -> tuple[Candidate, ...]:
    """Candidates of a vision result: the top face with its pose, the other ellipses too.

    Other ellipses get the circle-pose solution (for ``radius``, m) whose normal is nearest
    ``reference_normal_cam`` (the tracked face's normal), when both are known.
    """
    out: list[Candidate] = []
    for i, de in enumerate(det.ellipses):
        if i == det.top and det.pose is not None:
            p = det.pose
            out.append(Candidate(pixel=np.array([p.x, p.y]), normal_cam=np.asarray(p.normal_cam),
                                 centre_cam=np.asarray(p.centre_cam), radius=p.radius_m,
                                 is_top=True, ellipse=de.ellipse))
            continue
        normal = centre = None
        pixel = np.array([de.ellipse.cx, de.ellipse.cy])
        if radius is not None and reference_normal_cam is not None:
            try:
                sols: Sequence[CirclePose] = circle_poses(de.ellipse, k, radius)
            except (ValueError, np.linalg.LinAlgError):
                sols = ()
            if sols:
                best = max(sols, key=lambda s: float(s.normal_cam @ reference_normal_cam))
                normal, centre = np.asarray(best.normal_cam), np.asarray(best.centre_cam)
                pixel = k.project(centre)[0]
        out.append(Candidate(pixel=pixel, normal_cam=normal, centre_cam=centre,
                             radius=radius or 0.0, is_top=False, ellipse=de.ellipse))
    return tuple(out)


class Sensor:
    """Captures frames at the camera rate and releases their detections after the latency."""

    def __init__(self, cell: Cell, camera: WristCamera | None, rng: np.random.Generator, *,
                 detector: str, keep_images: bool = False) -> None:
        self._cell = cell
        self._camera = camera
        self._rng = rng
        self.detector = detector
        self.keep_images = keep_images
        self.period = 1.0 / cell.cfg.camera.fps
        self.latency = cell.cfg.camera.latency_s
        self._next_capture = 0.0
        self._frame_index = 0
        self._pending: deque[Observation] = deque()
        self.target: ObjectInfo | None = None
        """Object the oracle reports (set after the first detection)."""
        self.radius: float | None = None
        """Face radius of the tracked object (narrows the detector's radius choice)."""
        self.expected_depth: float | None = None
        """Predicted depth of the tracked face, m (narrows the detector's depth range)."""
        self.reference_normal_cam: FloatArray | None = None
        self.expected_ellipse: Ellipse | None = None
        """The tracked face's predicted ellipse in the next frame (set before its capture):
        where the detector misses it, its outline is searched for around this
        (:func:`~stackpick_sim.vision.moving_edges.track_outline`)."""
        self.frames = 0
        self.processed = 0
        """Frames rendered and run through the detector (or the oracle)."""
        self.process = True
        """Whether the next frame is processed; the phase logic clears it for frames the
        controller would not use (after the servo, or with the tracked face out of view)."""
        self.wall = {"render": 0.0, "vision": 0.0}
        types = [cell.cfg.object_types[name] for name in cell.cfg.objects.types]
        self._radii, colours, heights = object_kinds(
            [(t.radius, t.rgba[:3], t.height) for t in types])
        self._colours = None if colours is None else dict(zip(self._radii, colours, strict=True))
        """Colour of each radius's kind, when the kinds differ in colour."""
        self._heights = None if heights is None else dict(zip(self._radii, heights, strict=True))
        """Cylinder height of each radius's kind, when each radius has one."""

    def due(self, t: float) -> bool:
        """Whether a frame is due at sim time ``t`` s."""
        return t >= self._next_capture - 1e-9

    def capture(self, t: float, world_T_cam: FloatArray) -> None:
        """Capture a frame now (state after mj_forward) and queue its detection."""
        self._frame_index += 1
        self._next_capture = self._frame_index * self.period
        self.frames += 1
        image = None
        if not self.process:
            if self.keep_images:  # replay: a clean picture, the noise stream left untouched
                assert self._camera is not None, "rendering needs a WristCamera"
                image = self._camera.render()
            self._pending.append(Observation(
                capture_time=t, available_time=t + self.latency, world_T_cam=world_T_cam.copy(),
                candidates=(), detection=None, image=image,
                reason="not processed: the controller does not use this frame"))
            return
        self.processed += 1
        if self.detector == "ours" or self.keep_images:
            assert self._camera is not None, "rendering needs a WristCamera"
            start = time.perf_counter()
            image = self._camera.render(self._rng)
            self.wall["render"] += time.perf_counter() - start
        detection = None
        reason = ""
        start = time.perf_counter()
        if self.detector == "oracle":
            cands: tuple[Candidate, ...] = ()
            if self.target is not None:
                c = oracle_candidate(self._cell, self.target, world_T_cam, whole=False)
                cands = (c,) if c is not None else ()
                reason = "" if cands else "the tracked face's centre is not in the image"
        else:
            assert image is not None
            detection = detect(image, self._config())
            cands = detection_candidates(detection, self._cell.intrinsics, self.radius,
                                         self.reference_normal_cam)
            reason = detection.reason
            tracked = self._tracked_outline(image, cands)
            if tracked is not None:
                cands = (*cands, tracked)
        self.wall["vision"] += time.perf_counter() - start
        self._pending.append(Observation(
            capture_time=t, available_time=t + self.latency, world_T_cam=world_T_cam.copy(),
            candidates=cands, detection=detection,
            image=image if self.keep_images else None, reason=reason))

    def _tracked_outline(self, image: NDArray[np.uint8],
                         cands: tuple[Candidate, ...]) -> Candidate | None:
        """A candidate from the predicted face's outline, when no detection resembles it."""
        e = self.expected_ellipse
        if e is None or e.a < MIN_TRACKED_AXIS_PX:
            return None
        for c in cands:
            d = c.ellipse
            if (d is not None and math.hypot(d.cx - e.cx, d.cy - e.cy) < TRACKED_SEARCH_PX
                    and abs(d.a - e.a) < TRACKED_SEARCH_PX):
                return None  # the detector found it: its fit is the better one
        pinhole = undistort(image, self._cell.intrinsics)  # the predicted ellipse's pixels
        gray = np.asarray(cv2.GaussianBlur(cv2.cvtColor(pinhole, cv2.COLOR_RGB2GRAY)
                                           .astype(np.float32), (3, 3), 0), dtype=np.float32)
        fit = track_outline(gray, e, TRACKED_SEARCH_PX)
        if fit is None:
            return None
        return Candidate(pixel=np.array([fit.cx, fit.cy]), normal_cam=None, centre_cam=None,
                         radius=self.radius or 0.0, is_top=False, ellipse=fit)

    def ready(self, t: float) -> list[Observation]:
        """Observations whose detection is usable at sim time ``t`` s, oldest first."""
        out = []
        while self._pending and self._pending[0].available_time <= t + 1e-9:
            out.append(self._pending.popleft())
        return out

    def _config(self) -> DetectorConfig:
        cfg = self._cell.cfg
        if self.expected_depth is None:  # at the look pose
            depth = face_depth_range(cfg.camera.look_height, cfg.objects.max_face_height)
        else:
            depth = (self.expected_depth * (1 - TRACKED_DEPTH_MARGIN),
                     self.expected_depth * (1 + TRACKED_DEPTH_MARGIN))
        radii = (self.radius,) if self.radius is not None else self._radii
        known = self._colours or {}
        colours = tuple(known[r] for r in radii) if all(r in known for r in radii) else None
        tall = self._heights or {}
        heights = tuple(tall[r] for r in radii) if all(r in tall for r in radii) else None
        return DetectorConfig(intrinsics=self._cell.intrinsics, radii_m=radii,
                              kind_colours=colours, heights_m=heights,
                              depth_range_m=(max(depth[0], 1e-3), max(depth[1], 2e-3)),
                              limits=WorkLimits.of(cfg.vision),
                              marking_depth_ratio=cfg.vision.marking_depth_ratio,
                              marking_min_edge_share=cfg.vision.marking_min_edge_share)


def ellipse_inside(e: Ellipse, k: CameraIntrinsics, margin_px: float = 0.0) -> bool:
    """Whether the whole ellipse lies inside the image, ``margin_px`` px from its border."""
    u0, v0, u1, v1 = e.bounds()
    return (u0 >= margin_px and v0 >= margin_px and u1 <= k.width - 1 - margin_px
            and v1 <= k.height - 1 - margin_px)


def angle_deg(a: FloatArray, b: FloatArray) -> float:
    """Angle between two vectors, degrees."""
    c = float(a @ b) / (float(np.linalg.norm(a)) * float(np.linalg.norm(b)))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))

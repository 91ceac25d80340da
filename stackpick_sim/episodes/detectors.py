"""The built-in detectors of an episode (:class:`stackpick_sim.pipeline.Detector`).

* ``ours``: the rendered frame through :func:`stackpick_sim.vision.detect`; every detected
  ellipse is a candidate, the detector's top one carries its pose; where the detector misses
  the tracked face, its outline is searched for around the predicted ellipse.
* ``rht``, ``findellipses``: a baseline ellipse detector (the paper's randomized Hough
  transform; OpenCV's ``findEllipses``), then our top rule (markings inside a face included)
  and pose solver, as in
  ``stackpick bench-detect``: the paper's comparison in closed loop.
* ``oracle``: ground truth, no image needed (:mod:`stackpick_sim.episodes.audit` hands it the
  cell's truth): while the episode looks for the top, the flattest true top face wholly in
  view (the easiest pick; a face the border cuts would have the arm wait for it, belt
  running); once tracking, that object's face, exact, whenever its centre lies inside the
  image. It isolates control and estimation from vision.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.config.vision_params import OutlineTrackingParams
from stackpick_sim.episodes.audit import CellTruth
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, face_depth_range
from stackpick_sim.pipeline import Detections, FaceCandidate, Frame, Hints
from stackpick_sim.vision import Detection, DetectorConfig, detect
from stackpick_sim.vision.baselines import EllipseDetector, FindEllipsesDetector, RHTDetector
from stackpick_sim.vision.detector import marking_test, object_kinds, radius_by_colour
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.moving_edges import track_outline
from stackpick_sim.vision.occlusion import select_top
from stackpick_sim.vision.pose import Pose, estimate_pose
from stackpick_sim.vision.roi import find_roi
from stackpick_sim.vision.undistort import undistort

FloatArray = NDArray[np.float64]

#: The tracking mode's default outline search (see OutlineTrackingParams).
DEFAULT_OUTLINE = OutlineTrackingParams()


def scene_detector_config(cfg: SceneConfig, intrinsics: CameraIntrinsics,
                          depth_range_m: tuple[float, float] | None) -> DetectorConfig:
    """The vision pipeline's settings from a scene: its object kinds (radii, colours, heights)
    and ``[vision]`` table (limits, marking test, the stages' sections), for a top face
    expected at ``depth_range_m`` (min, max) m."""
    types = [cfg.object_types[name] for name in cfg.objects.types]
    radii, colours, heights = object_kinds([(t.radius, t.rgba[:3], t.height) for t in types],
                                           cfg.vision.top.kind_min_chroma_distance)
    return DetectorConfig(intrinsics=intrinsics, radii_m=radii, kind_colours=colours,
                          heights_m=heights, depth_range_m=depth_range_m
                          ).with_vision(cfg.vision)


def detector_config(cfg: SceneConfig, intrinsics: CameraIntrinsics,
                    hints: Hints) -> DetectorConfig:
    """What the scene and the track tell the vision pipeline: the scene's settings
    (:func:`scene_detector_config`) and the depth range of the face (at the look pose, or
    around the tracked one: ``episode.tracked_depth_margin``)."""
    if hints.expected_depth_m is None:  # at the look pose
        depth = face_depth_range(cfg.camera.look_height, cfg.objects.max_face_height)
    else:
        d, margin = hints.expected_depth_m, cfg.episode.tracked_depth_margin
        depth = (d * (1 - margin), d * (1 + margin))
    return scene_detector_config(cfg, intrinsics, (max(depth[0], 1e-3), max(depth[1], 2e-3)))


def detection_candidates(det: Detection) -> tuple[FaceCandidate, ...]:
    """Candidates of a vision result: the top face with its pose, the other ellipses too."""
    out: list[FaceCandidate] = []
    for i, de in enumerate(det.ellipses):
        if i == det.top and det.pose is not None:
            out.append(posed_candidate(det.pose, de.ellipse))
            continue
        out.append(other_candidate(de.ellipse))
    return tuple(out)


def posed_candidate(p: Pose, ellipse: Ellipse) -> FaceCandidate:
    """The top candidate of a pose."""
    return FaceCandidate(pixel=np.array([p.x, p.y]), normal_cam=np.asarray(p.normal_cam),
                         centre_cam=np.asarray(p.centre_cam), radius=p.radius_m, is_top=True,
                         ellipse=ellipse)


def other_candidate(ellipse: Ellipse) -> FaceCandidate:
    """A face that is not the detector's top: its ellipse alone (no pose)."""
    return FaceCandidate(pixel=np.array([ellipse.cx, ellipse.cy]), normal_cam=None,
                         centre_cam=None, radius=0.0, is_top=False, ellipse=ellipse)


def tracked_outline(image: NDArray[np.uint8], intrinsics: CameraIntrinsics, hints: Hints,
                    cands: tuple[FaceCandidate, ...],
                    params: OutlineTrackingParams = DEFAULT_OUTLINE) -> FaceCandidate | None:
    """A candidate from the predicted face's outline, when no detection resembles it (the
    predicted ellipse is in pinhole pixels: a distorted frame is undistorted first;
    ``params``: the scene's ``episode.outline`` settings)."""
    e = hints.expected_ellipse
    reach = params.search_px
    if e is None or e.a < params.min_axis_px:
        return None
    for c in cands:
        d = c.ellipse
        if (d is not None and math.hypot(d.cx - e.cx, d.cy - e.cy) < reach
                and abs(d.a - e.a) < reach):
            return None  # the detector found it: its fit is the better one
    pinhole = undistort(image, intrinsics)
    gray = np.asarray(cv2.GaussianBlur(cv2.cvtColor(pinhole, cv2.COLOR_RGB2GRAY)
                                       .astype(np.float32), (3, 3), 0), dtype=np.float32)
    fit = track_outline(gray, e, reach, params)
    if fit is None:
        return None
    return FaceCandidate(pixel=np.array([fit.cx, fit.cy]), normal_cam=None, centre_cam=None,
                         radius=0.0, is_top=False, ellipse=fit)


class VisionDetector:
    """``ours``: the vision pipeline (see the module docstring)."""

    name = "ours"
    needs_image = True
    exact = False

    def __init__(self, cfg: SceneConfig) -> None:
        self.cfg = cfg

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        assert frame.image is not None
        detection = detect(frame.image, detector_config(self.cfg, frame.intrinsics, hints))
        cands = detection_candidates(detection)
        tracked = tracked_outline(frame.image, frame.intrinsics, hints, cands,
                                  self.cfg.episode.outline)
        if tracked is not None:
            cands = (*cands, tracked)
        return Detections(candidates=cands, reason=detection.reason, raw=detection)


class BaselineDetector:
    """A baseline ellipse detector, then our top rule and pose solver (``rht``,
    ``findellipses``)."""

    needs_image = True
    exact = False

    def __init__(self, cfg: SceneConfig, ellipses: EllipseDetector, name: str) -> None:
        self.cfg = cfg
        self.name = name
        self._ellipses = ellipses

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        assert frame.image is not None
        k = frame.intrinsics
        rgb = undistort(frame.image, k)  # the pose solver's pinhole pixels
        found = tuple(s.ellipse for s in self._ellipses(np.ascontiguousarray(rgb[:, :, ::-1])))
        if not found:
            return Detections(reason=f"{self.name}: no ellipse")
        cfg = detector_config(self.cfg, k, hints)
        belt_colour = find_roi(rgb, cfg.roi).belt
        belt = None if belt_colour is None else np.array(belt_colour)
        radius_of = (None if cfg.kind_colours is None
                     else radius_by_colour(rgb, cfg.radii_m, cfg.kind_colours))
        grad = edge_image(rgb, cfg.edges)
        choice = select_top(found, grad, k, radius_of, image=rgb, height_of=cfg.height_of(),
                            belt=belt, markings=marking_test(cfg, rgb, grad), params=cfg.top,
                            pose_params=cfg.pose)
        cands = []
        for i, e in enumerate(found):
            if i != choice.index:
                cands.append(other_candidate(e))
                continue
            radius = None if radius_of is None else radius_of(e)
            pose = estimate_pose(e, k, cfg.radii_m if radius is None else (radius,), None,
                                 cfg.depth_range_m, image=rgb, belt=belt, params=cfg.pose)
            cands.append(posed_candidate(pose, e))
        reason = "" if choice.index is not None else f"{self.name}: no top face"
        return Detections(candidates=tuple(cands), reason=reason)


def rht_detector(cfg: SceneConfig) -> BaselineDetector:
    """``rht``: the paper's randomized Hough transform (seeded per frame: deterministic)."""
    return BaselineDetector(cfg, RHTDetector(seed=0), "rht")


def findellipses_detector(cfg: SceneConfig) -> BaselineDetector:
    """``findellipses``: OpenCV's ``cv2.ximgproc.findEllipses``."""
    return BaselineDetector(cfg, FindEllipsesDetector(), "findellipses")


class OracleDetector:
    """``oracle``: ground truth (see the module docstring); the only detector given it."""

    name = "oracle"
    needs_image = False
    exact = True

    def __init__(self, cfg: SceneConfig, truth: CellTruth) -> None:
        self.cfg = cfg
        self._truth = truth
        self._offered: dict[bytes, str] = {}
        """Object of each first choice offered (by its pixel), to follow once tracked."""
        self._target: str | None = None

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        if hints.target is None:
            self._target = None
            return self._first_choice(frame)
        if self._target is None:
            self._target = self._offered[hints.target.pixel.tobytes()]
        cand = self._truth.face(self._target, frame.world_T_cam, whole=False)
        if cand is None:
            return Detections(reason="the tracked face's centre is not in the image")
        return Detections(candidates=(cand,))

    def _first_choice(self, frame: Frame) -> Detections:
        truth = self._truth.frame()
        in_view = {name: self._truth.face(name, frame.world_T_cam, whole=True)
                   for name in truth.top_objects}
        tops = [o for o in truth.objects if o.is_top and in_view.get(o.name) is not None]
        if not tops:
            return Detections(reason="no true top face wholly in view")
        best = min(tops, key=lambda o: (o.tilt_deg, o.name))
        cand = in_view[best.name]
        assert cand is not None
        self._offered[cand.pixel.tobytes()] = best.name
        return Detections(candidates=(cand,))

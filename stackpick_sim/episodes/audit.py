"""Ground truth of an episode, for its record only: the audit hook.

The control path (detector hints, estimator, controller, phase transitions) never reads the
simulator's truth about the objects; :class:`Audit` alone does, at fixed moments (each look
and detection frame's capture, the track's start, the cup's contact, the end), and writes
what it finds into the record: the true top objects, the object the track started on, the
detection's and the pick-time estimate's errors, and the verdict. The ``oracle`` detector is
the one exception by design: it is handed a :class:`CellTruth` through its constructor.

:func:`auditing` tells whether truth is being read on the audit's behalf (tests use it to
prove that nothing else reads it).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np

from stackpick_sim.episodes.outcome import (
    AimBelief,
    axis_turn_deg,
    distance_to_axis,
    face_in_view,
    lip_on_face,
    match_object,
    view_pose,
)
from stackpick_sim.episodes.record import EpisodeRecord, PoseErrors
from stackpick_sim.episodes.verdict import judge
from stackpick_sim.geometry import project_circle, tilt_angles
from stackpick_sim.pipeline import FaceCandidate, TargetState
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.cell import Cell
from stackpick_sim.sim.ground_truth import FrameTruth, frame_truth, top_face
from stackpick_sim.sim.robot import TOOL_SITE

if TYPE_CHECKING:
    from stackpick_sim.episodes.episode import Episode

FloatArray = np.ndarray

#: A target whose axis turned more than this since detection has toppled, deg (record only).
TOPPLED_DEG = 10.0
#: Phases whose frames the audit keeps the truth of (the top objects at detection time).
DETECTION_PHASES = ("look", "detect")

_depth = [0]


def auditing() -> bool:
    """Whether ground truth is being read for the record (inside :func:`audit_scope`)."""
    return _depth[0] > 0


@contextmanager
def audit_scope() -> Iterator[None]:
    """Mark a read of ground truth as the audit's (or the oracle's)."""
    _depth[0] += 1
    try:
        yield
    finally:
        _depth[0] -= 1


def buried_target(rec: EpisodeRecord) -> None:
    """A cup that met no sealing face on its way to a target that was not a top object at
    detection (one lying under another, or no object at the detected face): the pick went
    for the wrong object, whatever the cup then touched. ``missed_grasp`` becomes
    ``wrong_object``, the detail naming the target and keeping the contact's."""
    if rec.failure != "missed_grasp" or not rec.top_objects:
        return
    if rec.target_object in rec.top_objects:
        return
    target = rec.target_object or "no object"
    rec.failure = "wrong_object"
    rec.failure_detail = (f"the track was on {target}, not a true top object "
                          f"{rec.top_objects}; {rec.failure_detail}")


class CellTruth:
    """The cell's truth seen from the wrist camera: the oracle's and the audit's source."""

    def __init__(self, cell: Cell, camera: WristCamera | None) -> None:
        self.cell = cell
        self.camera = camera
        self._frame: tuple[float, FrameTruth] | None = None

    def frame(self) -> FrameTruth:
        """Truth of the current state (one segmentation render per sim instant)."""
        t = float(self.cell.data.time)
        if self._frame is None or self._frame[0] != t:
            assert self.camera is not None, "ground truth of a frame needs a WristCamera"
            with audit_scope():
                self._frame = (t, frame_truth(self.cell, self.camera.segmentation()))
        return self._frame[1]

    def face(self, name: str, world_T_cam: FloatArray, whole: bool) -> FaceCandidate | None:
        """The true face of object ``name`` seen from ``world_T_cam``, or None if its ellipse
        is not wholly in the image (``whole``) or, else, if its face centre is not."""
        cell = self.cell
        obj = next(o for o in cell.objects if o.name == name)
        k = cell.intrinsics
        r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
        with audit_scope():
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
        return FaceCandidate(pixel=pixel, normal_cam=inward_c, centre_cam=centre_c,
                             radius=obj.radius, is_top=True, ellipse=ellipse)


class Audit:
    """Writes the truth of one episode into its record (see the module docstring)."""

    def __init__(self, ep: Episode, truth: CellTruth) -> None:
        self.ep = ep
        self.truth = truth
        self._frames: dict[float, FrameTruth] = {}
        self._start_z: dict[str, float] = {}
        self._start_axes: dict[str, FloatArray] = {}
        self._look_T_cam = ep.scene.cell.world_T_cam()

    def on_capture(self, t: float, phase: str) -> None:
        """A frame is captured at ``t`` s: keep its truth if it may start the track."""
        if phase not in DETECTION_PHASES:
            return
        start = time.perf_counter()
        self._frames[t] = self.truth.frame()
        self.ep.wall["truth"] += time.perf_counter() - start

    def on_start(self, capture_time: float, cand: FaceCandidate) -> None:
        """The track starts on ``cand`` of the frame captured at ``capture_time`` s."""
        rec, cell = self.ep.record, self.ep.scene.cell
        truth = self._frames.get(capture_time)
        with audit_scope():
            self._start_z = {o.name: float(cell.data.xpos[o.body_id][2]) for o in cell.objects}
            self._start_axes = {o.name: cell.data.xmat[o.body_id].reshape(3, 3)[:, 2].copy()
                                for o in cell.objects}
        if truth is None:
            return
        rec.top_objects = truth.top_objects
        rec.target_object = match_object(truth, cand.pixel)
        with audit_scope():
            rec.target_kind = next((o.type_name for o in cell.objects
                                    if o.name == rec.target_object), None)
        if rec.target_object is not None and cand.normal_cam is not None:
            t_obj = next(o for o in truth.objects if o.name == rec.target_object)
            rec.detection = PoseErrors(
                estimated=(float(cand.pixel[0]), float(cand.pixel[1]),
                           *tilt_angles(cand.normal_cam)),
                actual=(*t_obj.face_center_px, t_obj.theta_x_deg, t_obj.theta_y_deg))

    def on_contact(self, state: TargetState, aim: AimBelief) -> None:
        """The cup touched: the estimate ``state`` vs. the target's true face (Table 2), and
        where the cup met it against what the controller believed (``aim``)."""
        rec, cell = self.ep.record, self.ep.scene.cell
        if rec.target_object is None:
            return
        k = cell.intrinsics
        with audit_scope():
            obj = next(o for o in cell.objects if o.name == rec.target_object)
            actual, centre_w = face_in_view(cell, obj, self._look_T_cam, k)
        estimated = view_pose(state.centre, state.normal, self._look_T_cam, k)
        rec.pick_estimate = PoseErrors(estimated=estimated, actual=actual)
        rec.prediction_error_px = rec.pick_estimate.center_error_px
        rec.prediction_error_mm = 1e3 * float(np.linalg.norm(state.centre - centre_w))
        self.on_lip(aim)

    def on_lip(self, aim: AimBelief) -> None:
        """Where the cup's axis meets the target's true face now (the lip at contact, or the
        end of a descent that met nothing) against the controller's ``aim``."""
        rec, cell = self.ep.record, self.ep.scene.cell
        rec.believed_radius_m = aim.radius
        rec.believed_kinds = list(aim.kinds)
        rec.aim_offset_mm = round(1e3 * aim.offset, 3)
        if rec.target_object is None:
            return
        site = cell.model.site(TOOL_SITE).id
        cup_pos = cell.data.site_xpos[site].copy()
        cup_axis = cell.data.site_xmat[site].reshape(3, 3)[:, 2].copy()
        with audit_scope():
            obj = next(o for o in cell.objects if o.name == rec.target_object)
            centre, normal = top_face(cell, obj, cup_pos)
        lip = lip_on_face(cup_pos, cup_axis, centre, normal)
        if lip is not None:
            rec.lip_offset_mm, rec.lip_height_mm = (round(1e3 * v, 3) for v in lip)
        rec.aim_miss_mm = round(1e3 * distance_to_axis(aim.point, cup_pos, cup_axis), 3)

    def on_finish(self, done: bool, grasped: list[str]) -> None:
        """Judge the outcome (``done``: verify passed; ``grasped``: objects at the cup when the
        lift began) and note a toppled target."""
        rec, cell = self.ep.record, self.ep.scene.cell
        with audit_scope():
            if done:
                judge(self.ep, self._start_z, grasped)
            buried_target(rec)
            if rec.failure is None or rec.target_object not in self._start_axes:
                return
            # A pile that collapsed under its own weight on the running belt is a different
            # story from a controller's miss.
            obj = next(o for o in cell.objects if o.name == rec.target_object)
            turn = axis_turn_deg(cell, obj, self._start_axes[obj.name])
        if turn > TOPPLED_DEG:
            rec.failure_detail += (f"; the target toppled: its axis turned {turn:.0f} deg "
                                   "since detection")

"""Scoring one method's output on one frame against the ground truth.

* **Top-object success**: the method's chosen ellipse has mask IoU > MATCH_IOU with the face
  of a true top object (``is_top``: nothing rests on it, face >= 98% visible).
* **Precision / recall**: all the method's ellipses against the faces visible to at least
  COUNTED_VISIBLE_FRACTION (a mostly hidden face can be detected by no one); one-to-one
  greedy matching by IoU > MATCH_IOU. A detection matching a face that is too hidden to be
  counted is ignored (neither true nor false positive). Totals are summed over the data set.
* **Pose errors**, only on successful frames, against the matched top object: centre error
  (px) between the reported face-centre pixel and the projected true face centre, and the
  absolute theta_x and theta_y errors (deg).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from stackpick_sim.geometry import Ellipse, mask_iou
from stackpick_sim.vision.benchmark.frames import BenchFrame, TruthFace

#: Mask IoU above which a detected ellipse matches a true face: pixel-mask IoU > 0.8, the
#: field's convention for scoring ellipse detections on real images.
MATCH_IOU = 0.8
#: Faces at least this visible are counted for precision and recall (documented choice).
COUNTED_VISIBLE_FRACTION = 0.5


@dataclass(frozen=True, kw_only=True)
class MethodOutput:
    """What one method reports for one frame.

    ``ellipses``: every face ellipse it found; ``top``: its chosen top face or None;
    ``pose``: (x px, y px, theta_x deg, theta_y deg) of the top face or None;
    ``total_ms``: wall time of the whole call; ``detector_ms``: of the ellipse detector alone.
    """

    ellipses: tuple[Ellipse, ...]
    top: Ellipse | None
    pose: tuple[float, float, float, float] | None
    total_ms: float
    detector_ms: float
    stages_ms: dict[str, float]


@dataclass(frozen=True, kw_only=True)
class FrameScore:
    """Scores of one method on one frame (pose errors None unless the top was found)."""

    seed: int
    has_top: bool
    success: bool
    true_pos: int
    false_pos: int
    false_neg: int
    centre_err_px: float | None
    theta_x_err_deg: float | None
    theta_y_err_deg: float | None
    matched: TruthFace | None


def _iou(e1: Ellipse, e2: Ellipse, shape: tuple[int, int]) -> float:
    """Mask IoU, skipping the rasterisation for ellipses that cannot overlap."""
    if math.hypot(e1.cx - e2.cx, e1.cy - e2.cy) >= e1.a + e2.a:
        return 0.0
    return mask_iou(e1, e2, shape)


def best_match(ellipse: Ellipse, faces: list[TruthFace],
               shape: tuple[int, int]) -> tuple[TruthFace | None, float]:
    """The face with the highest IoU with ``ellipse`` and that IoU (None, 0 when none)."""
    best, best_iou = None, 0.0
    for f in faces:
        if f.ellipse is None:
            continue
        iou = _iou(ellipse, f.ellipse, shape)
        if iou > best_iou:
            best, best_iou = f, iou
    return best, best_iou


def _one_to_one(pairs: list[tuple[float, int, int]]) -> tuple[set[int], set[int]]:
    """Greedy one-to-one matching of (IoU, detection, face) pairs, highest IoU first: the
    detections and the faces used."""
    used_det: set[int] = set()
    used_face: set[int] = set()
    for _, i, j in sorted(pairs, reverse=True):
        if i not in used_det and j not in used_face:
            used_det.add(i)
            used_face.add(j)
    return used_det, used_face


def count_matches(ellipses: tuple[Ellipse, ...], frame: BenchFrame) -> tuple[int, int, int]:
    """(true positives, false positives, false negatives) of all ellipses of one frame."""
    counted = [f for f in frame.faces if f.ellipse is not None
               and f.visible_fraction >= COUNTED_VISIBLE_FRACTION]
    ignored = [f for f in frame.faces if f.ellipse is not None
               and f.visible_fraction < COUNTED_VISIBLE_FRACTION]
    pairs = []
    for i, e in enumerate(ellipses):
        for j, f in enumerate(counted):
            assert f.ellipse is not None
            iou = _iou(e, f.ellipse, frame.shape)
            if iou > MATCH_IOU:
                pairs.append((iou, i, j))
    used_det, used_face = _one_to_one(pairs)
    false_pos = 0
    for i, e in enumerate(ellipses):
        if i in used_det:
            continue
        _, iou = best_match(e, ignored, frame.shape)
        if iou <= MATCH_IOU:
            false_pos += 1
    return len(used_det), false_pos, len(counted) - len(used_face)


def score_frame(output: MethodOutput, frame: BenchFrame) -> FrameScore:
    """Score one method's output on one frame (see the module docstring)."""
    tp, fp, fn = count_matches(output.ellipses, frame)
    tops = frame.tops
    matched, iou = (None, 0.0) if output.top is None else best_match(output.top, tops,
                                                                    frame.shape)
    success = matched is not None and iou > MATCH_IOU
    centre = tx = ty = None
    if success and output.pose is not None and matched is not None:
        x, y, th_x, th_y = output.pose
        centre = math.hypot(x - matched.face_center_px[0], y - matched.face_center_px[1])
        tx, ty = abs(th_x - matched.theta_x_deg), abs(th_y - matched.theta_y_deg)
    return FrameScore(seed=frame.seed, has_top=bool(tops), success=success, true_pos=tp,
                      false_pos=fp, false_neg=fn, centre_err_px=centre, theta_x_err_deg=tx,
                      theta_y_err_deg=ty, matched=matched if success else None)

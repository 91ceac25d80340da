"""A plug-in detector in ~30 lines: OpenCV's HoughCircles, the largest circle called top.

    stackpick run --scene paper --seeds 0:10 --detector examples.hough_detector:HoughDetector

Circles are faces seen square-on: the pose is the circle's, its normal along the optical
axis and its depth from the scene's largest radius. On a tilted face that pose puts the cup
off the face or at a steep angle, and the suction seal leaks (``missed_grasp``, "no seal"):
on paper seeds 0-7 it picks 2 of 8. Run from the repository root (the
working directory is on the import path of every worker).
"""

from __future__ import annotations

import cv2
import numpy as np

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.geometry import Ellipse
from stackpick_sim.pipeline import Detections, FaceCandidate, Frame, Hints


class HoughDetector:
    name = "hough"
    version = "1.0"
    needs_image = True
    exact = False

    def __init__(self, cfg: SceneConfig) -> None:
        self.radius = max(t.radius for t in cfg.object_types.values())  # m

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        assert frame.image is not None
        gray = cv2.medianBlur(cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY), 5)
        found = cv2.HoughCircles(gray, cv2.HOUGH_GRADIENT, dp=1.5, minDist=20, param1=120,
                                 param2=40, minRadius=10, maxRadius=120)
        if found is None:
            return Detections(reason="no circle")
        k = frame.intrinsics
        candidates = []
        for i, (u, v, r) in enumerate(sorted(found[0], key=lambda c: -c[2])):
            depth = k.fx * self.radius / r  # a circle of the largest radius, square-on
            centre = depth * np.linalg.solve(k.K, np.array([u, v, 1.0]))
            candidates.append(FaceCandidate(
                pixel=np.array([u, v], dtype=float), normal_cam=np.array([0.0, 0.0, 1.0]),
                centre_cam=centre, radius=self.radius, is_top=i == 0,
                ellipse=Ellipse(cx=float(u), cy=float(v), a=float(r), b=float(r),
                                angle_deg=0.0)))
        return Detections(candidates=tuple(candidates))

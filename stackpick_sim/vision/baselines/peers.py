"""Peer ellipse detectors from opencv-contrib's ximgproc, converted to the package convention.

Row formats, verified on synthetic ellipses drawn with ``cv2.ellipse`` (opencv-contrib 5.0)
and, for findEllipses, against its source (``ximgproc/src/find_ellipses.cpp`` builds
``Vec6f(center.x, center.y, a, b, score, radius)`` where ``radius`` is the rotation):

* ``cv2.ximgproc.findEllipses`` (Jia et al. 2017) returns ``None`` or an (N, 1, 6) float32
  array of rows ``(cx, cy, a, b, score, angle_rad)``: semi-axes with ``a >= b`` always
  (``b = a * N`` with ``N <= 1``), ``angle_rad`` in [0, pi) the direction of the ``a`` axis
  from +u toward +v (the same sense as ``cv2.ellipse``), ``score`` = (share of arc pixels on
  the ellipse + reliability) / 2 in [0, 1]. The OpenCV docs give another column order; they
  are wrong. Its estimates are quantised by construction: ``a`` is a whole pixel, the angle a
  whole degree, ``b / a`` a multiple of 0.01.
* EdgeDrawing's ``detectEllipses`` returns ``None`` or an (N, 1, 6) float32 array of rows
  ``(cx, cy, r, a, b, angle_deg)``. A circle comes as ``r > 0, a = b = 0, angle = 0``; an
  ellipse as ``r = 0`` with **semi**-axes ``a``, ``b`` in no particular order, ``a`` lying
  along ``angle_deg`` (degrees, roughly (-45, 45], same sense as ``cv2.ellipse``). Its axes
  come out about 0.5 px long on bright-on-dark discs (its edge pixels sit on the dark side).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.baselines.common import (
    ScoredEllipse,
    as_gray,
    edge_distance_map,
    outline_coverage,
    sort_by_score,
    too_small,
)

#: findEllipses' own defaults (OpenCV signature), kept so the peer runs as published.
FE_SCORE_THRESHOLD = 0.7
FE_RELIABILITY_THRESHOLD = 0.5
#: Centre-distance threshold as a fraction of the image diagonal (OpenCV default).
FE_CENTER_DISTANCE_THRESHOLD = 0.05

#: EdgeDrawing gives no score; we score a detection by the share of its outline within this
#: distance of an ED edge pixel. 1.5 px covers ED's half-pixel offset plus one pixel of
#: digitisation, the same tolerance the RHT baseline verifies with.
ED_COVERAGE_TOLERANCE_PX = 1.5


def ellipse_from_fe_row(row: NDArray[np.floating]) -> Ellipse:
    """Convert one findEllipses row ``(cx, cy, a, b, score, angle_rad)`` to an Ellipse."""
    cx, cy, a, b, _score, angle_rad = (float(v) for v in row[:6])
    angle = math.degrees(angle_rad)
    if a < b:  # never seen (the source enforces a >= b); handled rather than trusted
        a, b, angle = b, a, angle + 90.0
    return Ellipse(cx=cx, cy=cy, a=a, b=b, angle_deg=angle % 180.0)


def ellipse_from_ed_row(row: NDArray[np.floating]) -> Ellipse:
    """Convert one EdgeDrawing row ``(cx, cy, r, a, b, angle_deg)`` to an Ellipse."""
    cx, cy, r, a, b, angle = (float(v) for v in row[:6])
    if r > 0.0:
        return Ellipse(cx=cx, cy=cy, a=r, b=r, angle_deg=0.0)
    if a < b:
        a, b, angle = b, a, angle + 90.0
    return Ellipse(cx=cx, cy=cy, a=a, b=b, angle_deg=angle % 180.0)


def _valid(e: Ellipse) -> bool:
    """Finite with positive axes: peers occasionally emit degenerate rows."""
    vals = (e.cx, e.cy, e.a, e.b, e.angle_deg)
    return all(math.isfinite(v) for v in vals) and e.b > 0.0


@dataclass(frozen=True, kw_only=True)
class FindEllipsesDetector:
    """``cv2.ximgproc.findEllipses`` (Jia et al. 2017) behind the common interface.

    Score: the detector's own score column, in [0, 1].
    """

    score_threshold: float = FE_SCORE_THRESHOLD
    reliability_threshold: float = FE_RELIABILITY_THRESHOLD
    center_distance_threshold: float = FE_CENTER_DISTANCE_THRESHOLD
    name: str = "findEllipses"

    def __call__(self, image: NDArray[np.uint8]) -> list[ScoredEllipse]:
        """Detect ellipses in an (H, W) gray or (H, W, 3) BGR uint8 image."""
        gray = as_gray(image)
        if too_small(gray):
            return []
        rows = cv2.ximgproc.findEllipses(
            gray,
            scoreThreshold=self.score_threshold,
            reliabilityThreshold=self.reliability_threshold,
            centerDistanceThreshold=self.center_distance_threshold,
        )
        if rows is None:
            return []
        found = []
        for row in np.asarray(rows, dtype=np.float64).reshape(-1, 6):
            e = ellipse_from_fe_row(row)
            if _valid(e):
                found.append(ScoredEllipse(ellipse=e, score=float(np.clip(row[4], 0.0, 1.0))))
        return sort_by_score(found)


@dataclass(frozen=True, kw_only=True)
class EdgeDrawingDetector:
    """EdgeDrawing / EDCircles ``detectEllipses`` behind the common interface.

    Score: share of the outline within :data:`ED_COVERAGE_TOLERANCE_PX` of ED's own edge map.
    A fresh EdgeDrawing object per call keeps calls independent.
    """

    coverage_tolerance_px: float = ED_COVERAGE_TOLERANCE_PX
    name: str = "EdgeDrawing"

    def __call__(self, image: NDArray[np.uint8]) -> list[ScoredEllipse]:
        """Detect ellipses in an (H, W) gray or (H, W, 3) BGR uint8 image."""
        gray = as_gray(image)
        if too_small(gray):
            return []
        ed = cv2.ximgproc.createEdgeDrawing()
        ed.detectEdges(gray)
        rows = ed.detectEllipses()
        if rows is None:
            return []
        edge_distance = edge_distance_map(np.asarray(ed.getEdgeImage()) > 0)
        found = []
        for row in np.asarray(rows, dtype=np.float64).reshape(-1, 6):
            e = ellipse_from_ed_row(row)
            if _valid(e):
                score = outline_coverage(e, edge_distance, tolerance_px=self.coverage_tolerance_px)
                found.append(ScoredEllipse(ellipse=e, score=score))
        return sort_by_score(found)

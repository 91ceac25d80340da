"""Baseline and peer ellipse detectors for the detection benchmark, behind one interface.

Every detector is a callable ``detector(image) -> list[ScoredEllipse]`` (see
:class:`EllipseDetector`): (H, W) gray or (H, W, 3) BGR uint8 in, detections sorted by
descending score out, ``[]`` when nothing is found, ImageError only for non-images.

* :class:`RHTDetector` - the paper's Randomized Hough Transform baseline (section 2.2).
* :class:`FindEllipsesDetector` - ``cv2.ximgproc.findEllipses`` (Jia et al. 2017).
* :class:`EdgeDrawingDetector` - EdgeDrawing / EDCircles ``detectEllipses``.
"""

from stackpick_sim.vision.baselines.common import (
    MIN_IMAGE_SIDE_PX,
    EllipseDetector,
    ScoredEllipse,
    as_gray,
)
from stackpick_sim.vision.baselines.edges import EdgePixels, extract_edges
from stackpick_sim.vision.baselines.peers import (
    EdgeDrawingDetector,
    FindEllipsesDetector,
    ellipse_from_ed_row,
    ellipse_from_fe_row,
)
from stackpick_sim.vision.baselines.rht import RHTConfig, RHTDetector, detect_ellipses_rht

__all__ = [
    "MIN_IMAGE_SIDE_PX",
    "EdgeDrawingDetector",
    "EdgePixels",
    "EllipseDetector",
    "FindEllipsesDetector",
    "RHTConfig",
    "RHTDetector",
    "ScoredEllipse",
    "as_gray",
    "detect_ellipses_rht",
    "ellipse_from_ed_row",
    "ellipse_from_fe_row",
    "extract_edges",
]

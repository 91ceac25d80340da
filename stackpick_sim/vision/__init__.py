"""Vision: find the top cylinder of a pile and its pose (paper section 2).

Stages, one module each: :mod:`edges`, :mod:`segments`, :mod:`fitting`, :mod:`merging`,
:mod:`refine` (refit on all edge pixels along each ellipse), :mod:`contrast` (outline support
from consistent gradients),
:mod:`occlusion` (the top-object rule, usable on any detector's ellipses; with
:mod:`wall_cover` and :mod:`resting`: walls under faces, leans on walls), :mod:`pose` (with
:mod:`wall`: the wall-colour test that resolves the tilt ambiguity); :mod:`roi` crops to the pile;
:mod:`detector` runs them as an ordered tuple of named stages (:mod:`stages`: the state
they pass on; :mod:`params`: each stage's settings; :mod:`limits`: caps on their work;
:mod:`kernels`: their compiled loops; :mod:`ellipses`: the ellipse stages alone,
:func:`find_ellipses`),
:mod:`detection` holds the result, :mod:`synthetic` renders test
stacks with ground truth. :mod:`moving_edges` finds an already tracked face's outline around
its predicted ellipse (tracking mode, used by the episodes when the detector misses it).
"""

from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.detector import DetectorConfig, TopObjectDetector, detect
from stackpick_sim.vision.ellipses import ScoredEllipse, find_ellipses
from stackpick_sim.vision.limits import WorkLimits
from stackpick_sim.vision.occlusion import OcclusionEvidence, TopChoice, select_top
from stackpick_sim.vision.pose import Pose, circle_poses, estimate_pose

__all__ = [
    "DetectedEllipse",
    "Detection",
    "DetectorConfig",
    "OcclusionEvidence",
    "Pose",
    "ScoredEllipse",
    "TopChoice",
    "TopObjectDetector",
    "WorkLimits",
    "circle_poses",
    "detect",
    "estimate_pose",
    "find_ellipses",
    "select_top",
]

"""The detector's settings, one section per stage: the sections of
:class:`~stackpick_sim.vision.detector.DetectorConfig` and of the scene's ``[vision]`` table.

Defined in :mod:`stackpick_sim.config.vision_params` (plain data, so that loading a scene does
not load the pipeline) and offered here beside the stages they set.
"""

from stackpick_sim.config.vision_params import (
    FALLBACKS,
    CompleteParams,
    EdgeParams,
    EllipsesParams,
    FitParams,
    GateParams,
    InnerFaceParams,
    LeanParams,
    MarkingParams,
    MergeParams,
    PoseParams,
    RefineParams,
    ReportParams,
    RoiParams,
    Section,
    SegmentParams,
    StageSections,
    TopParams,
    UnderWallParams,
    WholeRefitParams,
    sections_of,
)

__all__ = [
    "FALLBACKS",
    "CompleteParams",
    "EdgeParams",
    "EllipsesParams",
    "FitParams",
    "GateParams",
    "InnerFaceParams",
    "LeanParams",
    "MarkingParams",
    "MergeParams",
    "PoseParams",
    "RefineParams",
    "ReportParams",
    "RoiParams",
    "Section",
    "SegmentParams",
    "StageSections",
    "TopParams",
    "UnderWallParams",
    "WholeRefitParams",
    "sections_of",
]

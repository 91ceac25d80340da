"""The detector's result: every ellipse found, the top object, its pose and stage timings."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.occlusion import OcclusionEvidence
from stackpick_sim.vision.pose import Pose


@dataclass(frozen=True, kw_only=True)
class DetectedEllipse:
    """One ellipse: its fit, the edge segments it was fitted on, residual and support.

    ``segments`` index :attr:`Detection.segments`; ``residual_px`` is the RMS distance of
    those segments' pixels to the ellipse; ``support`` the share (0-1) of its circumference
    with an edge pixel within 1 px; ``evidence`` the occlusion evidence behind the top rule.
    """

    ellipse: Ellipse
    segments: tuple[int, ...]
    residual_px: float
    support: float
    evidence: OcclusionEvidence | None = None

    @classmethod
    def of(cls, ellipse: Ellipse, segments: tuple[int, ...], residual_px: float,
           support: float, evidence: OcclusionEvidence | None = None) -> DetectedEllipse:
        """``DetectedEllipse(ellipse=ellipse, ...)`` (an equal object) at a third of the
        frozen dataclass constructor's cost, for the detector's report of every frame: the
        fields are written to the instance dict directly (as
        :meth:`~stackpick_sim.geometry.Ellipse.of`; there is no validation to skip)."""
        d = object.__new__(cls)
        d.__dict__.update(ellipse=ellipse, segments=segments, residual_px=residual_px,
                          support=support, evidence=evidence)
        return d

    def as_dict(self) -> dict[str, float]:
        """JSON-friendly {cx, cy, a, b, angle_deg, support}."""
        return {**self.ellipse.as_dict(), "support": self.support}


@dataclass(frozen=True, kw_only=True)
class Detection:
    """Outcome of one frame. Falsy (with ``reason``) when no top object and pose were found.

    ``ellipses``: all validated ellipses, best-supported first. ``segments``: the edge
    segments, each (N_i, 2) int32 pixels (u, v) in chain order. ``top``: index of the top
    object's face in ``ellipses`` or None. ``pose``: its pose or None. ``timings_ms``:
    wall-clock milliseconds per stage run, under its name (by default roi, edges, segments,
    fitting, merging, refine, gate, top, pose; see :mod:`~stackpick_sim.vision.stages`), and
    total.
    """

    ellipses: tuple[DetectedEllipse, ...] = ()
    segments: tuple[NDArray[np.int32], ...] = ()
    top: int | None = None
    pose: Pose | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    reason: str = ""

    def __bool__(self) -> bool:
        return self.top is not None and self.pose is not None

    @property
    def top_ellipse(self) -> Ellipse | None:
        """The top object's face ellipse, or None."""
        return None if self.top is None else self.ellipses[self.top].ellipse

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly summary: ellipses, top, pose, timings_ms and reason."""
        return {
            "ellipses": [e.as_dict() for e in self.ellipses],
            "top": self.top,
            "pose": None if self.pose is None else self.pose.as_dict(),
            "timings_ms": dict(self.timings_ms),
            "reason": self.reason,
        }

"""Stage 5: which ellipse is the top object's face (paper section 2.3, Fig. 8).

The paper's rule: where two outlines meet in a T, the contour running through the T is the
occluding one and the edge that ends at it is occluded; an ellipse with an occluded edge lies
under something. Canny often leaves a pixel or two of gap at a T instead of a junction pixel,
so the T is read off the ellipse itself: walk its circumference, find the runs without edge
support (gaps), and call a gap end *occluded* when another contour (edge pixels off this
ellipse) passes within JUNCTION_RADIUS_PX of where this ellipse's edge stops.

Two more pieces of evidence make the rule robust, both implied by "nothing rests on it and
its face is >= 98% visible":

* support: an unoccluded face shows edge pixels along (nearly) its whole circumference;
* interior edges: no other contour crosses the face. This also rejects the ellipse of a
  cylinder's far rim, whose inside holds its own face's near rim.

A gap end counts as a T only when the other contour runs on into this face (an occluder
does; the object's own wall lines and the outlines of objects under it stay outside). Given
the camera intrinsics, the rule is also applied to side walls: a candidate whose predicted
wall runs under another candidate's face lies under it (:mod:`stackpick_sim.vision.
wall_cover`).

Among the unoccluded candidates the best-supported one wins (ties within SUPPORT_TIE go to
the larger ellipse, which is nearer the camera for equal radii). The rule needs only a list
of ellipses and an edge map, so it applies to any detector's ellipses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.contrast import contrast_support, outline
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.fitting import distances, ellipse_params
from stackpick_sim.vision.merging import MERGE_TOLERANCE_PX, support_map
from stackpick_sim.vision.pose import circle_poses
from stackpick_sim.vision.wall_cover import under_another

#: An unoccluded face must have edge support along this share of its circumference. The
#: top face is >= 98% visible; 0.9 leaves room for Canny's gaps at junctions and at low
#: contrast arcs.
TOP_MIN_SUPPORT = 0.9
#: Gaps shorter than this along the circumference, px, are Canny drop-outs, not occlusion:
#: where a lower outline meets the top face in a T, Canny often breaks the through-going
#: edge for 4-7 px too (seen on the simulator's frames).
MIN_GAP_PX = 8
#: Another contour within this distance (px) of a gap end makes the end a T-junction.
JUNCTION_RADIUS_PX = 3
#: An occluding contour runs on into the face it covers: besides passing within
#: JUNCTION_RADIUS_PX of the gap end, it must have pixels inside the outline (by more than
#: MERGE_TOLERANCE_PX) within this distance (px) of the end. A tilted cylinder's own wall
#: lines (its silhouette and shading edges, which touch the faint face-to-wall rim) and the
#: outlines of objects lying under it stay outside its face (dev seeds 96, 122).
CROSSING_REACH_PX = 6.0
#: Edge pixels farther than this inside the outline (px) count as interior edges.
INTERIOR_MARGIN_PX = 2.5
#: Interior edge pixels allowed, as a share of the perimeter (isolated noise edges).
MAX_INTERIOR_SHARE = 0.05
#: A candidate face nearer the camera than every other by this much (m) is the top: an
#: object resting on another's wall lies higher than it though both faces show whole. Face
#: depths of one pile's top candidates that were not clearly ordered differed by < 1 cm on
#: the development seeds; the fit's depth error is ~1 mm.
DEPTH_TIE_M = 0.01
#: Candidates whose supports differ by less than this are tied.
SUPPORT_TIE = 0.02


@dataclass(frozen=True, kw_only=True)
class OcclusionEvidence:
    """Occlusion evidence of one ellipse against an edge map."""

    support: float
    longest_gap_px: int
    occluded_ends: int
    interior_edge_px: int
    perimeter_px: int

    @property
    def occluded(self) -> bool:
        """True when any evidence says something lies on this ellipse."""
        return bool(self.reason)

    @property
    def reason(self) -> str:
        """Why the ellipse is taken as occluded; "" when it is a top candidate."""
        if self.occluded_ends:
            return f"{self.occluded_ends} edge end(s) at T-junctions"
        if self.support < TOP_MIN_SUPPORT:
            return f"support {self.support:.2f} < {TOP_MIN_SUPPORT}"
        if self.interior_edge_px > MAX_INTERIOR_SHARE * self.perimeter_px:
            return f"{self.interior_edge_px} edge px inside the face"
        return ""


@dataclass(frozen=True, kw_only=True)
class TopChoice:
    """Outcome of the top-object rule: ``index`` into the ellipses, or None with a reason."""

    index: int | None
    evidence: tuple[OcclusionEvidence, ...]
    reason: str = ""

    def __bool__(self) -> bool:
        return self.index is not None


def _gaps(ok: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Cyclic runs of False in ``ok`` as (start, length), start index into ``ok``."""
    n = ok.size
    if ok.all():
        return []
    if not ok.any():
        return [(0, n)]
    shift = int(np.flatnonzero(ok)[0])
    rolled = np.roll(ok, -shift)
    diff = np.diff(np.concatenate([[1], rolled.astype(np.int8), [1]]))
    starts, stops = np.flatnonzero(diff == -1), np.flatnonzero(diff == 1)
    return [((int(s) + shift) % n, int(e - s)) for s, e in zip(starts, stops, strict=True)]


def evidence_for(ellipse: Ellipse, edge_points: NDArray[np.float64],
                 support: NDArray[np.uint8], gradients: EdgeImage | None = None
                 ) -> OcclusionEvidence:
    """Occlusion evidence of ``ellipse`` given the edge pixels (M, 2) (u, v) and the
    (H, W) 0/1 support map (edges dilated by SUPPORT_RADIUS_PX).

    With ``gradients`` the circumference's support is read from the consistent edge contrast
    (:mod:`stackpick_sim.vision.contrast`), which also sees edges too faint for the edge map.
    """
    samples, normals = outline(ellipse)  # the same points as boundary_samples(ellipse)
    if gradients is not None:
        ok = contrast_support(ellipse, gradients, (samples, normals))
    else:
        pix = np.rint(samples).astype(np.int64)
        h, w = support.shape
        inside = (pix[:, 0] >= 0) & (pix[:, 0] < w) & (pix[:, 1] >= 0) & (pix[:, 1] < h)
        ok = np.zeros(pix.shape[0], bool)
        ok[inside] = support[pix[inside, 1], pix[inside, 0]] > 0
    params = ellipse_params([ellipse])
    near = np.abs(edge_points[:, 0] - ellipse.cx) <= ellipse.a + JUNCTION_RADIUS_PX + 1
    near &= np.abs(edge_points[:, 1] - ellipse.cy) <= ellipse.a + JUNCTION_RADIUS_PX + 1
    local = edge_points[near]
    off_curve = local[distances(params, local)[0] > MERGE_TOLERANCE_PX]
    inner = off_curve[_inside(ellipse, off_curve, MERGE_TOLERANCE_PX)]
    occluded_ends, longest = 0, 0
    n = samples.shape[0]
    for start, length in _gaps(ok):
        longest = max(longest, length)
        if length < MIN_GAP_PX or length == n:
            continue
        for end in ((start - 1) % n, (start + length) % n):
            if _near(off_curve, samples[end], JUNCTION_RADIUS_PX) and _near(
                    inner, samples[end], CROSSING_REACH_PX):
                occluded_ends += 1
    interior = int(np.count_nonzero(_inside(ellipse, local, INTERIOR_MARGIN_PX)))
    return OcclusionEvidence(support=float(ok.mean()), longest_gap_px=longest,
                             occluded_ends=occluded_ends, interior_edge_px=interior,
                             perimeter_px=n)


def _inside(ellipse: Ellipse, points: NDArray[np.float64], margin_px: float
            ) -> NDArray[np.bool_]:
    """(M,) bool: which points (M, 2) (u, v) lie more than ``margin_px`` inside the outline
    (the ellipse with both semi-axes shrunk by the margin)."""
    t = math.radians(ellipse.angle_deg)
    du, dv = points[:, 0] - ellipse.cx, points[:, 1] - ellipse.cy
    x = (math.cos(t) * du + math.sin(t) * dv) / max(ellipse.a - margin_px, 1e-6)
    y = (-math.sin(t) * du + math.cos(t) * dv) / max(ellipse.b - margin_px, 1e-6)
    return np.asarray(x * x + y * y < 1.0, np.bool_)


def _near(points: NDArray[np.float64], centre: NDArray[np.float64], radius_px: float) -> bool:
    """True when any of the points (M, 2) lies within ``radius_px`` of ``centre`` (2,)."""
    if points.shape[0] == 0:
        return False
    return bool(np.any(np.hypot(*(points - centre).T) <= radius_px))


def _clearly_nearest(faces: list[Ellipse], intrinsics: CameraIntrinsics,
                     radius_of: Callable[[Ellipse], float | None]) -> int | None:
    """Index of the face nearer the camera than every other by DEPTH_TIE_M (face-centre
    depth from its radius), or None when a radius is unknown or no face is clearly nearest."""
    depths = []
    for face in faces:
        radius = radius_of(face)
        if radius is None:
            return None
        sols = circle_poses(face, intrinsics, radius)
        depths.append(0.5 * float(sols[0].centre_cam[2] + sols[1].centre_cam[2]))
    order = np.argsort(depths)
    if depths[order[1]] - depths[order[0]] < DEPTH_TIE_M:
        return None
    return int(order[0])


def select_top(ellipses: Sequence[Ellipse], edges: NDArray | EdgeImage,
               intrinsics: CameraIntrinsics | None = None,
               radius_of: Callable[[Ellipse], float | None] | None = None) -> TopChoice:
    """Apply the top-object rule to any ellipses over a one-pixel-wide (H, W) edge map.

    ``edges`` is nonzero on edge pixels (e.g. :func:`stackpick_sim.vision.edges.detect_edges`)
    or, better, the whole :class:`~stackpick_sim.vision.edges.EdgeImage` (then faint but
    consistent edges count as support too). With ``intrinsics`` (K in the edge map's pixel
    frame), a candidate whose side wall runs under another candidate's face loses to it
    (:mod:`stackpick_sim.vision.wall_cover`). With ``intrinsics`` and ``radius_of`` (an
    ellipse's face radius, m, or None if unknown) the nearest remaining candidate wins when
    it is nearer than the others by DEPTH_TIE_M. Returns the chosen index (else the
    best-supported unoccluded ellipse) or None with the reason.
    """
    gradients = edges if isinstance(edges, EdgeImage) else None
    edge_map = edges.edges if isinstance(edges, EdgeImage) else edges
    binary = (np.asarray(edge_map) > 0).astype(np.uint8)
    if not ellipses:
        return TopChoice(index=None, evidence=(), reason="no ellipses")
    support = support_map(binary)
    vv, uu = np.nonzero(binary)
    edge_points = np.stack([uu, vv], axis=1).astype(np.float64)
    evidence = tuple(evidence_for(e, edge_points, support, gradients) for e in ellipses)
    candidates = [i for i, ev in enumerate(evidence) if not ev.occluded]
    if not candidates:
        return TopChoice(index=None, evidence=evidence,
                         reason=f"all {len(ellipses)} ellipses occluded")
    if intrinsics is not None and len(candidates) > 1:
        under = under_another([ellipses[i] for i in candidates], intrinsics)
        free = [i for i, u in zip(candidates, under, strict=True) if not u]
        candidates = free or candidates
    if intrinsics is not None and radius_of is not None and len(candidates) > 1:
        nearest = _clearly_nearest([ellipses[i] for i in candidates], intrinsics, radius_of)
        if nearest is not None:
            return TopChoice(index=candidates[nearest], evidence=evidence)
    best_support = max(evidence[i].support for i in candidates)
    tied = [i for i in candidates if evidence[i].support >= best_support - SUPPORT_TIE]
    index = max(tied, key=lambda i: ellipses[i].area)
    return TopChoice(index=index, evidence=evidence)

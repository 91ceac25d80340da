"""Faces the merge never fitted whose outline is faint along part of its length.

A steeply tilted top face meets its own side wall, or a neighbour of its colour and shade,
along a boundary of a few grey levels: Canny keeps only short pieces of that side, the
segments stage cuts them off where they meet the strong side's arc or the wall's silhouette,
and the merge (which joins two arcs only when each lies on the other's own ellipse) never
joins the strong arc, whose own fit extrapolates far off the face, with the faint pieces. No
candidate of the face then exists, and the top rule takes a lower face or none. The top
rule's arc-pair fallbacks fit such faces, but only when no face passes it.

The top stage proposes them (:func:`complete_faces`, settings ``vision.complete``) when the
rule's first choice is not clear, as candidates of their own: ellipses of pairs of arcs
(:func:`~stackpick_sim.vision.regroup.arc_pair_ellipses`, grown by the chains lying on
them), refitted on the edge pixels along them, kept only when their whole outline shows a
consistent edge in the gradients (:func:`~stackpick_sim.vision.contrast.supported_samples`:
the windowed normal gradient, a threshold from the image's own noise, far below Canny's), so
the faint side is read where the ellipse predicts it. A fit of arcs of two outlines, or a
lower face partly hidden, shows no edge along part of its outline and is not proposed; nor
is a face already fitted (an ellipse overlapping a merged one by ``same_face_iou``). Arcs
lying on a merged ellipse whose whole outline shows already are no face's missing arcs and
pair with nothing, and every pair holds an arc on no merged ellipse at all (the faint side's
pieces, or the strong arc whose own fit runs off the face). Whether a proposed face is the
top one is left to the top rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import CompleteParams, StageSections
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.contrast import outline_rows, supported_samples
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.fitting import within_gate
from stackpick_sim.vision.limits import longest
from stackpick_sim.vision.merging import MergedEllipse
from stackpick_sim.vision.occlusion import select_top
from stackpick_sim.vision.refine import refine_all
from stackpick_sim.vision.regroup import arc_pair_ellipses, chain_table, chains_on


def contrast_shares(ellipses: Sequence[Ellipse], image: EdgeImage) -> NDArray[np.float64]:
    """(E,) share [0, 1] of each ellipse's outline that shows a consistent edge in
    ``image``'s gradients (:func:`~stackpick_sim.vision.contrast.supported_samples`), in one
    compiled pass."""
    if not ellipses:
        return np.zeros(0)
    rows = outline_rows(ellipses)
    _, ok = supported_samples(rows, image)
    sizes = rows[1]
    bounds = np.zeros(sizes.shape[0] + 1, np.int64)
    np.cumsum(sizes, out=bounds[1:])
    hits = np.add.reduceat(ok.astype(np.int64), bounds[:-1]) if ok.size else np.zeros(0)
    return np.asarray(hits / sizes, np.float64)


def area_iou(one: Ellipse, other: Ellipse) -> float:
    """Intersection over union of the two ellipses' areas, counted on the pixel grid of
    their joint bounding box."""
    u0, v0, u1, v1 = one.bounds()
    p0, q0, p1, q1 = other.bounds()
    c0, r0 = math.floor(min(u0, p0)), math.floor(min(v0, q0))
    c1, r1 = math.ceil(max(u1, p1)) + 1, math.ceil(max(v1, q1)) + 1
    uu, vv = np.meshgrid(np.arange(c0, c1, dtype=np.float64),
                         np.arange(r0, r1, dtype=np.float64))
    inside = [_inside(e, uu, vv) for e in (one, other)]
    union = np.count_nonzero(inside[0] | inside[1])
    return float(np.count_nonzero(inside[0] & inside[1])) / union if union else 0.0


def _inside(ellipse: Ellipse, uu: NDArray[np.float64], vv: NDArray[np.float64]
            ) -> NDArray[np.bool_]:
    """Which of the grid points (uu, vv) lie inside ``ellipse``."""
    t = math.radians(ellipse.angle_deg)
    c, s = math.cos(t), math.sin(t)
    du, dv = uu - ellipse.cx, vv - ellipse.cy
    x, y = (c * du + s * dv) / ellipse.a, (c * dv - s * du) / ellipse.b
    return np.asarray(x * x + y * y <= 1.0)


def unexplained_arcs(arcs: Sequence[int], chains: Sequence[NDArray[np.int32]],
                     whole: Sequence[Ellipse], sections: StageSections) -> list[int]:
    """Those of the ``arcs`` (indices into ``chains``) that lie on none of the ``whole``
    ellipses (by the merge's ``tolerance_px`` and ``absorb_fraction``: :func:`~stackpick_sim.
    vision.regroup.chains_on`)."""
    if not whole:
        return list(arcs)
    table = chain_table([chains[k] for k in arcs])
    on: set[int] = set()
    for ellipse in whole:
        on.update(chains_on(ellipse, *table, sections.merging))
    return [k for i, k in enumerate(arcs) if i not in on]


def complete_faces(merged: Sequence[MergedEllipse], shown: Sequence[float],
                   arc_chains: tuple[NDArray[np.int32], ...],
                   arcs: Sequence[int], image: EdgeImage,
                   edge_pixels: tuple[NDArray[np.float64], NDArray[np.float64]],
                   shape: tuple[int, int], gate: tuple[float, float] | None,
                   sections: StageSections, params: CompleteParams, max_arcs: int
                   ) -> list[Ellipse]:
    """The faces to propose (see the module docstring): ellipses of pairs of the ``arcs``
    (indices into ``arc_chains``; the ``max_arcs`` longest of those that lie on no ``merged``
    ellipse showing its whole outline, by the share ``shown`` of each that shows a consistent
    edge, :func:`contrast_shares`, the top rule's support; at least one of each pair on no
    merged ellipse at all), refined on the edge pixels along them
    (``edge_pixels``: the edge map's pixels and their unit gradients, :func:`~stackpick_sim.
    vision.refine.refine_all`), within the size ``gate`` in an image of ``shape`` (H, W),
    whose outline shows a consistent edge in ``image``'s gradients along at least
    ``params.min_contrast_share`` of it, that are no merged ellipse's face (area IoU below
    ``params.same_face_iou``) and pass the top rule alone (no T-junction, no edge inside:
    :func:`~stackpick_sim.vision.occlusion.select_top` without rivals); at most
    ``params.max_faces``, each face once, those of the most contrast first. ``sections``: the
    fits', merge's, refit's and top rule's settings."""
    share = params.min_contrast_share
    fitted = [m.ellipse for m in merged]
    whole = [e for e, s in zip(fitted, shown, strict=True) if s >= share]
    free = unexplained_arcs(arcs, arc_chains, whole, sections)
    free = [free[i] for i in longest([arc_chains[k] for k in free], max_arcs)]
    # A face the merge missed has an arc on no merged ellipse at all (its faint side's
    # pieces, or its strong arc whose own fit runs off the face): pairs hold one.
    anchors = unexplained_arcs(free, arc_chains, fitted, sections)
    if not anchors or len(free) < 2:
        return []
    found = _whole(arc_pair_ellipses(arc_chains, free, shape, gate, sections, anchors),
                   image, share)
    if found:
        found = _whole([e for e in refine_all(found, *edge_pixels, shape, sections.refine,
                                              sections.fits)
                        if within_gate(e, gate)], image, share)
    if not found:
        return []
    evidence = select_top(found, image, edge_points=edge_pixels[0], params=sections.top)
    return _new_faces([f for f, ev in zip(found, evidence.evidence, strict=True)
                       if not ev.occluded], fitted, params)


def _new_faces(found: list[Ellipse], fitted: list[Ellipse], params: CompleteParams
               ) -> list[Ellipse]:
    """Of ``found`` in their order, at most ``params.max_faces`` that overlap none of the
    ``fitted`` ellipses, nor one taken before them, by ``params.same_face_iou`` (area
    IoU)."""
    out: list[Ellipse] = []
    for face in found:
        if len(out) >= params.max_faces:
            break
        if not any(area_iou(face, other) >= params.same_face_iou for other in fitted + out):
            out.append(face)
    return out


def _whole(ellipses: list[Ellipse], image: EdgeImage, share: float) -> list[Ellipse]:
    """Those of ``ellipses`` whose outline shows a consistent edge along at least ``share``
    of it (:func:`contrast_shares`), those of the most contrast first."""
    shown = contrast_shares(ellipses, image)
    order = np.argsort(-shown, kind="stable").tolist()
    return [ellipses[i] for i in order if shown[i] >= share]

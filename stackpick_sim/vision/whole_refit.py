"""A top face whose fit took in its own wall or a neighbour's arc, when no face passed the
top rule outright.

A top face over faces of its colour and shade is often fitted on more than its own outline:
the merge joins its strong arcs with the silhouette of its own side wall beyond its rim (the
wall's far edge against the belt, or against a lower face), or with a neighbour's arc that
runs on from it. The fit then lies off the face along part of its outline: it reads a
T-junction where the top object's wall meets a lower face's rim, edges inside (the face's
own rim against its wall), or too little support (its outline off the face's boundary along
the wall). It fails the rule, and the fallbacks take a lower face that fails on support
alone, whose occluder only clips its rim (or none at all).

Refitted on its innermost consistent edge (:func:`~stackpick_sim.vision.contrast.
refit_on_contrast`: the strongest local peaks of the edge contrast closest inside, so the
face's own rim rather than its wall's silhouette beyond it), such a fit lands on the face,
which then shows whole: it passes the rule. A lower face's fit, refitted so, still runs
into the face lying on it (a T-junction or its outline's edges inside), unless the occluder
only clips its rim; the fallback's own choice is that case, so when its refit shows whole
too, nothing changes.

So (``vision.whole_refit``): when the top stage's choice, if any, failed the rule itself (a
fallback's), each fit that shows at least ``min_support`` of its outline and fails the rule
is refitted on its innermost consistent edge; the refits that are plausible, lie within
the size gate and pass the rule outright (:func:`whole_refits`) join the rule again in their
fits' place, and a refit it chooses is the top face.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.contrast import refit_on_contrast
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.faint_faces import area_iou
from stackpick_sim.vision.fitting import plausible, within_gate
from stackpick_sim.vision.occlusion import (
    OcclusionEvidence,
    clearly_nearest,
    holds_centre,
    select_top,
)


def settled(fit: Ellipse, grad: EdgeImage, reach_px: int, top: TopParams, min_iou: float
            ) -> bool:
    """Whether ``fit`` lies on its own outline: its refit on its innermost consistent edge
    (within ``reach_px`` inward, ``top.contrast_*``) overlaps it by at least ``min_iou``
    (area intersection over union). A face fitted round part of its wall, or on arcs of two
    outlines, moves when so refitted; a face fitted on its outline stays (its refit lands on
    the edge it was fitted on), though part of that outline may show no contrast."""
    refit = refit_on_contrast(fit, grad, True, top, inner_reach_px=reach_px)
    return refit is not None and area_iou(fit, refit) >= min_iou


def candidates(evidence: Sequence[OcclusionEvidence], min_support: float) -> list[int]:
    """Indices of the fits that fail the rule (any of its tests) and show at least
    ``min_support`` (share [0, 1]) of their outline."""
    return [i for i, ev in enumerate(evidence) if ev.occluded and ev.support >= min_support]


def whole_refits(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                 grad: EdgeImage, edge_points: NDArray[np.float64], shape: tuple[int, int],
                 gate: tuple[float, float] | None, min_support: float, reach_px: int,
                 top: TopParams, fits: FitParams) -> dict[int, Ellipse]:
    """Index -> refit on its innermost consistent edge (``top.contrast_*``) of each of
    ``ellipses`` that fails the rule with at least ``min_support`` of its outline showing
    (:func:`candidates`), whose refit is plausible in an image of ``shape`` (``fits``), lies
    within the size ``gate`` and passes the rule outright (``top``)."""
    found: dict[int, Ellipse] = {}
    for i in candidates(evidence, min_support):
        refit = refit_on_contrast(ellipses[i], grad, True, top, inner_reach_px=reach_px)
        if (refit is not None and plausible(refit, shape, fits)
                and within_gate(refit, gate)):
            found[i] = refit
    if not found:
        return found
    keys = list(found)
    judged = select_top([found[i] for i in keys], grad, edge_points=edge_points,
                        params=top).evidence
    return {i: found[i] for i, ev in zip(keys, judged, strict=True) if not ev.occluded}


def below(refit: Ellipse, chosen: Ellipse, intrinsics: CameraIntrinsics,
          radius_of: Callable[[Ellipse], float | None], top: TopParams) -> bool:
    """Whether ``refit`` is another face than the fallback's ``chosen`` one (neither holds
    the other's centre) and lies clearly farther from the camera than it
    (:func:`~stackpick_sim.vision.occlusion.clearly_nearest`, ``top.depth_tie_m``; radii
    from ``radius_of``): a lower face's fit that runs into a T-junction or holds edges
    inside, its refit shrunk past them, under a top face fitted a little off its outline. A
    refit of the chosen face itself replaces it, though the fit round its wall reads
    nearer."""
    if holds_centre(refit, chosen) or holds_centre(chosen, refit):
        return False
    return clearly_nearest([chosen, refit], intrinsics, radius_of, top) == 0

"""A top face standing inside a lower face's fit, when every face reads as occluded.

A small top object standing on a larger lower object of its colour and shade, its face
nearly concentric with the lower face, shows two outlines: the lower face's silhouette, a
strong edge all round, and the top face's own, strong only where it meets its own side wall
(a darker band between the two faces on the side the wall shows) and a faint step of a few
grey levels elsewhere, where it lies on the lower face. The merge fits the strong silhouette
whole, round the top face and a sliver of the lower face; the top face's own boundary with
its wall then lies inside that fit as edges, so the fit fails the top rule on edges inside,
and the top face's own arc, fitted alone, fails on support (its faint side). Where the
top face reaches the lower face's rim, the top object's wall meets the fit's outline in a
T-junction too. No face passes the rule,
and the fallbacks find none: the one face that shows whole is the top face itself, inside
the fit.

So, when the top rule and its fallbacks chose no face, each fit that shows at least
``top.hidden_min_support`` of its outline and fails on edges inside (with or without a
T-junction: the top object's wall meets the lower face's outline where the top face reaches
its rim) is refitted on its innermost consistent edge within ``top.inner_refit_reach_px``
(:func:`~stackpick_sim.vision.contrast.refit_on_contrast`: the top face's own wall boundary
on one side, its faint step on the other), as the top stage's inner refit of a chosen face
(``top.inner_refit_*``): a refit clearly smaller than the fit (``top.inner_refit_max_area``)
that leaves out a sliver at least ``top.inner_refit_min_inset_px`` wide, plausible and
within the size gate, is a face inside it. The top rule then runs again with each such fit
replaced by its refit (:func:`refitted`), and a refit it chooses is the top face
(``vision.inner_face``).
"""

from __future__ import annotations

from collections.abc import Sequence

from stackpick_sim.config.vision_params import FitParams, TopParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.contrast import refit_on_contrast, widest_inset_px
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.fitting import plausible, within_gate
from stackpick_sim.vision.occlusion import OcclusionEvidence


def inner_refit(fit: Ellipse, grad: EdgeImage, shape: tuple[int, int],
                gate: tuple[float, float] | None, top: TopParams, fits: FitParams
                ) -> Ellipse | None:
    """``fit`` refitted on its innermost consistent edge within ``top.inner_refit_reach_px``
    (round by round, each re-centring on the last, at most ``top.contrast_rounds``), when
    the refit is clearly smaller (at most ``top.inner_refit_max_area`` of the fit's area),
    leaves out a sliver at least ``top.inner_refit_min_inset_px`` wide (not the face's own
    soft rim), is plausible in an image of ``shape`` (``fits``) and lies within the size
    ``gate``: a face inside the fit, which took in slivers of a lower face round it; else
    None."""
    # A round that leaves more than inner_refit_max_area of the fit's area (most faces)
    # ends the refit, at half its cost.
    refit = refit_on_contrast(fit, grad, True, top, inner_reach_px=top.inner_refit_reach_px,
                              rounds=1)
    for _ in range(top.contrast_rounds - 1):
        if refit is None or refit.a * refit.b > top.inner_refit_max_area * fit.a * fit.b:
            break
        refit = refit_on_contrast(refit, grad, True, top,
                                  inner_reach_px=top.inner_refit_reach_px, rounds=1)
    if (refit is None or refit.a * refit.b > top.inner_refit_max_area * fit.a * fit.b
            or widest_inset_px(fit, refit) < top.inner_refit_min_inset_px
            or not plausible(refit, shape, fits)
            or not within_gate(refit, gate)):
        return None
    return refit


def enclosing(evidence: Sequence[OcclusionEvidence], min_support: float) -> list[int]:
    """Indices of the fits that can enclose a face: edges inside (more than
    ``max_interior_share`` of the perimeter, the evidence's settings) and support at least
    ``min_support`` (share [0, 1] of the outline: at least half of it shows). A T-junction
    does not rule a fit out: the top object's wall meets the lower face's outline where the
    top face reaches its rim."""
    return [i for i, ev in enumerate(evidence) if ev.edges_inside and ev.support >= min_support]


def refitted(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
             grad: EdgeImage, shape: tuple[int, int], gate: tuple[float, float] | None,
             top: TopParams, fits: FitParams) -> dict[int, Ellipse]:
    """Index -> inner refit (:func:`inner_refit`) of each of ``ellipses`` that can enclose a
    face (:func:`enclosing`, ``top.hidden_min_support``) and has one."""
    found = {}
    for i in enclosing(evidence, top.hidden_min_support):
        refit = inner_refit(ellipses[i], grad, shape, gate, top, fits)
        if refit is not None:
            found[i] = refit
    return found

"""A top face leaning on the chosen whole face, its outline short of the rule's support.

The failure class *a short-outlined face leaning on the chosen one*: a steep top object
leaning its wall on a lower object's whole face shows no T-junction on either outline, and its
own outline is faint along part of its length (its boundary with its own wall, or with a
neighbour of its colour and shade), so its fit fails the top rule on support, and is no
``unobstructed`` face either (below ``top.unobstructed_min_support``, or with its own rim
inside the fit). The whole lower face passes the rule outright, and the rule's rest test,
which weighs only the faces that pass and the unobstructed ones, never meets the leaning
face. Nothing may rest on a top object: when such a face's reconstructed cylinder rests on
the chosen face's (the rule's rest test, :func:`~stackpick_sim.vision.resting.rests_on`, or
over every kind, :func:`~stackpick_sim.vision.resting.rests_on_any_kind`), the chosen face is
not top and the leaning face takes the choice.

The faces weighed (:func:`leaning_faces`): no T-junction end, support at least
``lean.min_support`` and below the rule's ``top.min_support``, not unobstructed, their edges
inside (if any) within the rule's rim band (``top.rim_band_px``: the face's own rim, all but
``top.max_interior_share`` of the perimeter). A second fit of the chosen face, or a looser
fit of a face fitted with more of its outline showing (one holds the other's centre), is not
weighed: two fits of one face can read the contact opposite ways (a lower face's loose fit
found resting on the top face its better fit lies under); the better one stands for the
face.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import LeanParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.markings import holds_centre
from stackpick_sim.vision.occlusion import OcclusionEvidence, deep_edge_counts, unobstructed


def leaning_faces(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                  chosen: int, edge_points: NDArray[np.float64], params: LeanParams
                  ) -> list[int]:
    """Indices of the faces that may lean on face ``chosen`` (see the module docstring):
    no T-junction end, support in [``params.min_support``, ``top.min_support``), not
    unobstructed, interior edges within the rim band only, not a second fit of the chosen
    face nor a looser fit of a better-supported face. ``edge_points``: the edge map's pixels
    (M, 2) (u, v) in ``np.nonzero`` order."""
    short = [i for i, ev in enumerate(evidence)
             if i != chosen and _short_outlined(ev, params)
             and not _better_fit(ellipses, evidence, i, chosen)]
    # Only faces with edges inside need their edges counted away from the rim band.
    inside = [i for i in short if evidence[i].edges_inside]
    if not inside:
        return short
    top = evidence[chosen].params
    deep = deep_edge_counts([ellipses[i] for i in inside], edge_points, top.rim_band_px)
    rimmed = {i for i, d in zip(inside, deep, strict=True)
              if d <= top.max_interior_share * evidence[i].perimeter_px}
    return [i for i in short if not evidence[i].edges_inside or i in rimmed]


def _short_outlined(ev: OcclusionEvidence, params: LeanParams) -> bool:
    """Support in [``params.min_support``, ``top.min_support``), no T-junction end, not
    unobstructed (the rule's rest test weighs those)."""
    return (ev.weakly_supported and ev.support >= params.min_support and not ev.occluded_ends
            and not unobstructed(ev))


def _better_fit(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence], i: int,
                chosen: int) -> bool:
    """Whether face ``i`` is a second fit of face ``chosen`` or a looser fit of a face
    fitted with more of its outline showing (one holds the other's centre): the face is the
    chosen one, or its better fit stands for it."""
    face = ellipses[i]
    return any(holds_centre(face, other) or holds_centre(other, face)
               for j, other in enumerate(ellipses)
               if j != i and (j == chosen or evidence[j].support > evidence[i].support))


def select_leaning(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                   chosen: int, edge_points: NDArray[np.float64],
                   rests: Callable[[Sequence[Ellipse]], list[bool]], params: LeanParams
                   ) -> int | None:
    """Index of the best-supported of the :func:`leaning_faces` of face ``chosen``
    (``params``) whose cylinder rests on the chosen face's, or None. ``rests``: per face of
    a list, whether another face's cylinder rests on its own (the top rule's rest test,
    :func:`~stackpick_sim.vision.resting.rests_on`, or over every kind,
    :func:`~stackpick_sim.vision.resting.rests_on_any_kind`)."""
    above = [i for i in leaning_faces(ellipses, evidence, chosen, edge_points, params)
             if rests([ellipses[chosen], ellipses[i]])[0]]
    return max(above, key=lambda i: evidence[i].support, default=None)

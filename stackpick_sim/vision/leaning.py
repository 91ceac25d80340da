"""A top face leaning on the chosen whole face, its outline short of the rule's support.

The failure class *a short-outlined face leaning on the chosen one*: a steep top object
leaning its wall on a lower object's whole face shows no T-junction on either outline, and its
own outline is faint along part of its length (its boundary with its own wall, or with a
neighbour of its colour and shade), so its fit fails the top rule on support alone, below the
share the ``unobstructed`` test lets into the rule's depth test. The whole lower face passes
the rule outright, and the rule's rest test, which weighs only the faces that pass or are
unobstructed, never meets the leaning one. Nothing may rest on a top object: when such a
face's reconstructed cylinder rests on the chosen face's (:func:`~stackpick_sim.vision.
resting.rests_on`), the chosen face is not top and the leaning face takes the choice.

The faces weighed (:func:`leaning_faces`): no T-junction end, support at least
``lean.min_support`` (at least half the outline, as the scoring counts a face) and below the
rule's ``top.min_support``, their edges inside (if any) within the rule's rim band
(``top.rim_band_px``: the face's own rim, all but ``top.max_interior_share`` of the
perimeter), none a second fit of the chosen face (one holds the other's centre).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import LeanParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.markings import holds_centre
from stackpick_sim.vision.occlusion import OcclusionEvidence, deep_edge_counts


def leaning_faces(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                  chosen: int, edge_points: NDArray[np.float64], params: LeanParams
                  ) -> list[int]:
    """Indices of the faces that may lean on face ``chosen`` (see the module docstring):
    no T-junction end, support in [``params.min_support``, ``top.min_support``), interior
    edges within the rim band only, not a second fit of the chosen face."""
    face = ellipses[chosen]
    short = [i for i, ev in enumerate(evidence)
             if i != chosen and not ev.occluded_ends and ev.weakly_supported
             and ev.support >= params.min_support
             and not (holds_centre(ellipses[i], face) or holds_centre(face, ellipses[i]))]
    if not short:
        return []
    top = evidence[chosen].params
    deep = deep_edge_counts([ellipses[i] for i in short], edge_points, top.rim_band_px)
    return [i for i, d in zip(short, deep, strict=True)
            if d <= top.max_interior_share * evidence[i].perimeter_px]


def select_leaning(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                   chosen: int, edge_points: NDArray[np.float64],
                   rests: Callable[[list[Ellipse]], list[bool]], params: LeanParams
                   ) -> int | None:
    """Index of the best-supported of the :func:`leaning_faces` of face ``chosen``
    (``params``) whose cylinder rests on the chosen face's, or None. ``rests``: per face of
    a list, whether another face's cylinder rests on its own (the top rule's rest test,
    :func:`~stackpick_sim.vision.resting.rests_on`, or over every kind,
    :func:`~stackpick_sim.vision.resting.rests_on_any_kind`)."""
    above = [i for i in leaning_faces(ellipses, evidence, chosen, edge_points, params)
             if rests([ellipses[chosen], ellipses[i]])[0]]
    return max(above, key=lambda i: evidence[i].support, default=None)

"""Last resort for a face the merge never fitted: ellipses of pairs of its arcs.

The merge (:mod:`~stackpick_sim.vision.merging`, paper Eq. 3) joins two arcs only when each
lies on the other's own ellipse. A face lying on faces of its own colour keeps only short
arcs of its outline between the junctions with theirs (the faint boundaries between same-
colour faces break it up, and Canny links the rest with the lower faces' silhouettes): an
arc of a sixth of the outline or less fits an ellipse that extrapolates far off the face, no
pair of its arcs scores C > ``merging.k``, and the face is never fitted although most of its
outline lies in the edge map (seen on rendered paper-scene frames, where it loses top faces
lying on lower faces of their own colour).

So when no ellipse passes the top rule, the ellipse of each pair of fitted arcs is fitted
directly, held to the merge's own checks on a merged pair (RMS residual at most
``merging.max_residual_px``, each arc staying on it by ``merging.absorb_fraction``), then
grown by every edge chain lying on it (``merging.absorb_fraction``, as the merge's leftovers)
and refitted while the residual stays within ``fits.max_residual_px``
(``top.arc_grow_rounds``; the settings: :mod:`~stackpick_sim.config.vision_params`).
Whether such an ellipse is a face at all, and the top one, is left to the top rule: a fit of
arcs of two outlines shows little edge contrast along the rest of its outline, and a lower
face has edges inside it or T-junctions.

The arcs are given as indices into the edge chains: the detector first pairs the fitted arcs,
and only when nothing else passes (after its last contrast refit), or to rival a contrast refit
its retry chose, the chains the fitting stage dropped and the parts of chains cut at their
junctions too (:func:`~stackpick_sim.vision.detector.last_resort_arcs`). Between close
junctions a face's outline breaks into arcs of 10-30 px whose own five-parameter fits are
ill-posed (the pixel staircase of an arc of a sixth of the outline or less fits a flat ellipse
a few px across, below ``fits.min_axis_px``), so no piece of it is fitted, yet a pair of such arcs
across the face fixes its ellipse (a top face lying across faces of its colour, its whole
outline in the edge map in such pieces). And where
Canny runs a face's outline on into a lower face's silhouette, the face's arc is a part of a
chain of two curves (:func:`split_at_junctions`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import MergeParams, StageSections
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_top
from stackpick_sim.vision.fitting import (
    fit_ellipse,
    plausible,
    rms_residual,
)

#: The default settings of every stage (the arc pairs read the fits', the merge's and the top
#: rule's).
DEFAULT_SECTIONS = StageSections()


def _bounds(points: NDArray[np.int32]) -> tuple[float, float, float, float]:
    """(u0, v0, u1, v1) bounding box of (N, 2) pixels."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def chain_table(chains: Sequence[NDArray[np.int32]]
                ) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.float64]]:
    """:func:`chains_on`'s input from the chains (N_i, 2): all their pixels concatenated
    (N, 2), the chain of each pixel (N,) and the chains' lengths (C,)."""
    pixels = np.concatenate(chains) if chains else np.zeros((0, 2), np.int32)
    lengths = np.array([c.shape[0] for c in chains], np.float64)
    return pixels, np.repeat(np.arange(len(chains)), lengths.astype(np.int64)), lengths


def chains_on(ellipse: Ellipse, pixels: NDArray[np.int32], owner: NDArray[np.int64],
              lengths: NDArray[np.float64], params: MergeParams = DEFAULT_SECTIONS.merging
              ) -> tuple[int, ...]:
    """Indices of the chains with ``params.absorb_fraction`` of their pixels within
    ``params.tolerance_px`` of ``ellipse``, given all chains' pixels concatenated (N, 2), the
    chain of each (N,) and the chains' lengths (C,) (one distance pass over all pixels)."""
    if pixels.dtype != np.int32 or not pixels.flags.c_contiguous:
        pixels = np.ascontiguousarray(pixels, np.float64)
    t = math.radians(ellipse.angle_deg)
    # The near pixels counted per chain in one compiled pass (kernels.chain_hits: the
    # distances of ellipse_distances, the counts of np.bincount).
    hits = kernels.chain_hits(pixels, np.ascontiguousarray(owner, np.int64), lengths.shape[0],
                              ellipse.cx, ellipse.cy, ellipse.a, ellipse.b, math.cos(t),
                              math.sin(t), params.tolerance_px)
    return tuple(np.flatnonzero(hits >= params.absorb_fraction * lengths).tolist())


def arc_pair_ellipses(chains: Sequence[NDArray[np.int32]], arcs: Sequence[int],
                      shape: tuple[int, int],
                      axis_range: tuple[float, float] | None = None,
                      sections: StageSections = DEFAULT_SECTIONS,
                      anchors: Sequence[int] | None = None) -> list[Ellipse]:
    """Ellipses fitted to pairs of the chains ``arcs`` (indices into ``chains``, all edge
    segments, (N_j, 2) int32 (u, v)) and grown by the chains lying on them; see the module
    docstring. ``shape``: the (H, W) image; ``axis_range``: (min, max) semi-major axis (px) of
    a face, or None; ``sections``: the settings read (the fits', the merge's, the top rule's
    ``arc_grow_rounds``; a DetectorConfig is one); ``anchors``: when given, only the pairs
    with at least one of these arcs (indices into ``chains``). Each ellipse once:
    a pair of arcs that both lie on an ellipse already grown is not fitted again."""
    hi = math.hypot(*shape) if axis_range is None else axis_range[1]
    boxes = np.array([_bounds(chains[k]) for k in arcs], np.float64).reshape(-1, 4)
    # Both arcs within one face's extent: the pairs whose joint box spans at most 2 ``hi``
    # on both axes, in (i, j) order.
    span_u = (np.maximum.outer(boxes[:, 2], boxes[:, 2])
              - np.minimum.outer(boxes[:, 0], boxes[:, 0]))
    span_v = (np.maximum.outer(boxes[:, 3], boxes[:, 3])
              - np.minimum.outer(boxes[:, 1], boxes[:, 1]))
    near = (span_u <= 2.0 * hi) & (span_v <= 2.0 * hi)
    if anchors is not None:
        anchored = np.isin(np.asarray(arcs, np.int64), np.asarray(anchors, np.int64))
        near &= anchored[:, None] | anchored[None, :]
    pairs = np.argwhere(np.triu(near, 1)).tolist()
    # A chain given twice (one array, as a piece fitted whole and as its chain) counts once.
    first: dict[int, int] = {}
    distinct = [k for k, c in enumerate(chains) if first.setdefault(id(c), k) == k]
    pixels, owner, lengths = chain_table([chains[k] for k in distinct])
    out: list[Ellipse] = []
    grown_sets: list[set[int]] = []
    for (i, j), may_pass in zip(pairs, _screened(chains, arcs, pairs, axis_range, sections),
                                strict=True):
        ci, cj = arcs[i], arcs[j]
        # Not a pair whose fit clearly fails _pair_fit's checks, nor both on an ellipse grown
        # already.
        if not may_pass or any(ci in g and cj in g for g in grown_sets):
            continue
        union = np.concatenate([chains[ci], chains[cj]])
        fit = _pair_fit(union, chains[ci].shape[0], shape, axis_range, sections)
        if fit is None:
            continue
        fit, lying = _grown(fit, union, (ci, cj), chains, distinct, (pixels, owner, lengths),
                            shape, sections)
        grown_sets.append({ci, cj, *lying})
        out.append(fit)
    return out


def _screened(chains: Sequence[NDArray[np.int32]], arcs: Sequence[int], pairs: list[list[int]],
              axis_range: tuple[float, float] | None, sections: StageSections) -> list[bool]:
    """For each pair (i, j) of ``pairs`` (positions in ``arcs``, indices into ``chains``):
    False when its direct fit clearly fails :func:`_pair_fit`'s axis, residual and share
    checks, all pairs in one compiled pass (:func:`~stackpick_sim.vision.kernels_top.
    pair_screen`: the same fit, decided only where rounding cannot change the outcome)."""
    if not pairs:
        return []
    pixels = np.ascontiguousarray(np.concatenate([chains[k] for k in arcs]), np.int32)
    starts = np.zeros(len(arcs) + 1, np.int64)
    np.cumsum([chains[k].shape[0] for k in arcs], out=starts[1:])
    lo, hi = (0.0, math.inf) if axis_range is None else axis_range
    merge = sections.merging
    return kernels_top.pair_screen(pixels, starts, np.array(pairs, np.int64), lo, hi,
                                   merge.tolerance_px, merge.max_residual_px,
                                   merge.absorb_fraction).tolist()


def _grown(fit: Ellipse, union: NDArray[np.int32], pair: tuple[int, int],
           chains: Sequence[NDArray[np.int32]], distinct: list[int],
           table: tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.float64]],
           shape: tuple[int, int], sections: StageSections
           ) -> tuple[Ellipse, tuple[int, ...]]:
    """A pair's ``fit`` (its two arcs' pixels ``union``, their indices ``pair``) grown by the
    ``chains`` lying on it and refitted, up to ``top.arc_grow_rounds`` times while the
    residual stays within ``fits.max_residual_px`` (of ``sections``), and the chains lying on
    it (indices); ``distinct``: the chains counted once, ``table`` their :func:`chain_table`."""
    lying: tuple[int, ...] = ()
    fits = sections.fits
    for _ in range(sections.top.arc_grow_rounds):
        on = tuple(distinct[k] for k in chains_on(fit, *table, sections.merging))
        if on == lying:
            break
        lying = on
        grown = np.concatenate([union] + [chains[k] for k in lying if k not in pair])
        refit = fit_ellipse(grown)
        if (refit is None or not plausible(refit, shape, fits)
                or rms_residual(refit, grown) > fits.max_residual_px):
            break
        fit = refit
    return fit, lying


def _pair_fit(union: NDArray[np.int32], n: int, shape: tuple[int, int],
              axis_range: tuple[float, float] | None, sections: StageSections
              ) -> Ellipse | None:
    """The ellipse fitted to two arcs given one after the other in ``union`` (the first
    ``n`` pixels the first arc), when it is plausible in an (H, W) image of ``shape``, its
    semi-major axis within ``axis_range`` and it passes the merge's checks on a merged pair
    (RMS residual, each arc's share on it); else None."""
    fit = fit_ellipse(union)
    if (fit is None or not plausible(fit, shape, sections.fits)
            or (axis_range is not None and not axis_range[0] <= fit.a <= axis_range[1])):
        return None
    # The residual and each arc's share on the fit, in one compiled pass.
    merge = sections.merging
    t = math.radians(fit.angle_deg)
    rms, near_first, near_second = kernels.pair_lies(
        np.ascontiguousarray(union, np.int32), n, fit.cx, fit.cy, fit.a, fit.b, math.cos(t),
        math.sin(t), merge.tolerance_px)
    share = merge.absorb_fraction
    if (rms > merge.max_residual_px or near_first < share * n
            or near_second < share * (union.shape[0] - n)):
        return None
    return fit


def split_at_junctions(chains: Sequence[NDArray[np.int32]],
                       reach_px: float = DEFAULT_SECTIONS.top.arc_split_reach_px
                       ) -> list[list[NDArray[np.int32]]]:
    """Each chain ((N_i, 2) int32 pixels) cut at its pixels nearest to the ends of the other
    chains within ``reach_px`` (its own two end pixels excepted): the pieces of each, in
    order, views of it (a chain with no junction is its one piece).

    Canny runs a face's outline on into the silhouette of a lower face of its colour beyond
    it, the faint boundary between them ending near the point where the two outlines meet;
    cut there, the face's arc is a piece of its own (a top face whose outline chain also takes
    the sliver of the face under it)."""
    if not chains:
        return []
    pixels = np.ascontiguousarray(np.concatenate(chains), np.int32)
    starts = np.zeros(len(chains) + 1, np.int64)
    np.cumsum([c.shape[0] for c in chains], out=starts[1:])
    at = np.flatnonzero(kernels.junction_cuts(pixels, starts, reach_px ** 2)).tolist()
    out = []
    k = 0
    for c, start in zip(chains, starts.tolist(), strict=False):
        cuts = []
        while k < len(at) and at[k] < start + c.shape[0]:
            cuts.append(at[k] - start)
            k += 1
        out.append([c[a:b] for a, b in zip([0, *cuts], [*cuts, c.shape[0]], strict=True)])
    return out

"""Stage 4: merge segment ellipses that describe the same ellipse (paper Eq. 3), then validate.

``N_{A/B}`` is the share of segment A's pixels lying within ``tolerance_px`` of the ellipse
fitted to B. Two groups merge when ``C = N_{A/B} * N_{B/A} > k`` and the refit on
their union still fits; the best pair merges first and the counts are recomputed after every
merge until no pair qualifies (the product is symmetric, so a short arc whose own ellipse is
poorly constrained cannot absorb a long one by accident).

All pair counts come from the (group, pixel) pairs within tolerance, those of a group
computed once per (re)fit and only for the pixels near its ellipse, counted per (ellipse,
group) in one pass per round. Afterwards every edge segment too short to have been fitted on
its own is absorbed by the ellipse its pixels lie on, and each final ellipse is validated by
the share of its circumference that edge pixels support, all final ellipses together. A
final ellipse that is still one segment's fit keeps that fit's residual (when the caller
passes them), a refit's is computed on its own input; the others' are computed together.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, cast

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import FitParams, MergeParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels
from stackpick_sim.vision.contrast import outline_rows, perimeter_px, unit_circle
from stackpick_sim.vision.fitting import DEFAULT as FIT_DEFAULT
from stackpick_sim.vision.fitting import (
    distance_rows,
    ellipse_distances,
    ellipse_params,
    fit_ellipse,
    plausible,
    rms_residual,
    within_pairs,
    within_pairs_split,
)

#: The default settings (see MergeParams: the reasons for each).
DEFAULT = MergeParams()
#: Circumference samples are checked against the edge map dilated by this radius, px: one
#: pixel of quantisation either way. Not a setting: it defines the support measure itself,
#: which the merge, the top rule and the report all read, and against which their support
#: thresholds are set; changed in one place, their supports would no longer compare.
SUPPORT_RADIUS_PX = 1


@dataclass(frozen=True, kw_only=True)
class MergedEllipse:
    """One merged ellipse: its fit, segment indices, RMS residual (px) and support (0-1)."""

    ellipse: Ellipse
    segments: tuple[int, ...]
    residual_px: float
    support: float

    @classmethod
    def of(cls, ellipse: Ellipse, segments: tuple[int, ...], residual_px: float,
           support: float) -> MergedEllipse:
        """``MergedEllipse(ellipse=ellipse, ...)`` (an equal object) at a third of the frozen
        dataclass constructor's cost, as :meth:`~stackpick_sim.geometry.Ellipse.of`."""
        m = object.__new__(cls)
        d = m.__dict__
        d["ellipse"], d["segments"], d["residual_px"], d["support"] = (ellipse, segments,
                                                                      residual_px, support)
        return m


def support_map(edges: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(H, W) 0/1 map of pixels within SUPPORT_RADIUS_PX (Chebyshev) of an edge pixel."""
    side = 2 * SUPPORT_RADIUS_PX + 1
    return cast("NDArray[np.uint8]", cv2.dilate(edges, np.ones((side, side), np.uint8)))


def boundary_samples(ellipse: Ellipse) -> NDArray[np.float64]:
    """(n, 2) points about 1 px apart along the ellipse (Ramanujan's perimeter): the points
    of :func:`~stackpick_sim.vision.contrast.outline`, without its normals."""
    ct, st = unit_circle(max(16, math.ceil(perimeter_px(ellipse))))
    th = math.radians(ellipse.angle_deg)
    c, s = math.cos(th), math.sin(th)
    x, y = ellipse.a * ct, ellipse.b * st
    pts = np.empty((ct.shape[0], 2))
    pts[:, 0] = ellipse.cx + c * x - s * y
    pts[:, 1] = ellipse.cy + s * x + c * y
    return pts


def boundary_shares(ways: list[tuple[Ellipse, Ellipse]], tol_px: float) -> list[float]:
    """Per (one, other) pair: the share of one's :func:`boundary_samples` within ``tol_px``
    of other (:func:`~stackpick_sim.vision.fitting.distances`), all pairs in one array pass
    (the same values as pair by pair)."""
    if not ways:
        return []
    # The samples and their distances to the other ellipse in one compiled pass.
    shares = kernels.outline_near_shares(
        *outline_rows([one for one, _ in ways]),
        distance_rows(ellipse_params([other for _, other in ways])), tol_px)
    return cast("list[float]", shares.tolist())


def supported(ellipse: Ellipse, support: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(n,) bool per boundary sample: is there an edge pixel near it (off-image: False)."""
    pts = np.rint(boundary_samples(ellipse)).astype(np.int64)
    h, w = support.shape
    inside = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
    out = np.zeros(pts.shape[0], bool)
    out[inside] = support[pts[inside, 1], pts[inside, 0]] > 0
    return out


def support_shares(ellipses: list[Ellipse], support: NDArray[np.uint8], radius: int = 0
                   ) -> NDArray[np.float64]:
    """(E,) share of each ellipse's :func:`supported` boundary samples, all in one pass; with
    ``radius`` (px), ``support`` is the edge map itself and a sample counts when an edge
    pixel lies within that radius (Chebyshev) of it: ``support_shares(e, edges,
    SUPPORT_RADIUS_PX)`` equals ``support_shares(e, support_map(edges))`` without the
    dilated map."""
    if not ellipses:
        return np.zeros(0)
    # The rows and sample counts (contrast.outline_rows), then the rounded samples (as
    # boundary_samples' points) looked up in one compiled pass.
    return kernels.outline_support(np.ascontiguousarray(support, np.uint8),
                                   *outline_rows(ellipses), radius)


@dataclass(kw_only=True)
class _Groups:
    """The merge's working state: per group (one per fit at first) its ``members`` (the
    segment indices of its pieces) and ellipse (None once merged into another); ``owner``
    (N,) the group of each piece pixel; the (group, pixel) pairs within tolerance of the
    group's ellipse, ``pair_g`` and ``pair_p`` (K,) each; the ``refused`` pairs of groups;
    ``rest``: the pairs of the later chains' pixels with the fits as they were (None once a
    merge changed an ellipse)."""

    members: list[list[int]]
    ellipses: list[Ellipse | None]
    owner: NDArray[np.int64]
    pair_g: NDArray[np.int64]
    pair_p: NDArray[np.int64]
    refused: set[tuple[int, int]] = field(default_factory=set)
    rest: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None

    def alive(self) -> list[int]:
        """The groups not merged into another."""
        return [g for g, e in enumerate(self.ellipses) if e is not None]

    def join(self, gi: int, gj: int, merged: Ellipse, d: NDArray[np.float64],
             tol_px: float = DEFAULT.tolerance_px) -> None:
        """Merge group ``gj`` into ``gi``, whose ellipse becomes ``merged`` (``d``: the
        distances of every piece pixel to it; ``tol_px``: the pertaining distance)."""
        self.ellipses[gi], self.ellipses[gj] = merged, None
        self.rest = None  # the later chains' pairs are for the fits as they were
        self.members[gi] += self.members[gj]
        self.owner[self.owner == gj] = gi
        other = (self.pair_g != gi) & (self.pair_g != gj)
        close = (d < tol_px).nonzero()[0]
        self.pair_g = np.concatenate([self.pair_g[other], np.full(close.shape[0], gi)])
        self.pair_p = np.concatenate([self.pair_p[other], close])


class _Pieces(NamedTuple):
    """The fitted pieces' pixels: ``pixels`` (N, 2) int32 (the fits' input) and ``points``,
    the same as float64; ``everything``: all the chains' pixels (float64) when the pieces
    lead the chains (None otherwise). (A named tuple: built on every frame, at a fraction of
    a frozen dataclass's cost.)"""

    pixels: NDArray[np.int32]
    points: NDArray[np.float64]
    everything: NDArray[np.float64] | None


def merge_segments(chains: tuple[NDArray[np.int32], ...], fits: list[tuple[int, Ellipse]],
                   edges: NDArray[np.uint8], residuals: Sequence[float] | None = None,
                   params: MergeParams = DEFAULT, fits_params: FitParams = FIT_DEFAULT
                   ) -> list[MergedEllipse]:
    """Merge per-segment fits by Eq. 3, absorb leftovers, validate by support.

    ``chains`` are all edge segments, (N_i, 2) int32 (u, v); ``fits`` (segment index,
    ellipse) for those that fitted on their own (one segment may appear once per piece);
    ``edges`` the (H, W) 0/1 edge map; ``residuals`` the RMS residual (px) of each fit on
    its own segment, parallel to ``fits``, when known (:func:`~stackpick_sim.vision.fitting.
    fit_all` gives them): a group that stays that one fit keeps it rather than have it
    computed again. ``params``: the merge's settings; ``fits_params``: the axis bounds every
    refit is held to. Returns ellipses sorted by support, best first.

    Each group's pixels within tolerance are found once, when its ellipse is (re)fitted; a
    refused pair changes nothing, so the next best pair is read off the same counts.
    """
    shape = (int(edges.shape[0]), int(edges.shape[1]))
    if not fits:
        return []
    seg_of_piece = [i for i, _ in fits]
    # The pieces lead ``chains`` (as the detector passes them): the pairs of all the later
    # chains' pixels come in the same pass and serve the absorbing step while no merge
    # changes an ellipse.
    leading = seg_of_piece == list(range(len(fits)))
    pieces, state = _start(chains, fits, leading, params.tolerance_px)
    while _merge_best(state, pieces, shape, params, fits_params):
        pass
    # The pieces' pairs stay valid for absorbing when the pieces lead ``chains``.
    kept = state.alive()
    if len(kept) == len(state.ellipses):  # no merge: the groups keep their indices
        final_g = state.pair_g
    else:
        final = np.full(len(state.ellipses), -1, np.int64)
        final[kept] = np.arange(len(kept))
        final_g = final[state.pair_g]
    # A group still one fit on its own segment has that fit's residual, when given.
    own = [None if residuals is None or len(m) > 1 else residuals[g]
           for g, m in enumerate(state.members)]
    return _absorb_and_validate(chains, state.members, state.ellipses, edges,
                                (final_g, state.pair_p, pieces.points.shape[0]) if leading
                                else None, state.rest, pieces.everything, own, params,
                                fits_params)


def _start(chains: tuple[NDArray[np.int32], ...], fits: list[tuple[int, Ellipse]],
           leading: bool, tol_px: float = DEFAULT.tolerance_px) -> tuple[_Pieces, _Groups]:
    """The pieces' pixels and the merge's first state (a group per fit), with the (group,
    pixel) pairs within ``tol_px`` of each fit; when the pieces are the ``leading`` chains,
    those of the later chains' pixels too (:attr:`_Groups.rest`)."""
    seg_of_piece = [i for i, _ in fits]
    params = ellipse_params([e for _, e in fits])
    rest: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
    everything: NDArray[np.float64] | None = None
    sizes = [chains[i].shape[0] for i in seg_of_piece]
    if leading:
        all_pixels = np.concatenate(chains)
        everything = all_pixels.astype(np.float64)
        done = sum(sizes)
        pixels, points = all_pixels[:done], everything[:done]  # int32: the fits' input
        pair_g, pair_p, *later = within_pairs_split(params, everything, tol_px, done)
        rest = (later[0], later[1])
    else:
        pixels = np.concatenate([chains[i] for i in seg_of_piece])  # int32: the fits' input
        points = pixels.astype(np.float64)
        pair_g, pair_p = within_pairs(params, points, tol_px)
    owner = np.arange(len(fits)).repeat(sizes)
    state = _Groups(members=[[i] for i in seg_of_piece], ellipses=[e for _, e in fits],
                    owner=owner, pair_g=pair_g, pair_p=pair_p, rest=rest)
    return _Pieces(pixels=pixels, points=points, everything=everything), state


def _pair_scores(state: _Groups, alive: list[int]) -> NDArray[np.float64]:
    """(G, G) Eq. 3 products C = N_{A/B} N_{B/A} of the ``alive`` groups (in that order),
    0 on the diagonal and for refused pairs."""
    # N[b, a], the share of group a's pixels within tolerance of ellipse b, and the
    # products, in one compiled pass over the pairs (kernels.pair_products).
    if len(alive) == len(state.ellipses):  # no merge yet: the identity map, nothing refused
        c = kernels.pair_products(state.pair_g, state.pair_p, state.owner, len(alive))
        if not state.refused:
            return c
        remap = list(range(len(state.ellipses)))
    else:
        index = np.full(len(state.ellipses), -1, np.int64)
        index[alive] = np.arange(len(alive))
        c = kernels.pair_products(index[state.pair_g], state.pair_p, index[state.owner],
                                  len(alive))
        remap = index.tolist()
    for i, j in state.refused:
        if remap[i] >= 0 and remap[j] >= 0:
            c[remap[i], remap[j]] = c[remap[j], remap[i]] = 0.0
    return c


def _merge_best(state: _Groups, pieces: _Pieces, shape: tuple[int, int],
                params: MergeParams = DEFAULT, fits_params: FitParams = FIT_DEFAULT) -> bool:
    """Merge the best-scoring pair of groups whose union refits (refusing, in turn, those
    that do not); whether a pair merged."""
    alive = state.alive()
    if len(alive) < 2:
        return False
    c = _pair_scores(state, alive)
    while True:
        bi, bj = divmod(int(c.argmax()), len(alive))
        if c[bi, bj] <= params.k:
            return False
        gi, gj = alive[bi], alive[bj]
        union = _union_fit(pieces, state.owner, (gi, gj), shape, params, fits_params)
        if union is None:
            state.refused.add((gi, gj))
            c[bi, bj] = c[bj, bi] = 0.0
            continue
        state.join(gi, gj, *union, params.tolerance_px)
        return True


def _union_fit(pieces: _Pieces, owner: NDArray[np.int64], groups: tuple[int, int],
               shape: tuple[int, int], params: MergeParams = DEFAULT,
               fits_params: FitParams = FIT_DEFAULT) -> tuple[Ellipse, NDArray[np.float64]] | None:
    """The refit on the union of two ``groups`` and the distances of every piece pixel to
    it, when it is plausible (``fits_params``' axis bounds), within
    ``params.max_residual_px`` and keeps each group on it (:func:`_keeps_members`); None
    otherwise."""
    gi, gj = groups
    in_union = (owner == gi) | (owner == gj)
    merged = fit_ellipse(pieces.pixels[in_union])
    if merged is None or not plausible(merged, shape, fits_params):
        return None
    d = ellipse_distances(merged, pieces.points)
    if (float(np.sqrt(np.mean(d[in_union] ** 2))) > params.max_residual_px
            or not _keeps_members(d < params.tolerance_px, owner, groups,
                                  params.absorb_fraction)):
        return None
    return merged, d


def _repeats(chains: tuple[NDArray[np.int32], ...], extra: list[int], segs: list[int]) -> bool:
    """Whether every chain of ``extra`` equals one of ``segs`` pixel for pixel (a fitted
    piece repeats the chain it was cut from when it is that whole chain, most often as the
    same array: that is told first, by identity, without reading the pixels)."""
    own = [id(chains[k]) for k in segs]
    for s in extra:
        chain = chains[s]
        if id(chain) not in own and not any(
                chain.shape == chains[k].shape and chain.tobytes() == chains[k].tobytes()
                for k in segs):
            return False
    return True


def _keeps_members(on: NDArray[np.bool_], owner: NDArray[np.int64], groups: tuple[int, int],
                   fraction: float = DEFAULT.absorb_fraction) -> bool:
    """True when ``fraction`` of each merged group's pixels lie on the refit ellipse
    (``on``: (N,) pixel within tolerance of it).

    A low RMS residual alone lets a big ellipse pass between the arcs of two different
    faces; requiring each part to stay on the union's ellipse does not.
    """
    return all(float(on[owner == g].mean()) >= fraction for g in groups)


@dataclass(frozen=True, kw_only=True)
class _Chains:
    """All the chains' pixels at once: their ``sizes``, ``starts`` (S + 1,) and ``points``
    (N, 2) float64, concatenated in order."""

    sizes: list[int]
    starts: NDArray[np.int64]
    points: NDArray[np.float64]

    @classmethod
    def of(cls, chains: tuple[NDArray[np.int32], ...],
           everything: NDArray[np.float64] | None) -> _Chains:
        """The table of ``chains`` (``everything``: their pixels concatenated, float64, when
        at hand)."""
        sizes = [c.shape[0] for c in chains]
        return cls(sizes=sizes, starts=np.array([0, *itertools.accumulate(sizes)], np.int64),
                   points=(np.concatenate(chains).astype(np.float64) if everything is None
                           else everything))

    def rms(self, pairs: list[tuple[Ellipse, list[int]]]) -> list[float]:
        """RMS residual of each (ellipse, segments) pair, all in one pass."""
        if not pairs:
            return []
        # Each pair's pixels in ascending order (its segments ascending, each segment's
        # pixel range in turn): the order of the sums does not change.
        segs_all: list[int] = []
        per = []
        for _, segs in pairs:
            ordered = sorted(set(segs))
            segs_all += ordered
            per.append(len(ordered))
        # The distances and their sums per pair in one compiled pass.
        rms = kernels.segments_rms(distance_rows(ellipse_params([e for e, _ in pairs])),
                                   self.points, self.starts, np.array(segs_all, np.int64),
                                   np.array(per, np.int64))
        return cast("list[float]", rms.tolist())


def _lying_segments(table: _Chains, groups: list[tuple[list[int], Ellipse]],
                    known: tuple[NDArray[np.int64], NDArray[np.int64], int] | None,
                    rest: tuple[NDArray[np.int64], NDArray[np.int64]] | None,
                    params: MergeParams = DEFAULT) -> list[list[int]]:
    """Per group, the segments (ascending) with ``params.absorb_fraction`` of their pixels
    within ``params.tolerance_px`` of its ellipse (``known``, ``rest``: see
    :func:`_absorb_and_validate`; ``known`` and ``rest`` hold to that tolerance)."""
    # (group, pixel) pairs within tolerance; only their count per (group, segment) matters.
    # The ellipses' parameters only for the pairs not already at hand.
    if known is None:
        g_on, p_on = within_pairs(ellipse_params([e for _, e in groups]), table.points,
                                  params.tolerance_px)
    else:
        g_known, p_known, done = known
        if rest is None:
            g_rest, p_rest = within_pairs(ellipse_params([e for _, e in groups]),
                                          table.points[done:], params.tolerance_px)
            p_rest = p_rest + done
        else:
            g_rest, p_rest = rest
        g_on = np.concatenate([g_known, g_rest])
        p_on = np.concatenate([p_known, p_rest])
    lying: list[list[int]] = [[] for _ in groups]
    # The pairs' count per (group, segment) and the shares at the fraction, in one pass.
    on_g, on_s = kernels.lying_pairs(g_on, p_on, table.starts, len(groups),
                                     params.absorb_fraction)
    for g, s in zip(on_g.tolist(), on_s.tolist(), strict=True):
        lying[g].append(s)
    return lying


def _refits(chains: tuple[NDArray[np.int32], ...], groups: list[tuple[list[int], Ellipse]],
            extras: list[list[int]], shape: tuple[int, int], fits_params: FitParams
            ) -> tuple[dict[int, Ellipse | None], dict[int, float]]:
    """Each group refitted with its ``extras`` (the segments lying on it besides its own),
    unless they only repeat its pixels; the refits (None: failed or implausible) and the
    RMS residuals of those that came out, by group."""
    refits: dict[int, Ellipse | None] = {}
    refit_rms: dict[int, float] = {}
    for g, (segs, _) in enumerate(groups):
        # Extras that only repeat the group's pixels (the chains its pieces were cut from
        # whole) would refit the same points, each twice: the fit in hand, up to rounding.
        if not extras[g] or _repeats(chains, extras[g], segs):
            continue
        # The chains themselves (int32, in this order): the fit's input as it stands.
        union = np.concatenate([chains[s] for s in segs + extras[g]])
        refit = fit_ellipse(union)
        refits[g] = (refit if refit is not None and plausible(refit, shape, fits_params)
                     else None)
        if (e := refits[g]) is not None:
            # One ellipse, about one a frame: its residual on the fit's own input (the
            # same pixels) costs a third of a batched pass.
            refit_rms[g] = rms_residual(e, union)
    return refits, refit_rms


def _finals(groups: list[tuple[list[int], Ellipse]], extras: list[list[int]],
            refits: dict[int, Ellipse | None], refit_rms: dict[int, float],
            known_rms: list[float | None], table: _Chains, max_residual_px: float
            ) -> tuple[list[tuple[list[int], Ellipse]], list[float]]:
    """Per group, its final (segments, ellipse): the refit with its extras when that stays
    within ``max_residual_px`` (a segment fit's), the fit in hand without them when the refit
    strays, the fit in hand with them otherwise (not refitted, or the refit failed); and their
    RMS residuals (``known_rms``: per group, the residual of its fit on its own segments when
    known)."""
    residuals = _unrefitted_residuals(groups, extras, refits, known_rms, table)
    finals: list[tuple[list[int], Ellipse]] = []
    for g, (segs, ellipse) in enumerate(groups):
        refit = refits.get(g)
        if refit is not None and refit_rms[g] <= max_residual_px:
            finals.append((segs + extras[g], refit))
            residuals[g] = refit_rms[g]
        elif refit is not None:
            finals.append((segs, ellipse))  # the refit strays: the extras are not on it
            if (r := known_rms[g]) is not None:
                residuals[g] = r
        else:
            # Not refitted, or the fit failed: keep all, as fitted.
            finals.append((segs + extras[g], ellipse))
    todo = [g for g in range(len(finals)) if g not in residuals]
    residuals.update(zip(todo, table.rms([(finals[g][1], finals[g][0]) for g in todo]),
                         strict=True))
    return finals, [residuals[g] for g in range(len(finals))]


def _unrefitted_residuals(groups: list[tuple[list[int], Ellipse]], extras: list[list[int]],
                          refits: dict[int, Ellipse | None], known_rms: list[float | None],
                          table: _Chains) -> dict[int, float]:
    """The RMS residuals of the groups not refitted (kept as fitted, with any extras that
    only repeat their pixels), by group: the known one, else all computed in one pass."""
    plain = [g for g in range(len(groups)) if g not in refits and known_rms[g] is None]
    residuals: dict[int, float] = dict(zip(
        plain, table.rms([(groups[g][1], groups[g][0] + extras[g]) for g in plain]),
        strict=True))
    for g, r in enumerate(known_rms):
        if r is not None and g not in refits:
            residuals[g] = r  # as fitted, with only repeating extras: the same pixels
    return residuals


def _absorb_and_validate(chains: tuple[NDArray[np.int32], ...], members: list[list[int]],
                         ellipses: list[Ellipse | None], edges: NDArray[np.uint8],
                         known: tuple[NDArray[np.int64], NDArray[np.int64], int] | None = None,
                         rest: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
                         everything: NDArray[np.float64] | None = None,
                         own: Sequence[float | None] | None = None,
                         params: MergeParams = DEFAULT, fits_params: FitParams = FIT_DEFAULT
                         ) -> list[MergedEllipse]:
    """Add leftover segments lying on each final ellipse, refit (unless they only repeat
    its pixels), keep supported ones.

    ``known``: (group, pixel) index pairs (K,) each of the first P pixels of ``chains`` that
    lie on each final ellipse, and P, when already computed; ``rest``: the pairs of the other
    pixels too (pixel indices into all of ``chains``), when also computed; ``everything``:
    all the chains' pixels concatenated (float64), when at hand; ``own``: per group, the RMS
    residual of its ellipse on its own segments when known (None: not known), which stands
    for the residual on them and on extras that only repeat their pixels; ``params``: the
    absorbing share, the tolerance and the least support kept; ``fits_params``: the refits'
    axis bounds."""
    alive = [g for g, e in enumerate(ellipses) if e is not None]
    groups = [(sorted(set(members[g])), e) for g in alive if (e := ellipses[g]) is not None]
    if not groups:
        return []
    known_rms = [None if own is None else own[g] for g in alive]
    table = _Chains.of(chains, everything)
    lying = _lying_segments(table, groups, known, rest, params)
    extras = [[s for s in lying[g] if s not in segs] for g, (segs, _) in enumerate(groups)]
    shape = (int(edges.shape[0]), int(edges.shape[1]))
    refits, refit_rms = _refits(chains, groups, extras, shape, fits_params)
    finals, residuals = _finals(groups, extras, refits, refit_rms, known_rms, table,
                                fits_params.max_residual_px)
    # The edge map's support read round each sample: no dilated map.
    shares = support_shares([e for _, e in finals], edges, SUPPORT_RADIUS_PX).tolist()
    out = [MergedEllipse.of(e, tuple(segs), residuals[k], shares[k])
           for k, (segs, e) in enumerate(finals) if shares[k] >= params.min_support]
    out.sort(key=lambda m: -m.support)
    return out

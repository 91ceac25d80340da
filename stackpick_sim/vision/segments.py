"""Stage 2: link edge pixels into segments (paper section 2.2, Fig. 6).

Each edge pixel is classified by its count of 8-connected edge neighbours: 2 continues a
segment, 1 ends one, 3 or more is a junction. Junction pixels are cut out, every remaining
8-connected chain is traced in order (OpenCV's contour follower walks a one-pixel-wide open
chain from one end to the other and back; the first half is the ordered chain), and chains
are split again at corners, so a cylinder's straight side wall and the arc of its face that
meet at a corner are never fitted together.

Everything per pixel is done by OpenCV or numpy; Python loops run over segments only.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import SegmentParams
from stackpick_sim.vision import kernels

#: The default settings (see SegmentParams: the reasons for each).
DEFAULT = SegmentParams()


@dataclass(frozen=True, kw_only=True)
class EdgeSegments:
    """Edge segments of one image.

    ``chains``: ordered pixel chains, each (N_i, 2) int32 (u, v).
    ``edges``: (H, W) uint8 0/1 one-pixel-wide edge map the chains came from.
    """

    chains: tuple[NDArray[np.int32], ...]
    edges: NDArray[np.uint8]

    @property
    def junctions(self) -> NDArray[np.bool_]:
        """(H, W) bool, edge pixels with three or more edge neighbours (:func:`find_junctions`
        of ``edges``, on request: the detector does not read them)."""
        return find_junctions(self.edges)


def neighbour_count(binary: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(H, W) uint8 count of 8-neighbours set in a 0/1 image (0 outside the image).

    The 3x3 box sum less the pixel itself (3x faster than a filter2D with the 8-neighbour kernel,
    which gives the same counts).
    """
    box = cv2.boxFilter(binary, cv2.CV_8U, (3, 3), normalize=False,
                        borderType=cv2.BORDER_CONSTANT)
    return cast("NDArray[np.uint8]", cv2.subtract(box, binary))


def find_junctions(edges: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(H, W) bool: edge pixels of a 0/1 edge map with three or more edge neighbours."""
    return (neighbour_count(edges) >= 3) & (edges > 0)


def _order_chain(contour: NDArray[np.int32], is_end: NDArray[np.bool_]) -> NDArray[np.int32]:
    """Ordered (N, 2) chain from an OpenCV contour of a one-pixel-wide curve.

    ``contour`` is (M, 2) (u, v) and ``is_end`` (M,) marks end-point pixels. An open chain's
    contour runs end -> end -> back: the chain is the stretch from its first end pixel to the
    next; a closed one is already a loop.
    """
    return _order_by_ends(contour, is_end.nonzero()[0].tolist())


def _order_by_ends(contour: NDArray[np.int32], ends: list[int]) -> NDArray[np.int32]:
    """:func:`_order_chain` given the indices ``ends`` (ascending) of the end pixels."""
    if not ends:
        return contour
    first = ends[0]
    if len(ends) > 1:
        return contour[first: ends[1] + 1]
    return np.concatenate([contour[first:], contour[:first]])


def _vertex_index(chain: NDArray[np.int32], vertex: NDArray[np.int32]) -> int:
    """Index of the chain pixel equal to ``vertex`` (approxPolyDP keeps original points)."""
    hits = ((chain[:, 0] == vertex[0]) & (chain[:, 1] == vertex[1])).nonzero()[0]
    return int(hits[0])


def split_chain(chain: NDArray[np.int32], closed: bool, params: SegmentParams = DEFAULT
                ) -> list[NDArray[np.int32]]:
    """Split an ordered (N, 2) chain at corners and where its turning direction flips.

    Turns are read at the vertices of a polygonal approximation (tolerance
    ``params.poly_epsilon_px``) so pixel staircases do not count. A vertex is a cut when it
    turns by more than ``params.corner_angle_deg`` (a corner), is a lone sharp turn (see
    :class:`~stackpick_sim.config.vision_params.SegmentParams`) or turns against the sign of
    the previous signed vertex: an ellipse arc turns one way throughout, while the outline
    of two overlapping convex faces has a reflex corner where it passes from one to the
    other, even when Canny left no junction pixel there; S-bends flip too.
    """
    poly = cast("NDArray[np.int32]", cv2.approxPolyDP(chain.reshape(-1, 1, 2),
                                                     params.poly_epsilon_px, closed).reshape(-1, 2))
    count = poly.shape[0]
    if count < 3:
        return [chain]
    # The turns at the vertices and the cut pixels, in one compiled pass.
    found = kernels.corner_cuts(chain, poly, closed, params.corner_angle_deg,
                                params.spike_min_deg, params.spike_ratio,
                                params.min_signed_turn_deg)
    if not found.size:
        return [chain]
    cuts = found.tolist()
    if closed:
        first = cuts[0]
        chain = np.concatenate([chain[first:], chain[:first]])
        bounds = [c - first for c in cuts] + [chain.shape[0]]
    else:
        bounds = [0, *cuts, chain.shape[0]]
    return [chain[i:j] for i, j in itertools.pairwise(bounds) if j > i]


def link_segments(edges: NDArray[np.uint8], max_contours: int | None = None,
                  params: SegmentParams = DEFAULT) -> EdgeSegments:
    """Split a (H, W) 0/1 one-pixel-wide edge map into ordered segments of at least
    ``params.min_chain_px``; with ``max_contours``, only the longest that many connected
    pieces (in their order) are ordered and split (the cost of this stage is a Python pass
    per piece)."""
    shortest = params.min_chain_px
    # Junctions, cut out: edge pixels with 3+ edge neighbours, i.e. a 3x3 sum (the pixel
    # included) of 4+; end points of the map without them: a 3x3 sum of at most 2.
    box = cv2.boxFilter(edges, cv2.CV_8U, (3, 3), normalize=False,
                        borderType=cv2.BORDER_CONSTANT)
    # 1 where the 3x3 sum is at most 3, ANDed with the 0/1 edges: the kept edge pixels, 0/1.
    cut = cast("NDArray[np.uint8]", cv2.threshold(box, 3, 1, cv2.THRESH_BINARY_INV)[1])
    cv2.bitwise_and(cut, edges, cut)
    box = cv2.boxFilter(cut, cv2.CV_8U, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    contours, hierarchy = cv2.findContours(cut, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    chains: list[NDArray[np.int32]] = []
    if hierarchy is None:
        return EdgeSegments(chains=(), edges=edges)
    # Hole boundaries (with a parent) repeat their outer contour's pixels.
    parents = hierarchy[0][:, 3].tolist()
    kept = [cast("NDArray[np.int32]", c.reshape(-1, 2))
            for c, parent in zip(contours, parents, strict=True)
            if parent == -1 and c.shape[0] >= shortest]
    if not kept:
        return EdgeSegments(chains=(), edges=edges)
    if max_contours is not None and len(kept) > max_contours:
        longest = sorted(range(len(kept)), key=lambda i: (-kept[i].shape[0], i))
        kept = [kept[i] for i in sorted(longest[:max_contours])]
    # The end-point test of all contour pixels at once (each is a kept pixel: only its 3x3
    # sum is read), then each contour's share of it.
    every = np.concatenate(kept)
    is_end_px = box.ravel()[every[:, 1] * edges.shape[1] + every[:, 0]] <= 2
    end_at = is_end_px.nonzero()[0].tolist()
    k = 0
    start = 0
    for pts in kept:
        stop = start + pts.shape[0]
        ends = []
        while k < len(end_at) and end_at[k] < stop:
            ends.append(end_at[k] - start)
            k += 1
        start = stop
        chain = _order_by_ends(pts, ends)
        if chain.shape[0] < shortest:
            continue  # its arcs would be shorter still
        for arc in split_chain(chain, closed=not ends, params=params):
            if arc.shape[0] >= shortest:
                chains.append(arc)
    return EdgeSegments(chains=tuple(chains), edges=edges)

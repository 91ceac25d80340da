"""Stage 2: link edge pixels into segments (paper section 2.2, Fig. 6).

Each edge pixel is classified by its count of 8-connected edge neighbours: 2 continues a
segment, 1 ends one, 3 or more is a junction. Junction pixels are cut out, every remaining
8-connected chain is traced in order (a border follower, the one of OpenCV's contour finder,
walks a one-pixel-wide open chain from one end to the other and back; the first half is the
ordered chain), and chains are split again at corners, so a cylinder's straight side wall and
the arc of its face that meet at a corner are never fitted together.

Everything per pixel is done by compiled passes; no Python loop runs per segment.
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
                  params: SegmentParams = DEFAULT, pixels: NDArray[np.float64] | None = None
                  ) -> EdgeSegments:
    """Split a (H, W) 0/1 one-pixel-wide edge map into ordered segments of at least
    ``params.min_chain_px``; with ``max_contours``, only the longest that many connected
    pieces (in their order) are ordered and split. ``pixels``: the map's set pixels (M, 2)
    (u, v) in row-major order when at hand (the edge stage lists them; pixels that are not
    exactly those are ignored, and the map is read instead).

    One compiled call (:func:`~stackpick_sim.vision.kernels.linked_chains`): the junctions
    cut out and the end points marked, the pieces' outer borders (OpenCV's contours), the
    contours ordered from end to end, the chains' polygonal approximations (OpenCV's), the
    chains cut at their corners (:func:`split_chain`, all chains at once)."""
    edges = np.ascontiguousarray(edges, np.uint8)
    rows, cols = _set_pixels(edges, pixels)
    # Every pass in one compiled call (kernels.linked_chains): the junctions cut, the pieces'
    # outer borders (cv2.findContours' contours without a parent: hole boundaries repeat
    # their outer contour's pixels) over the edge pixels, the longest that many, ordered,
    # their polygons (cv2.approxPolyDP's) and the arcs between their corners.
    turned, arcs = kernels.linked_chains(
        edges, rows, cols, -1 if max_contours is None else int(max_contours),
        int(params.min_chain_px), float(params.poly_epsilon_px),
        (float(params.corner_angle_deg), float(params.spike_min_deg),
         float(params.spike_ratio), float(params.min_signed_turn_deg)))
    return EdgeSegments(chains=tuple([turned[i:j] for i, j in arcs.tolist()]), edges=edges)


def _set_pixels(edges: NDArray[np.uint8], pixels: NDArray[np.float64] | None
                ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The rows and columns of the set pixels of the 0/1 map ``edges``, row-major: those of
    ``pixels`` (M, 2) (u, v) when they are as many whole pixels (the kernels check that they
    are the map's), else the map's own."""
    if pixels is not None and pixels.shape[0] == cv2.countNonZero(edges):
        # The (2, M) rows u, v the columns are a view of, when they are.
        uv = pixels.T if pixels.T.flags.c_contiguous else np.ascontiguousarray(pixels.T)
        rows, cols, whole = kernels.uv_rows_cols(np.asarray(uv, np.float64))
        if whole:
            return rows, cols
    return kernels.set_pixels(edges)

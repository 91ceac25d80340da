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
wall_cover`). Given the colour image as well, a candidate whose reconstructed cylinder
another candidate's touches from above (a lean on its side wall, below its face, shows no
T-junction) lies under it (:mod:`stackpick_sim.vision.resting`); one face fitted twice shares
that verdict.

Given each face's radius (from its colour) and the intrinsics, a candidate nearer the camera
than every other by DEPTH_TIE_M wins (a second fit of the same face is no rival); faces that
failed on support alone with nothing crossing them take part in this test too. Otherwise the
best-supported candidate wins (ties within SUPPORT_TIE go to the larger ellipse, which is
nearer the camera for equal radii). When no ellipse passes, :func:`select_unobstructed` is
the last resort: a face with no T-junction and no edge inside it, most of whose outline shows
(FALLBACK_MIN_SUPPORT), lies under nothing visible; its gaps are boundaries too faint to see.
After the detector's contrast refit, :func:`select_rimmed` is the next: a whole face whose
only interior edges lie within RIM_BAND_PX of its outline (its own faint rim, fitted on a
same-colour lower face's sliver beyond it). Such a face can also lie on the face the rule
chose: :func:`select_resting_rimmed` (called by the detector on a choice) takes it when its
cylinder, refitted on its innermost edge, rests on the chosen one's.
Given the object kinds' radii (the detector's ``markings`` settings), an ellipse that is a
marking or relief inside a larger face's outline (printed artwork, a can end's groove) is no
candidate, and a face whose outline shows whole and whose interior edges are only its own
markings is one (:mod:`~stackpick_sim.vision.markings`).
The rule needs only a list of ellipses and an edge map, so it applies to any detector's
ellipses.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels
from stackpick_sim.vision.contrast import (
    REFIT_DEFAULT,
    REFIT_INNER_REACH_PX,
    contrast_profiles,
    contrast_threshold,
    outlines,
    refit_on_contrast,
)
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.markings import MarkingTest, find_markings, holds_centre
from stackpick_sim.vision.merging import MERGE_TOLERANCE_PX, support_map
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.resting import rests_on
from stackpick_sim.vision.wall_cover import BandCache, under_another

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
#: outlines of objects lying under it stay outside its face.
CROSSING_REACH_PX = 6.0
#: Edge pixels farther than this inside the outline (px) count as interior edges.
INTERIOR_MARGIN_PX = 2.5
#: Interior edge pixels allowed, as a share of the perimeter (isolated noise edges).
MAX_INTERIOR_SHARE = 0.05
#: A candidate face nearer the camera than every other by this much (m) is the top: an
#: object resting on another's wall lies higher than it though both faces show whole. Face
#: depths of one pile's top candidates that were not clearly ordered differ by < 1 cm on
#: rendered paper-scene frames; the fit's depth error is ~1 mm.
DEPTH_TIE_M = 0.01
#: Candidates whose supports differ by less than this are tied.
SUPPORT_TIE = 0.02
#: Last resort (:func:`select_unobstructed`), when no ellipse passes the rule: a face with no
#: T-junction and no edge pixel inside, with edge contrast along at least this share of its
#: outline. An occluder's outline runs into the face it covers (interior edges, T-ends), so
#: such a face's gaps are boundaries too faint even for the contrast test: a top face over a
#: lower face of its colour and shade (~0.80 on rendered paper-scene frames). Far rims and
#: arcs of two outlines fitted together show about half their outline (0.5-0.6). Not proof
#: on its own: lower faces whose occluder only clips their rim also reach 0.75-0.88 with no
#: edge inside (on the same frames), so this evidence is used only when nothing passes, or
#: with the DEPTH_TIE_M margin. Placeholder chosen on those frames, not tuned further.
FALLBACK_MIN_SUPPORT = 0.75

#: Default of TopParams.hidden_min_support (see there).
HIDDEN_MIN_SUPPORT = TopParams().hidden_min_support

#: Last resort after the contrast refit (:func:`select_rimmed`): edge pixels inside a face's
#: outline by at most this (px) can be its own rim. A top face lying on a lower face of its
#: own colour and about its size is fitted on the lower face's strong silhouette where the
#: lower face shows a sliver beyond it; its own faint boundary then lies up to a few px inside
#: the fit (the contrast refit's inward reach, see REFIT_INNER_REACH_PX; 3-4 px measured on
#: rendered paper-scene frames), and where it is too near the silhouette for the contrast refit
#: to separate it, the fit keeps it inside as "interior edges". An occluder's outline runs
#: across the face, deeper than this. Such a fit is too large by up to this much, so its depth
#: from its size reads too near (up to ~2 cm for a small face at 0.22 m): it is no evidence
#: in the depth test (a lower face's misfit can win it, as on the paper scene with
#: objects.count = [5, 5]), only a last resort.
RIM_BAND_PX = float(REFIT_INNER_REACH_PX)
#: A face's semi-major axis is at least f r / z px and perspective enlarges it by up to this
#: factor on the paper scene's frames (see GateParams.slack): the slack of a depth
#: compared through r / a.
PERSPECTIVE_ENLARGEMENT = 1.04


@dataclass(frozen=True, kw_only=True)
class OcclusionEvidence:
    """Occlusion evidence of one ellipse against an edge map."""

    support: float
    longest_gap_px: int
    occluded_ends: int
    interior_edge_px: int
    perimeter_px: int

    @classmethod
    def of(cls, support: float, longest_gap_px: int, occluded_ends: int,
           interior_edge_px: int, perimeter_px: int) -> OcclusionEvidence:
        """``OcclusionEvidence(support=support, ...)`` (an equal object) at a fraction of the
        frozen dataclass constructor's cost, as :meth:`~stackpick_sim.geometry.Ellipse.of`:
        :func:`evidence_all` builds one per ellipse."""
        ev = object.__new__(cls)
        d = ev.__dict__
        d["support"], d["longest_gap_px"], d["occluded_ends"] = (support, longest_gap_px,
                                                                 occluded_ends)
        d["interior_edge_px"], d["perimeter_px"] = interior_edge_px, perimeter_px
        return ev

    @property
    def weakly_supported(self) -> bool:
        """Edge support along less than TOP_MIN_SUPPORT of the circumference."""
        return self.support < TOP_MIN_SUPPORT

    @property
    def edges_inside(self) -> bool:
        """More interior edge pixels than MAX_INTERIOR_SHARE of the perimeter."""
        return self.interior_edge_px > MAX_INTERIOR_SHARE * self.perimeter_px

    @property
    def occluded(self) -> bool:
        """True when any evidence says something lies on this ellipse (a :attr:`reason`;
        the same tests, without writing it)."""
        return bool(self.occluded_ends) or self.weakly_supported or self.edges_inside

    @property
    def reason(self) -> str:
        """Why the ellipse is taken as occluded; "" when it is a top candidate."""
        if self.occluded_ends:
            return f"{self.occluded_ends} edge end(s) at T-junctions"
        if self.weakly_supported:
            return f"support {self.support:.2f} < {TOP_MIN_SUPPORT}"
        if self.edges_inside:
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


def evidence_for(ellipse: Ellipse, edge_points: NDArray[np.float64],
                 support: NDArray[np.uint8], gradients: EdgeImage | None = None
                 ) -> OcclusionEvidence:
    """Occlusion evidence of ``ellipse`` given the edge pixels (M, 2) (u, v) and the
    (H, W) 0/1 support map (edges dilated by SUPPORT_RADIUS_PX); see :func:`evidence_all`."""
    return evidence_all([ellipse], edge_points, support, gradients)[0]


def evidence_all(ellipses: Sequence[Ellipse], edge_points: NDArray[np.float64],
                 support: NDArray[np.uint8] | None, gradients: EdgeImage | None = None
                 ) -> tuple[OcclusionEvidence, ...]:
    """Occlusion evidence of each ellipse given the edge pixels (M, 2) (u, v) (integer
    pixel coordinates, any order; row-major order, np.nonzero's, spares a sort) and the
    (H, W) 0/1 support map (edges dilated by SUPPORT_RADIUS_PX; unused with ``gradients``).

    With ``gradients`` the circumference's support is read from the consistent edge contrast
    (:mod:`stackpick_sim.vision.contrast`), which also sees edges too faint for the edge map.
    All ellipses are handled together: their outlines are one array, the interior edges are
    counted row by row (:func:`_interior_counts`), and the pixels near the gap ends are
    (end, pixel) pairs of one array.
    """
    if not ellipses:
        return ()
    lines = outlines(ellipses)
    samples = lines.points
    if gradients is not None:
        ok = contrast_profiles(lines, gradients) >= contrast_threshold(gradients)
    else:
        assert support is not None
        pix = np.rint(samples).astype(np.int64)
        h, w = support.shape
        inside = (pix[:, 0] >= 0) & (pix[:, 0] < w) & (pix[:, 1] >= 0) & (pix[:, 1] < h)
        ok = np.zeros(pix.shape[0], bool)
        ok[inside] = support[pix[inside, 1], pix[inside, 0]] > 0
    n_e = len(ellipses)
    # Any order of the pixels gives the same evidence: row-major, as the counts need.
    edge_points, keys, width = _row_major(edge_points)
    interior = _interior_counts(ellipses, keys, width, INTERIOR_MARGIN_PX)
    counts = lines.counts
    support_share = (np.add.reduceat(ok, lines.offsets[:-1], dtype=np.int64) / counts).tolist()
    # Gaps: cyclic runs of unsupported samples, from their first and last samples (a few a
    # frame: paired on Python ints).
    unsupported = ~ok
    firsts = (unsupported & ok[lines.window[2]]).nonzero()[0].tolist()  # sample before: ok
    sizes = counts.tolist()
    longest = [0 if supported else n
               for supported, n in zip(ok[lines.offsets[:-1]].tolist(), sizes, strict=True)]
    occluded_ends = [0] * n_e
    if firsts:
        lasts = (unsupported & ok[lines.window[3]]).nonzero()[0].tolist()  # sample after: ok
        ends, owners = _gap_ends(firsts, lasts, lines.offsets.tolist(), longest)
        if ends:
            for e in _junction_owners(ellipses, np.array(owners), samples[ends],
                                      edge_points):
                occluded_ends[e] += 1
    return tuple(map(OcclusionEvidence.of, support_share, longest, occluded_ends, interior,
                     sizes))


def _gap_ends(firsts: list[int], lasts: list[int], offsets: list[int], longest: list[int]
              ) -> tuple[list[int], list[int]]:
    """The supported samples at the ends of the gaps (runs of unsupported samples of at
    least MIN_GAP_PX along their outline, cyclic) and each one's outline, given every run's
    first and last samples (``firsts``, ``lasts``: ascending global sample indices) and the
    outlines' sample ``offsets`` (E + 1); ``longest`` (per outline) is raised to the longest
    run of each outline with runs."""
    ends: list[int] = []
    owners: list[int] = []
    runs: dict[int, int] = {}
    for first in firsts:
        e = bisect.bisect_right(offsets, first) - 1
        start, stop = offsets[e], offsets[e + 1]
        # The run's last sample: the first last at or after its first in its outline, else
        # (the run wraps round the outline's start) the outline's first last.
        j = bisect.bisect_left(lasts, first)
        last = (lasts[j] if j < len(lasts) and lasts[j] < stop
                else lasts[bisect.bisect_left(lasts, start)])
        length = (last - first) % (stop - start) + 1
        if length > runs.get(e, 0):
            runs[e] = length
        if length >= MIN_GAP_PX:
            ends += [first - 1 if first > start else stop - 1,
                     last + 1 if last + 1 < stop else start]
            owners += [e, e]
    for e, length in runs.items():
        longest[e] = length
    return ends, owners


def _row_major(edge_points: NDArray[np.float64]
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The edge pixels (M, 2) (integer u, v >= 0) in row-major order (sorted only when they
    are not: np.nonzero's order already is), their ascending keys v W + u, and W (past the
    largest u), as :func:`_interior_counts` takes them."""
    # The width, the keys and their order in one compiled pass (kernels.row_keys: the same
    # values as the array form).
    keys, width, ascending = kernels.row_keys(
        np.ascontiguousarray(edge_points[:, 0], np.float64),
        np.ascontiguousarray(edge_points[:, 1], np.float64))
    if not ascending:
        order = np.argsort(keys, kind="stable")
        edge_points, keys = edge_points[order], keys[order]
    return edge_points, keys, width


def _interior_counts(ellipses: Sequence[Ellipse], keys: NDArray[np.float64], width: int,
                     margin_px: float) -> list[int]:
    """Per ellipse: how many edge pixels lie inside its axes less ``margin_px`` (x^2 + y^2 <
    1 in its shrunk axes, as Ellipse.inside), the pixels (integer u, v >= 0) given by their
    ascending row-major keys v ``width`` + u (``width`` past the largest u; see
    :func:`_row_major`).

    Row by row: on row v the inside is the open interval of u between the roots of the
    quadratic x^2 + y^2 = 1, and the pixels in it are a range of the keys (two binary
    searches); every (ellipse, row) pair in one array pass."""
    params, sizes = [], []
    for e in ellipses:
        t = math.radians(e.angle_deg)
        c, s = math.cos(t), math.sin(t)
        ia = 1.0 / max(e.a - margin_px, 1e-6) ** 2
        ib = 1.0 / max(e.b - margin_px, 1e-6) ** 2
        # x^2 + y^2 = p du^2 + q du dv + r dv^2 about the centre.
        p, q, r = c * c * ia + s * s * ib, 2.0 * c * s * (ia - ib), s * s * ia + c * c * ib
        half = math.sqrt(p / (p * r - 0.25 * q * q))  # the rows it spans: |dv| <= half
        first = math.ceil(e.cy - half)
        params.append((e.cx, e.cy, p, q, r, float(first)))
        sizes.append(max(0, math.floor(e.cy + half) - first + 1))
    # Open intervals of u per row, clipped to the keys' columns (an empty one where the
    # roots are not real), and the keys in each: one compiled pass (kernels.interior_counts).
    counts = kernels.interior_counts(np.array(params, np.float64).reshape(-1, 6),
                                     np.array(sizes, np.int64),
                                     np.ascontiguousarray(keys, np.float64), width)
    return cast("list[int]", counts.tolist())


def _junction_owners(ellipses: Sequence[Ellipse], owner: NDArray[np.int64],
                     ends: NDArray[np.float64], edge_points: NDArray[np.float64]) -> list[int]:
    """The ellipse (``owner``, indices into ``ellipses``) of each gap end
    (``ends``, (K, 2) outline samples) that is a T-junction: an edge pixel (of the (M, 2)
    ``edge_points``, in row-major order) off the ellipse (Sampson distance above
    MERGE_TOLERANCE_PX) lies within JUNCTION_RADIUS_PX of it, and one inside the outline by
    more than MERGE_TOLERANCE_PX within CROSSING_REACH_PX of it. Only the pixels of the rows
    within reach of an end are tested, all (end, pixel) pairs in one pass."""
    reach = max(JUNCTION_RADIUS_PX, CROSSING_REACH_PX)
    # Per ellipse: centre, cos, sin, axes and the axes less the inner margin (an occluder's
    # pixels run into the face). The (end, pixel) tests in one compiled pass
    # (kernels.junction_ends: the same arithmetic as the pairs' array form).
    rows = []
    for e in ellipses:
        t = math.radians(e.angle_deg)
        rows.append((e.cx, e.cy, math.cos(t), math.sin(t), e.a, e.b,
                     max(e.a - MERGE_TOLERANCE_PX, 1e-6), max(e.b - MERGE_TOLERANCE_PX, 1e-6)))
    both = kernels.junction_ends(
        np.ascontiguousarray(edge_points[:, 0]), np.ascontiguousarray(edge_points[:, 1]),
        np.ascontiguousarray(ends, np.float64), np.asarray(owner, np.int64),
        np.array(rows, np.float64).reshape(-1, 8), float(reach),
        float(JUNCTION_RADIUS_PX ** 2), float(CROSSING_REACH_PX ** 2), MERGE_TOLERANCE_PX)
    return cast("list[int]", owner[both].tolist())


def clearly_nearest(faces: list[Ellipse], intrinsics: CameraIntrinsics,
                     radius_of: Callable[[Ellipse], float | None]) -> int | None:
    """Index of the face nearer the camera than every other by DEPTH_TIE_M (face-centre
    depth from its radius), or None when a radius is unknown or no face is clearly nearest.

    Faces of two objects that both show whole do not overlap, so a candidate holding the
    nearest one's centre, or whose centre it holds, is that face fitted twice: it is no rival.
    """
    depths = []
    for face in faces:
        radius = radius_of(face)
        if radius is None:
            return None
        # The unit-radius solutions' depths scaled on floats (the same values as
        # circle_poses' scaled centres, without their arrays).
        unit = unit_circle_poses(face, intrinsics)
        depths.append(0.5 * (float(unit[0].centre_cam[2]) * radius
                             + float(unit[1].centre_cam[2]) * radius))
    nearest = int(np.argmin(depths))
    rivals = [d for face, d in zip(faces, depths, strict=True)
              if not (holds_centre(face, faces[nearest])
                      or holds_centre(faces[nearest], face))]
    if rivals and min(rivals) - depths[nearest] < DEPTH_TIE_M:
        return None
    return nearest


def select_unobstructed(evidence: Sequence[OcclusionEvidence]) -> int | None:
    """Index of the best-supported ellipse with no T-junction end, no interior edge pixel and
    support >= FALLBACK_MIN_SUPPORT, or None: the top rule's last resort when no ellipse
    passes it (see FALLBACK_MIN_SUPPORT)."""
    ok = [i for i, ev in enumerate(evidence) if unobstructed(ev)]
    return max(ok, key=lambda i: evidence[i].support, default=None)


def hidden_by_no_outline(choice: TopChoice, min_support: float = HIDDEN_MIN_SUPPORT) -> bool:
    """Whether an ellipse besides the chosen one failed the rule on support alone (at least
    ``min_support``, below TOP_MIN_SUPPORT) with no T-junction end and no edge pixel
    inside: the failure class *top face hidden by same-colour neighbours*. An occluder whose
    outline shows runs into the face it covers (interior edges, T-ends); a face cut short with
    nothing crossing it lies under a face whose boundary with it shows no contrast, a face of
    its colour and shade that the merge may never have fitted, which can be the top."""
    return any(i != choice.index and not ev.occluded_ends and not ev.interior_edge_px
               and min_support <= ev.support < TOP_MIN_SUPPORT
               for i, ev in enumerate(choice.evidence))


def deep_edge_counts(ellipses: Sequence[Ellipse], edge_points: NDArray[np.float64],
                     depth_px: float) -> list[int]:
    """Per ellipse: how many edge pixels (M, 2) (integer u, v >= 0) lie inside it by more
    than ``depth_px`` (its axes shrunk by that much, as the interior-edge count measures;
    :func:`_interior_counts`, row by row: np.nonzero's order, as
    :func:`~stackpick_sim.vision.refine.edge_points` gives them, spares a sort)."""
    _, keys, width = _row_major(edge_points)
    return _interior_counts(ellipses, keys, width, depth_px)


def rim_only(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
             edge_points: NDArray[np.float64]) -> list[int]:
    """Indices of the ellipses that failed the top rule on interior edges alone (no
    T-junction end, support >= TOP_MIN_SUPPORT) and whose interior edge pixels all but
    MAX_INTERIOR_SHARE of the perimeter lie within RIM_BAND_PX of the outline (see
    RIM_BAND_PX): a whole face with its own rim inside its fit."""
    failed = [i for i, ev in enumerate(evidence)
              if not ev.occluded_ends and not ev.weakly_supported and ev.edges_inside]
    if not failed:
        return []
    deep = deep_edge_counts([ellipses[i] for i in failed], edge_points, RIM_BAND_PX)
    return [i for i, d in zip(failed, deep, strict=True)
            if d <= MAX_INTERIOR_SHARE * evidence[i].perimeter_px]


def select_rimmed(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                  edge_points: NDArray[np.float64]) -> int | None:
    """Index of the best-supported of the :func:`rim_only` ellipses (ties within SUPPORT_TIE
    to the larger), or None: a last resort when no ellipse passes the rule, nor after the
    contrast refit (see RIM_BAND_PX)."""
    ok = rim_only(ellipses, evidence, edge_points)
    return _best_supported(ok, ellipses, evidence) if ok else None


def select_resting_rimmed(ellipses: Sequence[Ellipse], choice: TopChoice, edges: EdgeImage,
                          edge_points: NDArray[np.float64], intrinsics: CameraIntrinsics,
                          radius_of: Callable[[Ellipse], float | None],
                          height_of: Callable[[float], float | None], image: NDArray[np.uint8],
                          belt: NDArray[np.float64] | None = None,
                          params: TopParams = REFIT_DEFAULT) -> int | None:
    """Index of a :func:`rim_only` ellipse whose object rests on the chosen face's, or None.

    The top rule's choice can be a whole lower face with a top face resting on it whose fit
    took in a same-colour lower face's sliver (see RIM_BAND_PX): that fit fails on its own
    rim inside it, and the lower face wins. The rest test (:mod:`~stackpick_sim.vision.
    resting`) tells them apart once the rimmed face is refitted on its innermost consistent
    edge (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`; the fit itself is too
    large, its depth too near): a rimmed face whose cylinder rests on the chosen one is above
    it, and the chosen face is not top (nothing may rest on a top object). Of several, the
    best-supported (:func:`select_rimmed`'s order).

    The refit and the rest test (~1 ms) run only for a rimmed face whose fit reads nearer
    the camera than the chosen face, up to PERSPECTIVE_ENLARGEMENT (a cost gate, on about one
    frame in fifty of the paper scene's; one in nine has a rimmed face): the fit is too large,
    so it reads nearer than its face is, and a face reading farther lies below the chosen
    one; such a lower face resting on it (a lean on its wall, below its face) is left to the
    top rule. ``belt``: the bare belt's colour in ``image``, for the rest test's wall bands;
    ``params``: the contrast refit's settings (the ``contrast_*`` fields)."""
    if choice.index is None or image.ndim != 3:
        return None
    evidence = choice.evidence
    rimmed = rim_only(ellipses, evidence, edge_points)
    if not rimmed:
        return None
    chosen = ellipses[choice.index]
    radius = radius_of(chosen)
    if radius is None:
        return None
    # Depth ~ radius / semi-major axis (f r / a; perspective enlarges a by up to
    # PERSPECTIVE_ENLARGEMENT, either face): a gate, not a measurement.
    depth = radius / chosen.a * PERSPECTIVE_ENLARGEMENT
    nearer = [i for i in rimmed if (own := radius_of(ellipses[i])) is not None
              and own / ellipses[i].a < depth]
    above = []
    for i in nearer:
        face = refit_on_contrast(ellipses[i], edges, True, params) or ellipses[i]
        if rests_on([chosen, face], intrinsics, radius_of, height_of, image, belt=belt)[0]:
            above.append(i)
    return _best_supported(above, ellipses, evidence) if above else None


def _best_supported(indices: Sequence[int], ellipses: Sequence[Ellipse],
                    evidence: Sequence[OcclusionEvidence]) -> int:
    """The best-supported of ``indices`` (non-empty); ties within SUPPORT_TIE go to the larger
    ellipse, which is nearer the camera for equal radii."""
    best = max(evidence[i].support for i in indices)
    return max((i for i in indices if evidence[i].support >= best - SUPPORT_TIE),
               key=lambda i: ellipses[i].area)


def unobstructed(ev: OcclusionEvidence) -> bool:
    """No T-junction end, no interior edge pixel, support >= FALLBACK_MIN_SUPPORT."""
    return (not ev.occluded_ends and not ev.interior_edge_px
            and ev.support >= FALLBACK_MIN_SUPPORT)


def _markings(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
              edge_points: NDArray[np.float64], test: MarkingTest | None,
              radius_of: Callable[[Ellipse], float | None] | None
              ) -> tuple[frozenset[int], frozenset[int]]:
    """(markings, marked faces) of :func:`~stackpick_sim.vision.markings.find_markings`
    (both empty without a ``test``), less the marked faces whose interior edges all lie in
    their rim band: a fit too large for its face (see RIM_BAND_PX), not a face with markings
    across it."""
    if test is None:
        return frozenset(), frozenset()
    found = find_markings(ellipses, evidence, test, radius_of)
    order = sorted(found.marked)
    if not order:
        return found.markings, found.marked
    rimmed = rim_only([ellipses[i] for i in order], [evidence[i] for i in order], edge_points)
    return found.markings, found.marked - {order[k] for k in rimmed}


def select_top(ellipses: Sequence[Ellipse], edges: NDArray | EdgeImage,
               intrinsics: CameraIntrinsics | None = None,
               radius_of: Callable[[Ellipse], float | None] | None = None, *,
               edge_points: NDArray[np.float64] | None = None,
               image: NDArray[np.uint8] | None = None,
               height_of: Callable[[float], float | None] | None = None,
               colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None,
               belt: NDArray[np.float64] | None = None,
               markings: MarkingTest | None = None) -> TopChoice:
    """Apply the top-object rule to any ellipses over a one-pixel-wide (H, W) edge map.

    ``edges`` is nonzero on edge pixels (e.g. :func:`stackpick_sim.vision.edges.detect_edges`)
    or, better, the whole :class:`~stackpick_sim.vision.edges.EdgeImage` (then faint but
    consistent edges count as support too). With ``intrinsics`` (K in the edge map's pixel
    frame), a candidate whose side wall runs under another candidate's face loses to it
    (:mod:`stackpick_sim.vision.wall_cover`; with ``radius_of``, only where that face lies in
    front of the wall). With ``intrinsics`` and ``radius_of`` (an
    ellipse's face radius, m, or None if unknown) the nearest remaining candidate wins when
    it is nearer than the others (other than fits of the same face) by DEPTH_TIE_M; faces
    that failed on support alone with nothing crossing them (:func:`select_unobstructed`'s)
    take part in this depth test too. With ``intrinsics``, ``radius_of``, ``height_of`` (the
    cylinder height, m, of a face radius, or None if unknown) and the (H, W, 3) RGB ``image``
    (the edge map's pixel frame), a candidate whose reconstructed cylinder another
    candidate's rests on loses to it (:mod:`stackpick_sim.vision.resting`), before the depth
    test. Returns the chosen index (else the
    best-supported unoccluded ellipse) or None with the reason. ``edge_points``: the edge
    map's pixels (M, 2) (u, v) in ``np.nonzero`` order, when the caller has them already;
    ``colour_of``: a face's colour in ``image`` (:func:`~stackpick_sim.vision.wall.
    face_colour`), when the caller keeps them; ``belt``: the bare belt's colour in ``image``
    (:attr:`~stackpick_sim.vision.roi.Roi.belt`), for the rest test's wall bands. With
    ``markings`` (its settings), an ellipse that is a marking or relief inside a whole face is
    no candidate, and a whole face that holds only such markings is one
    (:mod:`~stackpick_sim.vision.markings`).
    """
    if not ellipses:
        return TopChoice(index=None, evidence=(), reason="no ellipses")
    evidence, edge_points = _evidence_and_pixels(ellipses, edges, edge_points)
    inner, marked = _markings(ellipses, evidence, edge_points, markings, radius_of)
    candidates = [i for i, ev in enumerate(evidence)
                  if (not ev.occluded or i in marked) and i not in inner]
    if not candidates:
        return TopChoice(index=None, evidence=evidence,
                         reason=f"all {len(ellipses)} ellipses occluded")
    # The depth test also hears faces that failed on support alone with nothing crossing
    # them (see FALLBACK_MIN_SUPPORT): one clearly nearer than every whole face is above them.
    pool = candidates + [i for i, ev in enumerate(evidence)
                         if ev.occluded and unobstructed(ev) and i not in marked | inner]
    cues = _Cues(intrinsics=intrinsics, radius_of=radius_of, height_of=height_of, image=image,
                 colour_of=colour_of, belt=belt)
    # The candidates' wall bands, computed once for the cover and the rest tests.
    bands: BandCache = {}
    pool, candidates = _cover_test(ellipses, pool, candidates, cues, bands)
    pool, candidates = _rest_test(ellipses, pool, candidates, cues, bands)
    nearest = _clearly_nearest_of(ellipses, pool, intrinsics, radius_of)
    if nearest is not None:
        return TopChoice(index=nearest, evidence=evidence)
    return TopChoice(index=_best_supported(candidates, ellipses, evidence), evidence=evidence)


def _evidence_and_pixels(ellipses: Sequence[Ellipse], edges: NDArray | EdgeImage,
                         edge_points: NDArray[np.float64] | None
                         ) -> tuple[tuple[OcclusionEvidence, ...], NDArray[np.float64]]:
    """:func:`evidence_all` of ``ellipses`` over ``edges`` (an edge map, or an EdgeImage:
    support from the edge contrast), and the edge map's pixels (M, 2) (u, v) in
    ``np.nonzero`` order (``edge_points`` when given)."""
    gradients = edges if isinstance(edges, EdgeImage) else None
    support = None
    if gradients is None or edge_points is None:
        binary = (np.asarray(edges.edges if isinstance(edges, EdgeImage) else edges) > 0
                  ).astype(np.uint8)
        support = None if gradients is not None else support_map(binary)
        if edge_points is None:
            vv, uu = np.nonzero(binary)
            edge_points = np.stack([uu, vv], axis=1).astype(np.float64)
    return evidence_all(ellipses, edge_points, support, gradients), edge_points


def _without_under(pool: list[int], candidates: list[int], under: list[bool],
                   free_as_candidates: bool) -> tuple[list[int], list[int]]:
    """The ``pool`` and ``candidates`` (indices) without those of the pool a test found
    ``under`` another (parallel to ``pool``), each unchanged when that leaves it empty. With
    ``free_as_candidates``, candidates all found under another give way to the pool's faces
    left (the rest test: when every passing face has an object resting on it, the faces that
    failed on support alone are above them, e.g. a top face whose arc over a lower face of its
    own colour does not show)."""
    free = [i for i, u in zip(pool, under, strict=True) if not u]
    kept = [i for i in candidates if i in free]
    if not kept and free_as_candidates:
        kept = free
    return free or pool, kept or candidates


@dataclass(frozen=True, kw_only=True)
class _Cues:
    """What :func:`select_top` reads besides the ellipses and edges (see its docstring)."""

    intrinsics: CameraIntrinsics | None
    radius_of: Callable[[Ellipse], float | None] | None
    height_of: Callable[[float], float | None] | None
    image: NDArray[np.uint8] | None
    colour_of: Callable[[Ellipse], NDArray[np.float64]] | None
    belt: NDArray[np.float64] | None


def _cover_test(ellipses: Sequence[Ellipse], pool: list[int], candidates: list[int],
                cues: _Cues, bands: BandCache) -> tuple[list[int], list[int]]:
    """``pool`` and ``candidates`` without the faces whose side wall runs under another
    pool face's (:func:`~stackpick_sim.vision.wall_cover.under_another`, its wall bands kept
    in ``bands``); unchanged without intrinsics or rivals."""
    if cues.intrinsics is None or len(pool) < 2:
        return pool, candidates
    under = under_another([ellipses[i] for i in pool], cues.intrinsics, cues.radius_of,
                          cache=bands)
    return _without_under(pool, candidates, under, False)


def _rest_test(ellipses: Sequence[Ellipse], pool: list[int], candidates: list[int],
               cues: _Cues, bands: BandCache) -> tuple[list[int], list[int]]:
    """``pool`` and ``candidates`` without the faces another pool face's cylinder rests on
    (:func:`~stackpick_sim.vision.resting.rests_on`: a leaning object shows no T-junction on
    the face it leans on; the cover test's wall ``bands`` reused); unchanged without the
    intrinsics, radii, heights and an RGB image, or without rivals."""
    if (cues.intrinsics is None or cues.radius_of is None or cues.height_of is None
            or cues.image is None or cues.image.ndim != 3 or len(pool) < 2):
        return pool, candidates
    faces = [ellipses[i] for i in pool]
    under = rests_on(faces, cues.intrinsics, cues.radius_of, cues.height_of, cues.image,
                     colour_of=cues.colour_of, cache=bands, belt=cues.belt)
    return _without_under(pool, candidates, _shared_by_refits(faces, under), True)


def _shared_by_refits(faces: Sequence[Ellipse], under: list[bool]) -> list[bool]:
    """``under`` (per face) shared by every fit of one face: the failure class *rest verdict
    on one of two fits*. The top rule's pool can hold one face fitted twice (two arcs the
    merge kept apart, refined to outlines a fraction of a pixel apart); where a leaning
    cylinder's wall meets the face's rim edge to edge, the contact normal turns fast with the
    fit (measured on rendered paper-scene frames: 0.8 up for one fit, 0.2 for the other), so
    the rest test can find the lean on one fit only. Whole faces of two objects do not
    overlap, so two pool faces one of which holds the other's centre are one face
    (:func:`clearly_nearest` treats them alike): when an object rests on either fit, it
    rests on the face."""
    out = list(under)
    for i, face in enumerate(faces):
        if under[i]:
            for j, other in enumerate(faces):
                if not out[j] and (holds_centre(face, other) or holds_centre(other, face)):
                    out[j] = True
    return out


def _clearly_nearest_of(ellipses: Sequence[Ellipse], pool: list[int],
                        intrinsics: CameraIntrinsics | None,
                        radius_of: Callable[[Ellipse], float | None] | None) -> int | None:
    """The index (of ``pool``'s) of the face clearly nearest the camera
    (:func:`clearly_nearest`), or None: without intrinsics or radii, or with one face."""
    if intrinsics is None or radius_of is None or len(pool) < 2:
        return None
    nearest = clearly_nearest([ellipses[i] for i in pool], intrinsics, radius_of)
    return None if nearest is None else pool[nearest]

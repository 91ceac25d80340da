"""Stage 5: which ellipse is the top object's face (paper section 2.3, Fig. 8).

The paper's rule: where two outlines meet in a T, the contour running through the T is the
occluding one and the edge that ends at it is occluded; an ellipse with an occluded edge lies
under something. Canny often leaves a pixel or two of gap at a T instead of a junction pixel,
so the T is read off the ellipse itself: walk its circumference, find the runs without edge
support (gaps), and call a gap end *occluded* when another contour (edge pixels off this
ellipse) passes within ``junction_radius_px`` of where this ellipse's edge stops.

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
than every other by ``depth_tie_m`` wins (a second fit of the same face is no rival); faces that
failed on support alone with nothing crossing them take part in this test too. Otherwise the
best-supported candidate wins (ties within ``support_tie`` go to the longer semi-major axis,
nearer the camera for equal radii whatever the tilt). When no ellipse passes,
:func:`select_unobstructed` is the last resort: a face with no T-junction and no edge inside
it, most of whose outline shows (``unobstructed_min_support``), lies under nothing visible;
its gaps are boundaries too faint to see.
After the detector's contrast refit, :func:`select_rimmed` is the next: a whole face whose
only interior edges lie within ``rim_band_px`` of its outline (its own faint rim, fitted on a
same-colour lower face's sliver beyond it). Such a face can also lie on the face the rule
chose: :func:`select_resting_rimmed` (called by the detector on a choice) takes it when its
cylinder, refitted on its innermost edge, rests on the chosen one's.
Given the object kinds' radii (the detector's ``markings`` settings), an ellipse that is a
marking or relief inside a larger face's outline (printed artwork, a can end's groove) is no
candidate, and a face whose outline shows whole and whose interior edges are only its own
markings is one (:mod:`~stackpick_sim.vision.markings`).
The rule needs only a list of ellipses and an edge map, so it applies to any detector's
ellipses. Its settings (the names above) are the fields of
:class:`~stackpick_sim.config.vision_params.TopParams`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.contrast import outline_rows, refit_on_contrast, supported_samples
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.kind_size import depth_radius
from stackpick_sim.vision.markings import (
    MarkingTest,
    find_markings,
    holds_centre,
    whole_with_edges_inside,
)
from stackpick_sim.vision.merging import support_map
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.resting import cover_check, rest_test, rests_on
from stackpick_sim.vision.wall_cover import BandCache, under_another

#: The top rule's default settings (the reasons for each: TopParams).
DEFAULT_TOP = TopParams()
#: The pose's default settings (the rest test reads its wall band test).
DEFAULT_POSE = PoseParams()


@dataclass(frozen=True, kw_only=True)
class OcclusionEvidence:
    """Occlusion evidence of one ellipse against an edge map, and the settings it is judged
    by (``params``)."""

    support: float
    longest_gap_px: int
    occluded_ends: int
    interior_edge_px: int
    perimeter_px: int
    params: TopParams = field(default=DEFAULT_TOP, repr=False)

    @classmethod
    def of(cls, support: float, longest_gap_px: int, occluded_ends: int,
           interior_edge_px: int, perimeter_px: int, params: TopParams = DEFAULT_TOP
           ) -> OcclusionEvidence:
        """``OcclusionEvidence(support=support, ...)`` (an equal object) at a fraction of the
        frozen dataclass constructor's cost, as :meth:`~stackpick_sim.geometry.Ellipse.of`:
        :func:`evidence_all` builds one per ellipse."""
        ev = object.__new__(cls)
        d = ev.__dict__
        d["support"], d["longest_gap_px"], d["occluded_ends"] = (support, longest_gap_px,
                                                                 occluded_ends)
        d["interior_edge_px"], d["perimeter_px"] = interior_edge_px, perimeter_px
        d["params"] = params
        return ev

    @property
    def weakly_supported(self) -> bool:
        """Edge support along less than ``params.min_support`` of the circumference."""
        return self.support < self.params.min_support

    @property
    def edges_inside(self) -> bool:
        """More interior edge pixels than ``params.max_interior_share`` of the perimeter."""
        return self.interior_edge_px > self.params.max_interior_share * self.perimeter_px

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
            return f"support {self.support:.2f} < {self.params.min_support}"
        if self.edges_inside:
            return f"{self.interior_edge_px} edge px inside the face"
        return ""


@dataclass(frozen=True, kw_only=True)
class TopChoice:
    """Outcome of the top-object rule: ``index`` into the ellipses, or None with a reason.
    ``inner``: the chosen ellipse is the top stage's inner refit of a fit that took in slivers
    of lower faces (the pose's final fit then keeps off the edge pixels beyond it)."""

    index: int | None
    evidence: tuple[OcclusionEvidence, ...]
    reason: str = ""
    inner: bool = False

    def __bool__(self) -> bool:
        return self.index is not None


def evidence_for(ellipse: Ellipse, edge_points: NDArray[np.float64],
                 support: NDArray[np.uint8], gradients: EdgeImage | None = None,
                 params: TopParams = DEFAULT_TOP) -> OcclusionEvidence:
    """Occlusion evidence of ``ellipse`` given the edge pixels (M, 2) (u, v) and the
    (H, W) 0/1 support map (edges dilated by SUPPORT_RADIUS_PX); see :func:`evidence_all`."""
    return evidence_all([ellipse], edge_points, support, gradients, params)[0]


def evidence_all(ellipses: Sequence[Ellipse], edge_points: NDArray[np.float64],
                 support: NDArray[np.uint8] | None, gradients: EdgeImage | None = None,
                 params: TopParams = DEFAULT_TOP) -> tuple[OcclusionEvidence, ...]:
    """Occlusion evidence of each ellipse given the edge pixels (M, 2) (u, v) (integer
    pixel coordinates, any order; row-major order, np.nonzero's, spares a sort) and the
    (H, W) 0/1 support map (edges dilated by SUPPORT_RADIUS_PX; unused with ``gradients``).

    With ``gradients`` the circumference's support is read from the consistent edge contrast
    (:mod:`stackpick_sim.vision.contrast`), which also sees edges too faint for the edge map.
    All ellipses are handled together: their outlines are one array, the interior edges are
    counted row by row (:func:`_interior_counts`), and the pixels near the gap ends are
    (end, pixel) pairs of one array. ``params``: the rule's settings (the gaps, T-junctions
    and interior edges measured, and the evidence's judgement).
    """
    if not ellipses:
        return ()
    rows = outline_rows(ellipses)
    table, sizes = rows[0], rows[1]
    pts, ok = _support_along(rows, support, gradients)
    # Any order of the pixels gives the same evidence: row-major, as the counts need. The
    # interior edge pixels, and the gaps (cyclic runs of unsupported samples), the longest
    # of each outline, and the T-junctions at the ends of those of at least min_gap_px (an
    # edge pixel off the ellipse, Sampson distance above off_outline_px, within
    # junction_radius_px of the end, and one inside the outline by more than off_outline_px
    # within crossing_reach_px of it; only the pixels of the rows within reach of an end are
    # tested), in one compiled pass (kernels_pose.occlusion_counts).
    radius, crossing = params.junction_radius_px, params.crossing_reach_px
    supported, longest, occluded_ends, interior = kernels_pose.occlusion_counts(
        ok, sizes, pts, table, np.ascontiguousarray(edge_points[:, 0], np.float64),
        np.ascontiguousarray(edge_points[:, 1], np.float64), float(params.interior_margin_px),
        params.min_gap_px, float(max(radius, crossing)), float(radius ** 2),
        float(crossing ** 2), params.off_outline_px)
    n_e = len(ellipses)
    return tuple(map(OcclusionEvidence.of, (supported / sizes).tolist(), longest.tolist(),
                     occluded_ends.tolist(), interior.tolist(), sizes.tolist(),
                     [params] * n_e))


def _support_along(rows: tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64],
                               NDArray[np.float64]],
                   support: NDArray[np.uint8] | None, gradients: EdgeImage | None
                   ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The (2, N) outline samples of the ellipses of ``rows`` (:func:`~stackpick_sim.vision.
    contrast.outline_rows`) and which of them show an edge: with ``gradients``, a consistent
    contrast (:func:`~stackpick_sim.vision.contrast.supported_samples`), else the (H, W)
    0/1 ``support`` map at the nearest pixel (none off the map)."""
    if gradients is not None:
        return supported_samples(rows, gradients)
    assert support is not None
    pts, _ = kernels.outline_samples(*rows)
    pix = np.rint(pts.T).astype(np.int64)
    h, w = support.shape
    inside = (pix[:, 0] >= 0) & (pix[:, 0] < w) & (pix[:, 1] >= 0) & (pix[:, 1] < h)
    ok = np.zeros(pix.shape[0], bool)
    ok[inside] = support[pix[inside, 1], pix[inside, 0]] > 0
    return pts, ok


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
    # The shrunk forms, their rows' open intervals of u (clipped to the keys' columns, empty
    # where the roots are not real) and the keys in each: one compiled pass
    # (kernels_pose.interior_counts_of: the same arithmetic as the loop on floats).
    table = np.array([(e.cx, e.cy, e.a, e.b, math.cos(t), math.sin(t))
                      for e in ellipses for t in (math.radians(e.angle_deg),)],
                     np.float64).reshape(-1, 6)
    counts = kernels_pose.interior_counts_of(table, margin_px,
                                             np.ascontiguousarray(keys, np.float64), width)
    return cast("list[int]", counts.tolist())


def clearly_nearest(faces: list[Ellipse], intrinsics: CameraIntrinsics,
                     radius_of: Callable[[Ellipse], float | None],
                     params: TopParams = DEFAULT_TOP) -> int | None:
    """Index of the face nearer the camera than every other by ``params.depth_tie_m``
    (face-centre depth from its radius), or None when a radius is unknown or no face is
    clearly nearest.

    Faces of two objects that both show whole do not overlap, so a candidate holding the
    nearest one's centre, or whose centre it holds, is that face fitted twice: it is no rival.
    """
    depths = []
    for face in faces:
        radius = radius_of(face)
        if radius is None:
            return None
        # The unit-radius solutions' depths scaled on floats (the same values as
        # circle_poses' scaled centres, without their arrays). A steeply tilted face near
        # the image border can have a solution whose centre lies behind the camera (its
        # plane seen nearly edge on): the mirror image of that circle through the camera
        # images to the same ellipse, so its depth is the centre's distance either way.
        unit = unit_circle_poses(face, intrinsics)
        depths.append(0.5 * (abs(float(unit[0].centre_cam[2])) * radius
                             + abs(float(unit[1].centre_cam[2])) * radius))
    nearest = int(np.argmin(depths))
    rivals = [d for face, d in zip(faces, depths, strict=True)
              if not (holds_centre(face, faces[nearest])
                      or holds_centre(faces[nearest], face))]
    if rivals and min(rivals) - depths[nearest] < params.depth_tie_m:
        return None
    return nearest


def select_unobstructed(evidence: Sequence[OcclusionEvidence]) -> int | None:
    """Index of the best-supported ellipse with no T-junction end, no interior edge pixel and
    support >= ``unobstructed_min_support``, or None: the top rule's last resort when no
    ellipse passes it (see TopParams.unobstructed_min_support)."""
    ok = [i for i, ev in enumerate(evidence) if unobstructed(ev)]
    return max(ok, key=lambda i: evidence[i].support, default=None)


def hidden_by_no_outline(choice: TopChoice,
                         min_support: float = DEFAULT_TOP.hidden_min_support) -> bool:
    """Whether an ellipse besides the chosen one failed the rule on support alone (at least
    ``min_support``, below the rule's ``min_support``) with no T-junction end and no edge pixel
    inside: the failure class *top face hidden by same-colour neighbours*. An occluder whose
    outline shows runs into the face it covers (interior edges, T-ends); a face cut short with
    nothing crossing it lies under a face whose boundary with it shows no contrast, a face of
    its colour and shade that the merge may never have fitted, which can be the top."""
    return any(i != choice.index and not ev.occluded_ends and not ev.interior_edge_px
               and min_support <= ev.support and ev.weakly_supported
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
    T-junction end, support >= ``min_support``) and whose interior edge pixels all but
    ``max_interior_share`` of the perimeter lie within ``rim_band_px`` of the outline (the
    settings the evidence is judged by; see TopParams.rim_band_px): a whole face with its own
    rim inside its fit."""
    failed = _inside_only(evidence)
    if not failed:
        return []
    return [failed[k] for k in _rim_kept(ellipses, evidence, failed, edge_points,
                                         evidence[failed[0]].params)]


def _inside_only(evidence: Sequence[OcclusionEvidence]) -> list[int]:
    """Indices of the ellipses that failed the top rule on interior edges alone (no
    T-junction end, support >= ``min_support``)."""
    return [i for i, ev in enumerate(evidence) if whole_with_edges_inside(ev)]


def _rim_kept(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
              failed: list[int], edge_points: NDArray[np.float64], params: TopParams
              ) -> list[int]:
    """Positions in ``failed`` (indices of :func:`_inside_only` ellipses) of those whose
    interior edge pixels all but ``max_interior_share`` of the perimeter lie within
    ``rim_band_px`` of the outline (``params``; see :func:`rim_only`); each ellipse's verdict
    its own."""
    deep = deep_edge_counts([ellipses[i] for i in failed], edge_points, params.rim_band_px)
    return [k for k, (i, d) in enumerate(zip(failed, deep, strict=True))
            if d <= params.max_interior_share * evidence[i].perimeter_px]


def select_rimmed(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                  edge_points: NDArray[np.float64]) -> int | None:
    """Index of the best-supported of the :func:`rim_only` ellipses (ties within
    ``support_tie`` to the longer semi-major axis), or None: a last resort when no ellipse
    passes the rule, nor after the contrast refit (see TopParams.rim_band_px)."""
    ok = rim_only(ellipses, evidence, edge_points)
    return _best_supported(ok, ellipses, evidence) if ok else None


def select_resting_rimmed(ellipses: Sequence[Ellipse], choice: TopChoice, edges: EdgeImage,
                          edge_points: NDArray[np.float64], intrinsics: CameraIntrinsics,
                          radius_of: Callable[[Ellipse], float | None],
                          height_of: Callable[[float], float | None], image: NDArray[np.uint8],
                          belt: NDArray[np.float64] | None = None,
                          params: TopParams = DEFAULT_TOP,
                          pose_params: PoseParams = DEFAULT_POSE) -> int | None:
    """Index of a :func:`rim_only` ellipse whose object rests on the chosen face's, or None.

    The top rule's choice can be a whole lower face with a top face resting on it whose fit
    took in a same-colour lower face's sliver (see TopParams.rim_band_px): that fit fails on its own
    rim inside it, and the lower face wins. The rest test (:mod:`~stackpick_sim.vision.
    resting`) tells them apart once the rimmed face is refitted on its innermost consistent
    edge (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`; the fit itself is too
    large, its depth too near): a rimmed face whose cylinder rests on the chosen one is above
    it, and the chosen face is not top (nothing may rest on a top object). Of several, the
    best-supported (:func:`select_rimmed`'s order).

    The refit and the rest test (~1 ms) run only for a rimmed face whose fit reads nearer
    the camera than the chosen face, up to ``params.perspective_enlargement`` (a cost gate,
    on about one frame in fifty of the paper scene's; one in nine has a rimmed face): the fit
    is too large, so it reads nearer than its face is, and a face reading farther lies below
    the chosen one; such a lower face resting on it (a lean on its wall, below its face) is
    left to the top rule. ``belt``: the bare belt's colour in ``image``, for the rest test's
    wall bands; ``params``: the contrast refit's and the rest test's settings;
    ``pose_params``: the wall band test's."""
    if choice.index is None or image.ndim != 3:
        return None
    evidence = choice.evidence
    # rim_only's failures on interior edges alone first; its count of the edge pixels deep
    # inside each (the cost) only for those that read nearer (per ellipse: the same set).
    failed = _inside_only(evidence)
    if not failed:
        return None
    chosen = ellipses[choice.index]
    radius = radius_of(chosen)
    if radius is None:
        return None
    # Depth ~ radius / semi-major axis (f r / a; perspective enlarges a by up to
    # params.perspective_enlargement, either face): a gate, not a measurement.
    depth = radius / chosen.a * params.perspective_enlargement
    nearer = [i for i in failed if (own := radius_of(ellipses[i])) is not None
              and own / ellipses[i].a < depth]
    if not nearer:
        return None
    nearer = [nearer[k] for k in _rim_kept(ellipses, evidence, nearer, edge_points,
                                           evidence[failed[0]].params)]
    above = []
    for i in nearer:
        face = refit_on_contrast(ellipses[i], edges, True, params) or ellipses[i]
        if rests_on([chosen, face], intrinsics, radius_of, height_of, image, belt=belt,
                    params=params, pose_params=pose_params)[0]:
            above.append(i)
    return _best_supported(above, ellipses, evidence) if above else None


def _best_supported(indices: Sequence[int], ellipses: Sequence[Ellipse],
                    evidence: Sequence[OcclusionEvidence]) -> int:
    """The best-supported of ``indices`` (non-empty); ties within the evidence's
    ``support_tie`` go to the ellipse of the longer semi-major axis, which is nearer the
    camera for equal radii whatever the faces' tilts (about f r / z; the area shrinks with
    the tilt's cosine, so a tilted face resting on a flatter one of its size reads smaller
    by area)."""
    best = max(evidence[i].support for i in indices)
    tie = evidence[indices[0]].params.support_tie
    return max((i for i in indices if evidence[i].support >= best - tie),
               key=lambda i: ellipses[i].a)


def unobstructed(ev: OcclusionEvidence) -> bool:
    """No T-junction end, no interior edge pixel, support >= the evidence's
    ``unobstructed_min_support``."""
    return (not ev.occluded_ends and not ev.interior_edge_px
            and ev.support >= ev.params.unobstructed_min_support)


def _markings(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
              edge_points: NDArray[np.float64], test: MarkingTest | None,
              radius_of: Callable[[Ellipse], float | None] | None
              ) -> tuple[frozenset[int], frozenset[int]]:
    """(markings, marked faces) of :func:`~stackpick_sim.vision.markings.find_markings`
    (both empty without a ``test``), less the marked faces whose interior edges all lie in
    their rim band: a fit too large for its face (see :func:`rim_only`), not a face with markings
    across it."""
    if test is None:
        return frozenset(), frozenset()
    found = find_markings(ellipses, evidence, test, radius_of, edge_points)
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
               markings: MarkingTest | None = None,
               params: TopParams = DEFAULT_TOP,
               pose_params: PoseParams = DEFAULT_POSE,
               kind_radii: Sequence[float] = (),
               kinds_of: Callable[[Ellipse], tuple[float, ...]] | None = None
               ) -> TopChoice:
    """Apply the top-object rule to any ellipses over a one-pixel-wide (H, W) edge map.

    ``edges`` is nonzero on edge pixels (e.g. :func:`stackpick_sim.vision.edges.detect_edges`)
    or, better, the whole :class:`~stackpick_sim.vision.edges.EdgeImage` (then faint but
    consistent edges count as support too). With ``intrinsics`` (K in the edge map's pixel
    frame), a candidate whose side wall runs under another candidate's face loses to it
    (:mod:`stackpick_sim.vision.wall_cover`; with ``radius_of``, only where that face lies in
    front of the wall). With ``intrinsics`` and ``radius_of`` (an
    ellipse's face radius, m, or None if unknown) the nearest remaining candidate wins when
    it is nearer than the others (other than fits of the same face) by ``depth_tie_m``; faces
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
    (:mod:`~stackpick_sim.vision.markings`). ``params``: the rule's settings;
    ``pose_params``: the rest test's wall band test's (the pose's). Without ``radius_of``
    (kinds that colour cannot tell apart), ``kind_radii`` (the kinds' radii, m) with
    ``height_of`` and the image let the rest test try every kind for each face
    (:func:`~stackpick_sim.vision.resting.rests_on_any_kind`); with ``kinds_of`` (the radii
    of the kinds a face's size admits, :mod:`~stackpick_sim.vision.kind_size`), only those,
    and the depth test runs on faces whose size admits one kind.
    """
    if not ellipses:
        return TopChoice(index=None, evidence=(), reason="no ellipses")
    evidence, edge_points = _evidence_and_pixels(ellipses, edges, edge_points, params)
    inner, marked = _markings(ellipses, evidence, edge_points, markings, radius_of)
    candidates = [i for i, ev in enumerate(evidence)
                  if (not ev.occluded or i in marked) and i not in inner]
    if not candidates:
        return TopChoice(index=None, evidence=evidence,
                         reason=f"all {len(ellipses)} ellipses occluded")
    # The depth test also hears faces that failed on support alone with nothing crossing
    # them (see TopParams.unobstructed_min_support): one clearly nearer than every whole face
    # is above them.
    pool = candidates + [i for i, ev in enumerate(evidence)
                         if ev.occluded and unobstructed(ev) and i not in marked | inner]
    cues = _Cues(intrinsics=intrinsics, radius_of=radius_of, height_of=height_of, image=image,
                 colour_of=colour_of, belt=belt, params=params, pose_params=pose_params,
                 kind_radii=tuple(kind_radii), kinds_of=kinds_of)
    # The candidates' wall bands, computed once for the cover and the rest tests.
    bands: BandCache = {}
    pool, candidates = _cover_test(ellipses, pool, candidates, cues, bands)
    pool, candidates = _rest_test(ellipses, pool, candidates, cues, bands)
    nearest = _depth_test(ellipses, pool, candidates, cues)
    if nearest is not None:
        return TopChoice(index=nearest, evidence=evidence)
    return TopChoice(index=_best_supported(candidates, ellipses, evidence), evidence=evidence)


def _evidence_and_pixels(ellipses: Sequence[Ellipse], edges: NDArray | EdgeImage,
                         edge_points: NDArray[np.float64] | None, params: TopParams
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
    return evidence_all(ellipses, edge_points, support, gradients, params), edge_points


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
    params: TopParams
    pose_params: PoseParams
    kind_radii: tuple[float, ...]
    kinds_of: Callable[[Ellipse], tuple[float, ...]] | None


def _cover_test(ellipses: Sequence[Ellipse], pool: list[int], candidates: list[int],
                cues: _Cues, bands: BandCache) -> tuple[list[int], list[int]]:
    """``pool`` and ``candidates`` without the faces whose side wall runs under another
    pool face's (:func:`~stackpick_sim.vision.wall_cover.under_another`, its wall bands kept
    in ``bands``); unchanged without intrinsics or rivals."""
    if cues.intrinsics is None or len(pool) < 2:
        return pool, candidates
    faces = [ellipses[i] for i in pool]
    possible = (None if cues.radius_of is None or cues.height_of is None
                else cover_check(faces, cues.intrinsics, cues.radius_of, cues.height_of,
                                 cues.params))
    under = under_another(faces, cues.intrinsics, cues.radius_of, cache=bands,
                          params=cues.params, pose=cues.pose_params, possible=possible)
    return _without_under(pool, candidates, under, False)


def _rest_test(ellipses: Sequence[Ellipse], pool: list[int], candidates: list[int],
               cues: _Cues, bands: BandCache) -> tuple[list[int], list[int]]:
    """``pool`` and ``candidates`` without the faces another pool face's cylinder rests on
    (:func:`~stackpick_sim.vision.resting.rests_on`: a leaning object shows no T-junction on
    the face it leans on; the cover test's wall ``bands`` reused; without radii from colour,
    :func:`~stackpick_sim.vision.resting.rests_on_any_kind` over the kinds' radii);
    unchanged without the intrinsics, radii, heights and an RGB image, or without rivals."""
    if (cues.intrinsics is None or cues.height_of is None or cues.image is None
            or cues.image.ndim != 3 or len(pool) < 2):
        return pool, candidates
    test = rest_test(cues.intrinsics, cues.radius_of, cues.kind_radii, cues.height_of,
                     cues.image, colour_of=cues.colour_of, cache=bands, belt=cues.belt,
                     params=cues.params, pose_params=cues.pose_params, kinds_of=cues.kinds_of)
    if test is None:
        return pool, candidates
    faces = [ellipses[i] for i in pool]
    return _without_under(pool, candidates, _shared_by_refits(faces, test(faces)), True)


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


def _depth_test(ellipses: Sequence[Ellipse], pool: list[int], candidates: list[int],
                cues: _Cues) -> int | None:
    """The index of the ``pool`` face clearly nearest the camera (:func:`_clearly_nearest_of`;
    radii from colour, else of faces whose size admits one kind), else, with
    ``depth_among_passing``, of the ``candidates`` (the passing faces), or None."""
    radius_of = depth_radius(cues.radius_of, cues.kinds_of)
    params = cues.params
    nearest = _clearly_nearest_of(ellipses, pool, cues.intrinsics, radius_of, params)
    if nearest is None and params.depth_among_passing and len(candidates) < len(pool):
        # A face that failed on support alone ties with a passing one: of the passing
        # faces, one clearly nearer than the others is above them.
        nearest = _clearly_nearest_of(ellipses, candidates, cues.intrinsics, radius_of,
                                      params)
    return nearest


def _clearly_nearest_of(ellipses: Sequence[Ellipse], pool: list[int],
                        intrinsics: CameraIntrinsics | None,
                        radius_of: Callable[[Ellipse], float | None] | None,
                        params: TopParams) -> int | None:
    """The index (of ``pool``'s) of the face clearly nearest the camera
    (:func:`clearly_nearest`), or None: without intrinsics or radii, or with one face."""
    if intrinsics is None or radius_of is None or len(pool) < 2:
        return None
    nearest = clearly_nearest([ellipses[i] for i in pool], intrinsics, radius_of, params)
    return None if nearest is None else pool[nearest]

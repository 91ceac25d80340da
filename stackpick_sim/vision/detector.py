"""The top-object detector: edges -> segments -> fits -> merging -> top rule -> pose.

Given a depth range, refined ellipses too small or too large for any face radius in it are
dropped (SIZE_GATE_SLACK). When no ellipse passes the top rule, the best-supported face with
no T-junction and no edge inside is taken (:func:`~stackpick_sim.vision.occlusion.
select_unobstructed`); failing that, those that failed on support or interior edges alone are
refitted on the edge contrast (faint same-colour boundaries) and the rule is re-run (a face
from the last stage's arc pairs, below, that passes the rule and lies clearly nearer than the
refit it chose takes the choice: :func:`_nearer_arc_face`); failing that, a whole face whose
interior edges all lie in a band along its outline is taken (its own faint rim inside a
same-colour lower face's sliver, :func:`~stackpick_sim.vision.occlusion.select_rimmed`);
failing that, ellipses fitted to pairs of arcs the merge never joined
(:mod:`~stackpick_sim.vision.regroup`) go through the rule; then a contrast refit with no
T-junction and no edge inside, most of its outline showing; the very last are the pairs that
also take in the edge chains no fit was kept for and the parts of the chains cut at their
junctions (:func:`last_resort_arcs`), through the rule and else its own last resorts
(select_unobstructed, then select_rimmed). One face fitted twice is reported once
(DUPLICATE_SHARE), nor are the top face's refits on other outlines too (MISFIT_SHARE), and a
cylinder's far rim is not reported as a face (RIM_OFFSET_RANGE).

When no ellipse passes the rule outright (none does, or a face with markings is chosen,
:mod:`~stackpick_sim.vision.markings`) and some face holds markings across it, the faces with
markings fitted on pairs of arcs join the rule first (:meth:`TopObjectDetector.
_marked_arc_faces`): the merge joins no arcs across a printed face's artwork or a can end's
rings.

When an ellipse does pass the rule, a whole face that failed on its own rim inside its fit
(:func:`~stackpick_sim.vision.occlusion.rim_only`) and whose reconstructed cylinder rests on
the chosen face's takes the choice instead (:func:`~stackpick_sim.vision.occlusion.
select_resting_rimmed`): nothing may rest on a top object.

Entry point :func:`detect` (or a reusable :class:`TopObjectDetector`). Any image gives a
:class:`~stackpick_sim.vision.detection.Detection` (falsy with a reason on a miss) or, for
input that is not an image at all (wrong dtype, shape, NaN), one
:class:`~stackpick_sim.exceptions.ImageError`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.contrast import refit_on_contrast
from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.edges import (
    MIN_SIDE_PX,
    EdgeImage,
    as_rgb_or_gray,
    edge_image,
    unblurred_gradients,
)
from stackpick_sim.vision.fitting import (
    MIN_FIT_PX,
    fit_all,
    plausible,
    rms_residual,
)
from stackpick_sim.vision.limits import (
    Deadline,
    WorkLimits,
    downscale_factor,
    downscaled,
    longest,
    scaled_intrinsics,
    upscaled,
)
from stackpick_sim.vision.markings import (
    RIM_SAMPLE_SCALE,
    MarkingTest,
    inside_rim_band,
    whole_with_edges_inside,
)
from stackpick_sim.vision.merging import (
    MergedEllipse,
    boundary_shares,
    merge_segments,
    support_map,
    support_shares,
)
from stackpick_sim.vision.occlusion import (
    INTERIOR_MARGIN_PX,
    OcclusionEvidence,
    TopChoice,
    clearly_nearest,
    holds_centre,
    select_resting_rimmed,
    select_rimmed,
    select_top,
    select_unobstructed,
    unobstructed,
)
from stackpick_sim.vision.pose import estimate_pose
from stackpick_sim.vision.refine import (
    PROFILE_REACH_PX,
    edge_points,
    refine_all,
    refine_on_profile,
    refine_subpixel,
)
from stackpick_sim.vision.regroup import (
    arc_pair_ellipses,
    chain_table,
    chains_on,
    split_at_junctions,
)
from stackpick_sim.vision.roi import Roi, find_roi
from stackpick_sim.vision.segments import link_segments
from stackpick_sim.vision.undistort import undistort
from stackpick_sim.vision.wall import FACE_SAMPLE_SCALE, face_colour

#: Vertical field of view (deg) assumed when no intrinsics are given: the wrist camera's.
DEFAULT_FOVY_DEG = 45.0
#: Ellipses whose outline shows consistent edge contrast along less than this share are not
#: reported (they are arcs of two outlines fitted together, or far rims): a real face at
#: least half visible keeps about its visible share, and the scoring counts faces >= 50%
#: visible. Placeholder chosen on rendered paper-scene frames, not tuned further.
MIN_REPORTED_SUPPORT = 0.6
#: Size gate (with a depth range): a face of radius r at depth z images with a semi-major
#: axis of at least f r / z px (perspective only enlarges it: up to 4% on the paper scene's
#: frames). Ellipses smaller than this share of the smallest such axis for the farthest depth,
#: or larger than this multiple of the largest for the nearest, are not faces of the pile
#: (arcs of rims, walls and shading fitted together). The slack covers fits on partial arcs.
SIZE_GATE_SLACK = (0.9, 1.25)
#: Two reported ellipses are one face fitted twice when each outline lies within this
#: distance (px) of the other along DUPLICATE_SHARE of it: the edge refit's first collection
#: tolerance (refine.TOLERANCES_PX), within which it pulls a fit onto the face's edge.
DUPLICATE_TOLERANCE_PX = 2.5
DUPLICATE_SHARE = 0.9
#: Only ellipses whose centres and semi-axes each differ by at most this (px) are compared
#: outline to outline (the cost of the comparison is in its array passes): two outlines
#: within DUPLICATE_TOLERANCE_PX of each other along nearly all their length differ by about
#: that much, twice it at most (measured on 400 rendered paper-scene frames: the duplicates
#: found differ by <= 1.3 px, and 89% of the compared pairs by more than this).
DUPLICATE_NEAR_PX = 2.0 * DUPLICATE_TOLERANCE_PX
#: A reported ellipse whose outline lies within DUPLICATE_TOLERANCE_PX of the top face's along
#: at least this share of its own is the top face fitted again on arcs of its outline and of
#: another (a lower face's silhouette beyond it), not a face of its own: where a face shows,
#: its outline lies outside the whole top face, and two faces' outlines cross at points; they
#: run together along an arc only where a face of the top's size lies nearly in line under it,
#: hidden. On 4000 rendered paper-scene frames and 200 cluttered-scene frames, 350 ellipses
#: besides the top reach this share, 4 of which match a true face (two equal faces stacked
#: in line).
MISFIT_SHARE = 0.5
#: A reported ellipse is a cylinder's far rim (the end of its wall silhouette, half hidden
#: behind its face), not a face, when it has a better-supported face's size within this
#: share...
RIM_SIZE_TOLERANCE = 0.1
#: ...and is shifted from it along that face's minor axis (the image of the cylinder's axis,
#: within RIM_ANGLE_DEG) by this range of shares of its semi-major axis: a height h rim of a
#: face of radius r tilted by t lies (h / r) sin t semi-axes away; the paper scene's h <= r and
#: t <= 45 deg give <= 0.71, the upper end adds perspective and fit error, the lower end keeps
#: near-concentric ellipses (two faces stacked in line, square on) out of the test.
RIM_OFFSET_RANGE = (0.15, 0.9)
RIM_ANGLE_DEG = 20.0
#: Margin (px) beyond the profile search of the window whose unblurred gradients the top
#: face's final fit reads: Sobel's 3x3 footprint and the bilinear neighbour.
PROFILE_WINDOW_MARGIN_PX = 3
#: Object kinds whose colours' chromaticities (r, g, b over their sum) differ by less than
#: this (L1 distance) cannot be told apart by colour: the radius is then not read from it.
MIN_KIND_CHROMA_DISTANCE = 0.1
#: The paper scene's cylinder radii, metres (large and small kind).
DEFAULT_RADII_M: tuple[float, ...] = (0.035, 0.025)


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """Detector settings.

    ``intrinsics``: camera K (default: a centred pinhole of DEFAULT_FOVY_DEG for the image's
    size). ``radii_m``: candidate face radii. ``depth_range_m``: expected (min, max) depth of
    a top face, metres, used to choose among the radii (the caller knows the camera's height
    above the belt); None takes the first radius. ``kind_colours``: optional RGB colour
    (components 0-1) of the objects of each radius, parallel to ``radii_m``: a face's radius
    is then read from its colour (nearest chromaticity), which gives each candidate's depth
    for the top rule (the nearest wins) and the pose its radius. ``heights_m``: optional
    cylinder height (m) of the objects of each radius, parallel to ``radii_m``; with the
    colours it lets the top rule rebuild the candidates' cylinders and reject one another
    rests on (:mod:`~stackpick_sim.vision.resting`). ``limits``: caps on the work done on any
    image and an optional time budget (:class:`~stackpick_sim.vision.limits.WorkLimits`).
    ``marking_depth_ratio``, ``marking_min_edge_share``: the top rule's test for a marking or
    relief inside a face (ratios; the scene's ``vision`` keys of those names, see
    :mod:`~stackpick_sim.vision.markings`).
    """

    intrinsics: CameraIntrinsics | None = None
    radii_m: tuple[float, ...] = DEFAULT_RADII_M
    depth_range_m: tuple[float, float] | None = None
    kind_colours: tuple[tuple[float, float, float], ...] | None = None
    heights_m: tuple[float, ...] | None = None
    limits: WorkLimits = field(default_factory=WorkLimits)
    marking_depth_ratio: float = VisionCfg.marking_depth_ratio
    marking_min_edge_share: float = VisionCfg.marking_min_edge_share

    def __post_init__(self) -> None:
        if not self.radii_m or any(not r > 0 for r in self.radii_m):
            raise ConfigError(f"radii_m must be positive metres, got {self.radii_m}")
        if self.depth_range_m is not None:
            lo, hi = self.depth_range_m
            if not 0 < lo <= hi:
                raise ConfigError(f"depth_range_m must be 0 < min <= max, got {self.depth_range_m}")
        if self.kind_colours is not None and (
                len(self.kind_colours) != len(self.radii_m)
                or any(len(c) != 3 or not all(0.0 <= x <= 1.0 for x in c)
                       for c in self.kind_colours)):
            raise ConfigError("kind_colours must give one RGB colour (components 0-1) per "
                              f"radius in radii_m, got {self.kind_colours}")
        if not 0.5 <= self.marking_depth_ratio <= 2.0:
            raise ConfigError("marking_depth_ratio must lie in 0.5 to 2, got "
                              f"{self.marking_depth_ratio}")
        if not 0.0 <= self.marking_min_edge_share <= 10.0:
            raise ConfigError("marking_min_edge_share must lie in 0 to 10, got "
                              f"{self.marking_min_edge_share}")
        if self.heights_m is not None and (len(self.heights_m) != len(self.radii_m)
                                           or any(not h > 0 for h in self.heights_m)):
            raise ConfigError("heights_m must give one positive height (m) per radius in "
                              f"radii_m, got {self.heights_m}")

    def height_of(self) -> Callable[[float], float | None] | None:
        """Radius (m) -> cylinder height (m) of its kind (None for another radius), or None
        without ``heights_m``."""
        if self.heights_m is None:
            return None
        return dict(zip(self.radii_m, self.heights_m, strict=True)).get


class _Clock:
    """Stage times (ms, into ``timings``) and the time budget's checks."""

    def __init__(self, t0: float, deadline: Deadline, timings: dict[str, float]) -> None:
        self.t, self.deadline, self.timings = t0, deadline, timings

    def lap(self, name: str) -> None:
        """Record stage ``name`` as ending now; raise _OutOfTime past the deadline."""
        now = time.perf_counter()
        self.timings[name] = (now - self.t) * 1e3
        self.t = now
        self.check(name)

    def check(self, name: str) -> None:
        """Raise _OutOfTime (within stage ``name``) past the deadline."""
        if self.deadline.expired():
            raise _OutOfTime(name)


@dataclass(frozen=True, kw_only=True)
class _Found:
    """The ellipse stages' output, in the region of interest's pixels: ``roi`` and its
    ``work`` crop of ``crop`` (H, W); edges and gradients ``grad``; the edge chains
    ``segments``; the fitted ``pieces`` (and the chain indices ``fitted`` they came from);
    ``chains``, the pieces then the segments; the refined ``merged`` ellipses within the size
    ``gate``; the edge pixels ``points`` and their unit gradients ``grads``."""

    roi: Roi
    work: NDArray[np.uint8]
    crop: tuple[int, int]
    grad: EdgeImage
    segments: tuple[NDArray[np.int32], ...]
    pieces: list[NDArray[np.int32]]
    fitted: set[int]
    chains: tuple[NDArray[np.int32], ...]
    merged: list[MergedEllipse]
    points: NDArray[np.float64]
    grads: NDArray[np.float64]
    gate: tuple[float, float] | None


@dataclass(frozen=True, kw_only=True)
class _Cues:
    """What the top rule reads besides the ellipses (see :meth:`TopObjectDetector._cues`)."""

    k_crop: CameraIntrinsics
    rgb: NDArray[np.uint8] | None
    belt: NDArray[np.float64] | None
    colour_of: Callable[[Ellipse], NDArray[np.float64]] | None
    radius_of: Callable[[Ellipse], float | None] | None
    height_of: Callable[[float], float | None] | None
    markings: MarkingTest


class TopObjectDetector:
    """Finds the top cylinder's face and pose in one image; see :func:`detect`."""

    def __init__(self, config: DetectorConfig | None = None) -> None:
        self.config = config or DetectorConfig()

    def _intrinsics(self, shape: tuple[int, int]) -> CameraIntrinsics:
        if self.config.intrinsics is not None:
            return self.config.intrinsics
        return CameraIntrinsics.from_fovy(DEFAULT_FOVY_DEG, shape[1], shape[0])

    def _axis_range(self, k: CameraIntrinsics) -> tuple[float, float] | None:
        """(min, max) semi-major axis (px) of a face given the depth range, or None without
        one (see SIZE_GATE_SLACK)."""
        if self.config.depth_range_m is None:
            return None
        near, far = self.config.depth_range_m
        radii = self.config.radii_m
        lo = SIZE_GATE_SLACK[0] * min(k.fx, k.fy) * min(radii) / far
        hi = SIZE_GATE_SLACK[1] * max(k.fx, k.fy) * max(radii) / near
        return lo, hi

    def detect(self, image: NDArray) -> Detection:
        """Detect ellipses, the top object and its pose in an (H, W[, C]) image.

        Images of more than ``limits.max_pixels`` are detected on a :func:`~stackpick_sim.
        vision.limits.downscaled` copy, and the ellipses, chains and pose's pixel centre
        mapped back to the full image."""
        t0 = time.perf_counter()
        img = undistort(as_rgb_or_gray(image), self.config.intrinsics)
        shape = (int(img.shape[0]), int(img.shape[1]))
        if min(shape) < MIN_SIDE_PX:
            return Detection(reason=f"image {shape[1]}x{shape[0]} smaller than "
                             f"{MIN_SIDE_PX} px a side")
        deadline = Deadline(t0, self.config.limits.time_budget_ms)
        factor = downscale_factor(shape, self.config.limits.max_pixels)
        if factor == 1:
            return self._detect(img, t0, deadline)
        small = downscaled(img, factor)
        if min(small.shape[:2]) < MIN_SIDE_PX:
            return Detection(reason=f"image {shape[1]}x{shape[0]} downscaled by {factor} "
                             f"is smaller than {MIN_SIDE_PX} px a side")
        config = replace(self.config, intrinsics=scaled_intrinsics(self._intrinsics(shape),
                                                                   factor))
        found = TopObjectDetector(config)._detect(small, t0, deadline)
        return _upscaled_detection(found, factor)

    def _detect(self, img: NDArray[np.uint8], t0: float, deadline: Deadline) -> Detection:
        """:meth:`detect` of a validated image within the pixel limit."""
        timings: dict[str, float] = {}
        try:
            return self._stages(img, t0, deadline, timings)
        except _OutOfTime as out:
            timings["total"] = (time.perf_counter() - t0) * 1e3
            return Detection(timings_ms=timings,
                             reason=f"time budget of {deadline.budget_ms:g} ms ran out after "
                                    f"the {out.stage} stage")

    def _stages(self, img: NDArray[np.uint8], t0: float, deadline: Deadline,
                timings: dict[str, float]) -> Detection:
        """The stages of :meth:`detect` in order (roi, edges, segments, fitting, merging,
        refine: :meth:`_ellipse_stages`; top: :meth:`_top_stage`; pose:
        :meth:`_pose_stage`), each timed into ``timings``; raises _OutOfTime after a stage
        that ends past the ``deadline``."""
        clock = _Clock(t0, deadline, timings)
        shape = (int(img.shape[0]), int(img.shape[1]))
        k = self._intrinsics(shape)
        found = self._ellipse_stages(img, self._axis_range(k), clock)
        cues = self._cues(found, k)
        merged, choice = self._top_stage(found, cues, clock)
        detection = self._pose_stage(found, merged, choice, img, k, cues, timings)
        clock.lap("pose")
        timings["total"] = (clock.t - t0) * 1e3
        return detection

    def _ellipse_stages(self, img: NDArray[np.uint8], gate: tuple[float, float] | None,
                        clock: _Clock) -> _Found:
        """roi, edges, segments, fitting, merging and refine (each within its cap of
        ``limits``; after the refit, ellipses outside the size ``gate`` are dropped)."""
        limits = self.config.limits
        roi = find_roi(img)
        work = np.ascontiguousarray(roi.crop(img))
        if min(work.shape[:2]) < MIN_SIDE_PX:
            roi, work = Roi(u0=0, v0=0, u1=int(img.shape[1]), v1=int(img.shape[0])), img
        crop = (int(work.shape[0]), int(work.shape[1]))
        clock.lap("roi")
        grad = edge_image(work)
        edges = grad.edges
        clock.lap("edges")
        segments = link_segments(edges, limits.max_chains).chains
        if len(segments) > limits.max_chains:
            segments = tuple(segments[i] for i in longest(segments, limits.max_chains))
        clock.lap("segments")
        found = fit_all(segments, crop)
        found = [found[i] for i in longest([f[1] for f in found], limits.max_fits)]
        pieces = [points for _, points, _, _ in found]
        chains = tuple(pieces) + segments
        clock.lap("fitting")
        merged = merge_segments(chains, [(i, f[2]) for i, f in enumerate(found)], edges,
                                [f[3] for f in found])
        merged = _best_supported(merged, limits.max_ellipses)
        clock.lap("merging")
        points, grads = edge_points(grad)
        refined = refine_all([m.ellipse for m in merged], points, grads, crop)
        merged = [MergedEllipse(ellipse=e, segments=m.segments, residual_px=m.residual_px,
                                support=m.support) for m, e in zip(merged, refined, strict=True)]
        # After the refit: a fit on a few short arcs can be far smaller than its face.
        merged = _within_gate(merged, gate)
        clock.lap("refine")
        return _Found(roi=roi, work=work, crop=crop, grad=grad, segments=segments,
                      pieces=pieces, fitted={c for c, _, _, _ in found}, chains=chains,
                      merged=merged, points=points, grads=grads, gate=gate)

    def _cues(self, found: _Found, k: CameraIntrinsics) -> _Cues:
        """What the top rule reads besides the ellipses: the crop's intrinsics, colours,
        the belt's colour and the radius and height of each candidate's kind."""
        du, dv = found.roi.offset
        # Built directly: dataclasses.replace costs several times the constructor.
        k_crop = CameraIntrinsics(fx=k.fx, fy=k.fy, cx=k.cx - du, cy=k.cy - dv, width=k.width,
                                  height=k.height)
        work = found.work
        rgb = work if work.ndim == 3 else None
        # Each candidate's face colour once, for its radius and the rest test's wall bands.
        colour_of = None if rgb is None else face_colours(rgb)
        colours = self.config.kind_colours
        radius_of = (None if colours is None else
                     radius_by_colour(work, self.config.radii_m, colours, colour_of))
        markings = marking_test(self.config, work, found.grad)
        return _Cues(k_crop=k_crop, rgb=rgb,
                     belt=None if found.roi.belt is None else np.array(found.roi.belt),
                     colour_of=colour_of, radius_of=radius_of,
                     height_of=self.config.height_of(), markings=markings)

    def _select(self, ellipses: list[Ellipse], found: _Found, cues: _Cues) -> TopChoice:
        """The top rule (:func:`~stackpick_sim.vision.occlusion.select_top`) with every
        cue."""
        return select_top(ellipses, found.grad, cues.k_crop, cues.radius_of,
                          edge_points=found.points, image=cues.rgb, height_of=cues.height_of,
                          colour_of=cues.colour_of, belt=cues.belt, markings=cues.markings)

    def _top_stage(self, found: _Found, cues: _Cues, clock: _Clock
                   ) -> tuple[list[MergedEllipse], TopChoice]:
        """The top rule, then, when it chose a face, the rest test's correction, and when
        it chose none, its fallbacks (:meth:`_fallbacks`)."""
        merged = found.merged
        choice = self._select([m.ellipse for m in merged], found, cues)
        if choice.index is None or choice.evidence[choice.index].occluded:
            # None passed the rule outright: faces with markings the merge never fitted.
            merged, choice = self._marked_arc_faces(found, merged, choice, cues, clock)
        if (choice.index is not None and cues.radius_of is not None
                and cues.height_of is not None and cues.rgb is not None):
            # A whole lower face that a top face rests on, that face's fit taking in a
            # same-colour sliver beyond it.
            above = select_resting_rimmed([m.ellipse for m in merged], choice, found.grad,
                                          found.points, cues.k_crop, cues.radius_of,
                                          cues.height_of, cues.rgb, cues.belt)
            if above is not None:
                choice = replace(choice, index=above)
        if choice.index is None:
            merged, choice = self._fallbacks(found, merged, choice, cues, clock)
        clock.lap("top")
        return merged, choice

    def _marked_arc_faces(self, found: _Found, merged: list[MergedEllipse], choice: TopChoice,
                          cues: _Cues, clock: _Clock) -> tuple[list[MergedEllipse], TopChoice]:
        """When no ellipse passed the top rule outright (none did, or a face with markings
        was chosen, :mod:`~stackpick_sim.vision.markings`) and some ellipse holds markings
        across it (interior edges along ``marking_min_edge_share`` of its perimeter; on plain
        faces the fallbacks decide, at no extra cost): the top rule again over the ellipses
        and those of pairs of every arc (:func:`_arc_pair_faces`; the merge joins no arcs
        across a face's artwork or a can end's rings, so a printed or tinplate face is often
        fitted only on arc pairs). A face with markings it chooses takes the choice (an arc
        pair's ellipse is then added to ``merged``); otherwise both come back unchanged."""
        test = cues.markings
        if test.image is None or not any(ev.interior_edge_px >= test.min_edge_share
                                         * ev.perimeter_px for ev in choice.evidence):
            return merged, choice
        clock.check("top")
        arc_chains, arcs = last_resort_arcs(found.pieces, found.segments, found.fitted)
        arcs = _longest_arcs(arcs, arc_chains, self.config.limits.max_arcs)
        extra, alone = _arc_pair_faces(arcs, arc_chains, found.grad, found.points,
                                       found.grads, found.crop, found.gate)
        # Only whole faces with markings across them can be chosen so (the rule's evidence
        # of each ellipse is its own: the union's is the same).
        extra = [e for e, ev in zip(extra, alone.evidence, strict=True)
                 if whole_with_edges_inside(ev)
                 and ev.interior_edge_px >= test.min_edge_share * ev.perimeter_px]
        if not extra:
            return merged, choice
        n = len(merged)
        both = self._select([m.ellipse for m in merged] + extra, found, cues)
        if both.index is None or not both.evidence[both.index].occluded:
            return merged, choice
        mine = TopChoice(index=None, evidence=both.evidence[:n])
        if both.index < n:
            return merged, replace(mine, index=both.index)
        face = extra[both.index - n]
        if choice.index is not None and _refit_round(face, merged[choice.index].ellipse):
            return merged, choice
        return _with_face(merged, mine, face, both.evidence[both.index], found.chains,
                          found.grad)

    def _fallbacks(self, found: _Found, merged: list[MergedEllipse], choice: TopChoice,
                   cues: _Cues, clock: _Clock) -> tuple[list[MergedEllipse], TopChoice]:
        """When no ellipse passed the top rule, in order, until one gives a face: the
        unobstructed face, the contrast retry (and a clearly nearer face of arc pairs beside
        its choice), a face with its own rim inside, arc pairs of the fitted pieces, the
        retry's spare refit, arc pairs of every arc (see the module docstring)."""
        limits, crop, gate, grad = self.config.limits, found.crop, found.gate, found.grad
        edge_pixels = (found.points, found.grads)
        spare: tuple[int, Ellipse, OcclusionEvidence] | None = None
        # Before the contrast retry: a refit of a lower face can shrink past the outline
        # crossing it and pass.
        fallback = select_unobstructed(choice.evidence)
        if fallback is not None:
            return merged, replace(choice, index=fallback, reason="")
        clock.check("top")
        # Only then: a refit that passes next to a passing face is more often a lower,
        # nearly whole face than the top.
        merged, retried, spare = _retry_on_contrast(merged, choice.evidence, grad, crop,
                                                    gate, limits.max_refits)
        if retried:
            choice = self._select([m.ellipse for m in merged], found, cues)
        if retried and choice.index is not None and cues.radius_of is not None:
            # A face clearly nearer than such a refit is above it (a top face the merge never
            # fitted beside a lower, nearly whole face of its colour).
            arc_chains, arcs = last_resort_arcs(found.pieces, found.segments, found.fitted)
            arcs = _longest_arcs(arcs, arc_chains, limits.max_arcs)
            return _nearer_arc_face(merged, choice, arcs, found.chains, arc_chains, grad,
                                    edge_pixels, crop, gate, cues.k_crop, cues.radius_of)
        if choice.index is None:
            # A face whose fit took in a same-colour lower face's sliver (see RIM_BAND_PX).
            rimmed = select_rimmed([m.ellipse for m in merged], choice.evidence, found.points)
            if rimmed is not None:
                return merged, replace(choice, index=rimmed, reason="")
            # Last: a face the merge never fitted, from pairs of its arcs (see regroup).
            clock.check("top")
            merged, choice = _regroup_arcs(
                merged, choice, _longest_arcs(range(len(found.pieces)), found.chains,
                                              limits.max_arcs),
                found.chains, grad, edge_pixels, crop, gate)
        if choice.index is None and spare is not None:
            # The very last: a contrast refit with no T-junction and no edge inside, most of
            # its outline showing (select_unobstructed's evidence: a top face over a lower
            # face of its colour, fitted with part of that one's outline, refits onto its own
            # faint boundary).
            i, refit, refit_evidence = spare
            merged[i] = replace(merged[i], ellipse=refit)
            return merged, TopChoice(index=i, evidence=(*choice.evidence[:i], refit_evidence,
                                                        *choice.evidence[i + 1:]))
        if choice.index is None:
            # After all: pairs that take in the chains no fit was kept for and the parts of
            # chains cut at junctions too (see regroup), else the one with nothing crossing
            # it (its boundary with a lower face of its colour shows no contrast), else one
            # with its own rim inside. Last, as the least constrained.
            clock.check("top")
            arc_chains, arcs = last_resort_arcs(found.pieces, found.segments, found.fitted)
            arcs = _longest_arcs(arcs, arc_chains, limits.max_arcs)
            merged, choice = _regroup_arcs(merged, choice, arcs, found.chains, grad,
                                           edge_pixels, crop, gate, unobstructed=True,
                                           arc_chains=arc_chains)
        return merged, choice

    def _pose_stage(self, found: _Found, merged: list[MergedEllipse], choice: TopChoice,
                    img: NDArray[np.uint8], k: CameraIntrinsics, cues: _Cues,
                    timings: dict[str, float]) -> Detection:
        """The reported ellipses (distinct, supported, in frame pixels) and the top face's
        final fit and pose (``timings``: the stage times, shared with the caller, which
        adds this stage's)."""
        du, dv = found.roi.offset
        keep = _distinct([i for i, ev in enumerate(choice.evidence)
                          if ev.support >= MIN_REPORTED_SUPPORT or i == choice.index],
                         [m.ellipse for m in merged], choice)
        ellipses = tuple(
            DetectedEllipse(ellipse=_moved(merged[i].ellipse, du, dv),
                            segments=merged[i].segments, residual_px=merged[i].residual_px,
                            support=merged[i].support, evidence=choice.evidence[i])
            for i in keep)
        chains = found.chains
        frame_chains = chains if du == dv == 0 else _shifted(chains, np.array([du, dv],
                                                                               np.int32))
        if choice.index is None:
            return Detection(ellipses=ellipses, segments=frame_chains, timings_ms=timings,
                             reason=choice.reason)
        work, grad = found.work, found.grad
        top_ellipse = refine_subpixel(merged[choice.index].ellipse, grad, found.points,
                                      found.grads, found.crop)
        top_ellipse = _profile_refit(top_ellipse, work, grad)
        # The face's colour once, for its radius and the pose's wall test (the same pixels
        # in the crop and in the frame while the face's interior lies in the crop).
        face = face_colour(top_ellipse, work) if work.ndim == 3 else None
        colours = self.config.kind_colours
        radius = (None if colours is None or face is None
                  else _nearest_kind(face, _chromaticities(colours), self.config.radii_m))
        pose = estimate_pose(_moved(top_ellipse, du, dv), k,
                             self.config.radii_m if radius is None else (radius,), None,
                             self.config.depth_range_m,
                             image=img if img.ndim == 3 else None, face_rgb=face,
                             belt=cues.belt)
        return Detection(ellipses=ellipses, segments=frame_chains, top=keep.index(choice.index),
                         pose=pose, timings_ms=timings, reason=choice.reason)


class _OutOfTime(Exception):
    """The time budget ran out after (or within) ``stage``."""

    def __init__(self, stage: str) -> None:
        super().__init__(stage)
        self.stage = stage


def _best_supported(merged: list[MergedEllipse], cap: int) -> list[MergedEllipse]:
    """The ``cap`` best-supported of ``merged`` (of equals, the first), in their order."""
    if len(merged) <= cap:
        return merged
    best = sorted(range(len(merged)), key=lambda i: (-merged[i].support, i))
    return [merged[i] for i in sorted(best[:cap])]


def _within_gate(merged: list[MergedEllipse], gate: tuple[float, float] | None
                 ) -> list[MergedEllipse]:
    """Those of ``merged`` whose semi-major axis lies within the size ``gate`` (all without
    one)."""
    if gate is None:
        return merged
    return [m for m in merged if gate[0] <= m.ellipse.a <= gate[1]]


def _refit_round(face: Ellipse, chosen: Ellipse) -> bool:
    """Whether an arc pairs' ``face`` is the ``chosen`` face of the merge fitted again (one
    holds the other's centre) round it and beyond, the chosen face reaching into its rim band
    (:func:`~stackpick_sim.vision.markings.inside_rim_band`; the fit taking in the wall's
    silhouette or a lower face's arc beyond it): then the merge's fit is kept. A chosen fit
    lying within the arc face's rim band is a fit on an arc of that face's outline and its
    artwork, and gives way."""
    return ((holds_centre(face, chosen) or holds_centre(chosen, face))
            and not inside_rim_band(chosen, face, INTERIOR_MARGIN_PX))


def _longest_arcs(arcs: Sequence[int], chains: Sequence[NDArray[np.int32]], cap: int
                  ) -> list[int]:
    """The ``cap`` longest of the ``arcs`` (indices into ``chains``), in their order."""
    arcs = list(arcs)
    return [arcs[i] for i in longest([chains[a] for a in arcs], cap)]


def _upscaled_detection(found: Detection, factor: int) -> Detection:
    """A detection on the image downscaled by ``factor`` in the full image's pixels: ellipses
    and the pose's pixel centre mapped back (:func:`~stackpick_sim.vision.limits.upscaled`),
    chains' pixels to the full-image pixel nearest each block's centre."""
    shift = (factor - 1) // 2
    ellipses = tuple(replace(e, ellipse=upscaled(e.ellipse, factor)) for e in found.ellipses)
    segments = tuple((c * factor + shift).astype(np.int32) for c in found.segments)
    pose = found.pose
    if pose is not None:
        half = (factor - 1) / 2.0
        pose = replace(pose, x=pose.x * factor + half, y=pose.y * factor + half)
    return replace(found, ellipses=ellipses, segments=segments, pose=pose)


def object_kinds(kinds: Sequence[tuple[float, tuple[float, float, float], float]]
                 ) -> tuple[tuple[float, ...], tuple[tuple[float, float, float], ...] | None,
                            tuple[float, ...] | None]:
    """``radii_m``, ``kind_colours`` and ``heights_m`` for a DetectorConfig from a scene's
    object kinds, (radius m, RGB 0-1, height m) triples: each radius once, largest first, with
    its colour and height. The colours are None when the kinds cannot be told apart by colour
    (one radius in two colours, or two radii in colours within MIN_KIND_CHROMA_DISTANCE); the
    heights are None when one radius comes in two heights. ValueError for no kinds."""
    if not kinds:
        raise ValueError("no object kinds given")
    by_radius: dict[float, set[tuple[float, float, float]]] = {}
    heights: dict[float, set[float]] = {}
    for radius, rgb, height in kinds:
        by_radius.setdefault(float(radius), set()).add((float(rgb[0]), float(rgb[1]),
                                                        float(rgb[2])))
        heights.setdefault(float(radius), set()).add(float(height))
    radii = tuple(sorted(by_radius, reverse=True))
    kind_heights = (None if any(len(h) > 1 for h in heights.values()) else
                    tuple(next(iter(heights[r])) for r in radii))
    if any(len(c) > 1 for c in by_radius.values()):
        return radii, None, kind_heights
    colours = tuple(next(iter(by_radius[r])) for r in radii)
    chroma = np.asarray(colours) / np.maximum(np.sum(colours, axis=1, keepdims=True), 1e-9)
    apart = np.abs(chroma[:, None, :] - chroma[None, :, :]).sum(axis=2)
    np.fill_diagonal(apart, np.inf)
    if float(apart.min(initial=np.inf)) < MIN_KIND_CHROMA_DISTANCE:
        return radii, None, kind_heights
    return radii, colours, kind_heights


def radius_by_colour(image: NDArray[np.uint8], radii: tuple[float, ...],
                     colours: tuple[tuple[float, float, float], ...],
                     colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None
                     ) -> Callable[[Ellipse], float | None] | None:
    """Ellipse -> radius (of ``radii``) of the object kind whose colour (``colours``, RGB 0-1,
    parallel to ``radii``) is nearest in chromaticity to the face's colour in the (H, W, 3)
    RGB ``image`` the ellipse is given in; None for a gray image. ``colour_of``: the
    :func:`face_colours` of ``image`` when the caller has it."""
    if image.ndim != 3:
        return None
    chroma = _chromaticities(colours)
    colour = face_colours(image) if colour_of is None else colour_of
    # The top rule asks for a face's radius several times (rest test, depth test).
    known: dict[Ellipse, float | None] = {}

    def radius_of(ellipse: Ellipse) -> float | None:
        if ellipse not in known:
            known[ellipse] = _nearest_kind(colour(ellipse), chroma, radii)
        return known[ellipse]

    return radius_of


def marking_test(config: DetectorConfig, image: NDArray[np.uint8], grad: EdgeImage
                 ) -> MarkingTest:
    """The top rule's settings for markings inside a face (:mod:`~stackpick_sim.vision.
    markings`) on ``image`` ((H, W) or (H, W, 3) RGB) and its edges and gradients ``grad``:
    ``config``'s radii and marking keys, a face's kind read from its rim band's colour when
    the kinds' colours are known (an RGB image), the image for the two-surface test."""
    rgb = image if image.ndim == 3 else None
    colours = config.kind_colours
    rim_radius_of = (None if colours is None or rgb is None else
                     radius_by_colour(rgb, config.radii_m, colours,
                                      face_colours(rgb, RIM_SAMPLE_SCALE)))
    return MarkingTest(radii=config.radii_m, rim_radius_of=rim_radius_of,
                       depth_ratio=config.marking_depth_ratio,
                       min_edge_share=config.marking_min_edge_share,
                       margin_px=INTERIOR_MARGIN_PX, image=rgb, gradients=grad)


def face_colours(image: NDArray[np.uint8], scale: float = FACE_SAMPLE_SCALE
                 ) -> Callable[[Ellipse], NDArray[np.float64]]:
    """Ellipse -> its face's (3,) colour in the (H, W, 3) RGB ``image`` (:func:`~stackpick_sim.
    vision.wall.face_colour` on the ellipse of ``scale`` times its semi-axes; the array is
    shared: not to be modified), each face's once (its radius and the rest test's wall bands
    both read it)."""
    known: dict[Ellipse, NDArray[np.float64]] = {}

    def colour_of(ellipse: Ellipse) -> NDArray[np.float64]:
        colour = known.get(ellipse)
        if colour is None:
            colour = known[ellipse] = face_colour(ellipse, image, scale)
        return colour

    return colour_of


def _chromaticities(colours: tuple[tuple[float, float, float], ...]
                    ) -> list[tuple[float, float, float]]:
    """(r, g, b) / (r + g + b) of each RGB colour (0-1)."""
    out = []
    for r, g, b in colours:
        total = max(float(r) + float(g) + float(b), 1e-9)
        out.append((float(r) / total, float(g) / total, float(b) / total))
    return out


def _nearest_kind(face: NDArray[np.float64], chroma: list[tuple[float, float, float]],
                  radii: tuple[float, ...]) -> float | None:
    """The radius of the kind whose chromaticity is nearest (L1) to the (3,) RGB ``face``
    colour (the first of equals); None for a black face."""
    # Three numbers per kind: Python floats cost less than numpy's calls.
    f0, f1, f2 = face.tolist()
    total = f0 + f1 + f2
    if total <= 0.0:
        return None
    f0, f1, f2 = f0 / total, f1 / total, f2 / total
    d = [abs(c0 - f0) + abs(c1 - f1) + abs(c2 - f2) for c0, c1, c2 in chroma]
    return float(radii[d.index(min(d))])


def _retry_on_contrast(merged: list[MergedEllipse], evidence: tuple[OcclusionEvidence, ...],
                       grad: EdgeImage, shape: tuple[int, int],
                       gate: tuple[float, float] | None = None, max_refits: int = 8
                       ) -> tuple[list[MergedEllipse], bool,
                                  tuple[int, Ellipse, OcclusionEvidence] | None]:
    """Refit on the edge contrast (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`)
    each ellipse that failed the top rule on support or interior edges only (no T-junction,
    support at least MIN_REPORTED_SUPPORT), on the strongest and else on the innermost
    consistent edge (at most ``max_refits`` ellipses, the best-supported: each refit reads
    profiles along its whole outline); keep a refit where it passes the rule. Returns the
    ellipses, whether any changed, and, when none passed, the refit
    :func:`~stackpick_sim.vision.occlusion.select_unobstructed` takes among those within the
    size ``gate`` ((min, max) semi-major axis, px, or None) as (index of the ellipse it
    refits, refit, its evidence), else None."""
    todo = [i for i, ev in enumerate(evidence)
            if ev.occluded and not ev.occluded_ends and ev.support >= MIN_REPORTED_SUPPORT]
    if len(todo) > max_refits:  # the best-supported, in their order
        best = sorted(todo, key=lambda i: (-evidence[i].support, i))[:max_refits]
        todo = sorted(best)
    tries = [(i, r) for innermost in (False, True) for i in todo
             if (r := refit_on_contrast(merged[i].ellipse, grad, innermost)) is not None
             and plausible(r, shape)]
    if not tries:
        return merged, False, None
    checked = select_top([r for _, r in tries], grad).evidence
    passed: dict[int, Ellipse] = {}
    for (i, r), ev in zip(tries, checked, strict=True):
        if not ev.occluded and i not in passed:  # the strongest-edge refit first
            passed[i] = r
    if not passed:
        sized = [k for k, (_, r) in enumerate(tries) if gate is None or gate[0] <= r.a <= gate[1]]
        spare = select_unobstructed([checked[k] for k in sized])
        return merged, False, (None if spare is None else
                               (tries[sized[spare]][0], tries[sized[spare]][1],
                                checked[sized[spare]]))
    return [replace(m, ellipse=passed[i]) if i in passed else m
            for i, m in enumerate(merged)], True, None


def last_resort_arcs(pieces: list[NDArray[np.int32]], chains: Sequence[NDArray[np.int32]],
                     fitted: set[int]) -> tuple[tuple[NDArray[np.int32], ...], list[int]]:
    """The chains the last arc pairs are drawn from, and which of them are arcs (indices):
    the fitted ``pieces``, then the edge ``chains`` ((N_i, 2) pixels) cut at their junctions
    (:func:`~stackpick_sim.vision.regroup.split_at_junctions`). Arcs are the pieces and the
    parts at least MIN_FIT_PX long of the chains that were cut or that are not in ``fitted``
    (the chains some piece of which was fitted)."""
    out = list(pieces)
    arcs = list(range(len(pieces)))
    for k, parts in enumerate(split_at_junctions(chains)):
        for part in parts:
            if part.shape[0] >= MIN_FIT_PX and (len(parts) > 1 or k not in fitted):
                arcs.append(len(out))
            out.append(part)
    return tuple(out), arcs


def _regroup_arcs(merged: list[MergedEllipse], choice: TopChoice,
                  arcs: Sequence[int], chains: tuple[NDArray[np.int32], ...],
                  grad: EdgeImage, edge_pixels: tuple[NDArray[np.float64], NDArray[np.float64]],
                  shape: tuple[int, int], gate: tuple[float, float] | None,
                  unobstructed: bool = False,
                  arc_chains: tuple[NDArray[np.int32], ...] | None = None
                  ) -> tuple[list[MergedEllipse], TopChoice]:
    """When no ellipse passed the top rule: the ellipses of pairs of the ``arcs``
    (:func:`_arc_pair_faces`) through the top rule alone (no rival that already failed it can
    win), and with ``unobstructed``, when none passes, through its last resorts
    (:func:`~stackpick_sim.vision.occlusion.select_unobstructed`, then :func:`~stackpick_sim.
    vision.occlusion.select_rimmed`). Only one chosen so is added (with its evidence) to
    ``merged``; otherwise both come back unchanged."""
    found, extra = _arc_pair_faces(arcs, chains if arc_chains is None else arc_chains, grad,
                                   edge_pixels[0], edge_pixels[1], shape, gate)
    if not found:
        return merged, choice
    if extra.index is None and unobstructed:
        extra = replace(extra, index=select_unobstructed(extra.evidence))
    if extra.index is None and unobstructed:
        extra = replace(extra, index=select_rimmed(found, extra.evidence, edge_pixels[0]))
    if extra.index is None:
        return merged, choice
    return _with_face(merged, choice, found[extra.index], extra.evidence[extra.index], chains,
                      grad)


def _arc_pair_faces(arcs: Sequence[int], arc_chains: tuple[NDArray[np.int32], ...],
                    grad: EdgeImage, points: NDArray[np.float64], grads: NDArray[np.float64],
                    shape: tuple[int, int], gate: tuple[float, float] | None
                    ) -> tuple[list[Ellipse], TopChoice]:
    """The ellipses of pairs of the ``arcs`` (indices into ``arc_chains``;
    :func:`~stackpick_sim.vision.regroup.arc_pair_ellipses`), refined on the edge map (its
    pixels ``points`` and their gradients ``grads``) like the merged ones and within the size
    ``gate``, and the top rule's choice among them alone (no intrinsics: the depth, wall and
    rest tests need rivals)."""
    found = arc_pair_ellipses(arc_chains, arcs, shape, gate)
    if found:
        found = [e for e in refine_all(found, points, grads, shape)
                 if gate is None or gate[0] <= e.a <= gate[1]]
    if not found:
        return [], TopChoice(index=None, evidence=())
    return found, select_top(found, grad, edge_points=points)


def _with_face(merged: list[MergedEllipse], choice: TopChoice, ellipse: Ellipse,
               evidence: OcclusionEvidence, chains: tuple[NDArray[np.int32], ...],
               grad: EdgeImage) -> tuple[list[MergedEllipse], TopChoice]:
    """``merged`` with ``ellipse`` added (its support, the ``chains`` on it and their
    residual), and the choice of it, ``evidence`` added to ``choice``'s."""
    support = float(support_shares([ellipse], support_map(grad.edges))[0])
    on = chains_on(ellipse, *chain_table(chains))
    residual = rms_residual(ellipse, np.concatenate([chains[k] for k in on])) if on else 0.0
    merged = [*merged, MergedEllipse(ellipse=ellipse, segments=on, residual_px=residual,
                                     support=support)]
    return merged, TopChoice(index=len(merged) - 1, evidence=(*choice.evidence, evidence))


def _nearer_arc_face(merged: list[MergedEllipse], choice: TopChoice, arcs: Sequence[int],
                     chains: tuple[NDArray[np.int32], ...],
                     arc_chains: tuple[NDArray[np.int32], ...], grad: EdgeImage,
                     edge_pixels: tuple[NDArray[np.float64], NDArray[np.float64]],
                     shape: tuple[int, int], gate: tuple[float, float] | None,
                     intrinsics: CameraIntrinsics, radius_of: Callable[[Ellipse], float | None]
                     ) -> tuple[list[MergedEllipse], TopChoice]:
    """``choice`` (an index) unchanged, unless an ellipse of pairs of the ``arcs`` that passes
    the top rule (:func:`_arc_pair_faces`), or fails it on support alone with nothing crossing
    it (:func:`~stackpick_sim.vision.occlusion.unobstructed`: the rule's depth test hears
    those too), and is another face than the chosen one (neither holds the other's centre) is
    clearly nearer the camera than it and every other such (:func:`~stackpick_sim.vision.
    occlusion.clearly_nearest`): then it is added to ``merged`` and chosen."""
    assert choice.index is not None
    chosen = merged[choice.index].ellipse
    found, extra = _arc_pair_faces(arcs, arc_chains, grad, edge_pixels[0], edge_pixels[1],
                                   shape, gate)
    passed = [i for i, ev in enumerate(extra.evidence) if (not ev.occluded or unobstructed(ev))
              and not (holds_centre(chosen, found[i]) or holds_centre(found[i], chosen))]
    if not passed:
        return merged, choice
    faces = [chosen, *(found[i] for i in passed)]
    nearest = clearly_nearest(faces, intrinsics, radius_of)
    if nearest is None or nearest == 0:  # no face clearly nearest, or the chosen one is
        return merged, choice
    i = passed[nearest - 1]
    return _with_face(merged, choice, found[i], extra.evidence[i], chains, grad)


def _distinct(indices: list[int], ellipses: list[Ellipse], choice: TopChoice) -> list[int]:
    """``indices`` without duplicates, in their order: an ellipse whose outline lies within
    DUPLICATE_TOLERANCE_PX of an ellipse already kept, along at least DUPLICATE_SHARE of it
    (and the other way round), is the same face fitted twice (two arcs the merge kept apart
    refine to one outline). The top face is kept first, then the better supported. Refits of
    the top face on other outlines too (:func:`_top_misfits`) and far rims of better-supported
    faces (:func:`_far_rim`) are dropped too."""
    order = sorted(indices, key=lambda i: (i != choice.index, -choice.evidence[i].support))
    same = _same_outlines(ellipses, order)
    misfits = _top_misfits(ellipses, order, choice.index)
    kept: list[int] = []
    for i in order:
        if i not in misfits and not any((i, j) in same for j in kept):
            kept.append(i)
    # Far rims: only of better-supported faces, never the top.
    return sorted(i for i in kept if i == choice.index or not any(
        choice.evidence[j].support > choice.evidence[i].support
        and _far_rim(ellipses[i], ellipses[j]) for j in kept if j != i))


def _top_misfits(ellipses: list[Ellipse], indices: list[int], top: int | None) -> set[int]:
    """Those of ``indices`` (other than ``top``) whose outline lies within
    DUPLICATE_TOLERANCE_PX of the top ellipse's along at least MISFIT_SHARE of it (see
    MISFIT_SHARE), all in one array pass; empty without a top. Only ellipses whose centre
    lies within the top's semi-major axis of its centre are compared (the cost is in the
    array pass): a refit of the top on half its own outline keeps its centre near the top's."""
    if top is None:
        return set()
    face = ellipses[top]
    others = [i for i in indices if i != top
              and math.hypot(ellipses[i].cx - face.cx, ellipses[i].cy - face.cy) < face.a]
    if not others:
        return set()
    shares = boundary_shares([(ellipses[i], ellipses[top]) for i in others],
                             DUPLICATE_TOLERANCE_PX)
    return {i for i, share in zip(others, shares, strict=True) if share >= MISFIT_SHARE}


def _far_rim(rim: Ellipse, face: Ellipse) -> bool:
    """Whether ``rim`` is the far rim of the cylinder whose face is ``face``: the same size
    (within RIM_SIZE_TOLERANCE), shifted along the face's minor axis (the projected cylinder
    axis, within RIM_ANGLE_DEG) by RIM_OFFSET_RANGE of its semi-major axis."""
    if (abs(rim.a - face.a) > RIM_SIZE_TOLERANCE * face.a
            or abs(rim.b - face.b) > RIM_SIZE_TOLERANCE * face.b):
        return False
    du, dv = rim.cx - face.cx, rim.cy - face.cy
    offset = math.hypot(du, dv)
    lo, hi = RIM_OFFSET_RANGE
    if not lo * face.a <= offset <= hi * face.a:
        return False
    minor = math.radians(face.angle_deg + 90.0)
    along = abs(du * math.cos(minor) + dv * math.sin(minor)) / offset
    return along >= math.cos(math.radians(RIM_ANGLE_DEG))


def _same_outlines(ellipses: list[Ellipse], indices: list[int]) -> set[tuple[int, int]]:
    """The pairs (i, j), both ways, of ``indices`` whose ellipses have the same outline (see
    :func:`_distinct`): centres within the larger semi-minor axis and within DUPLICATE_NEAR_PX,
    semi-axes within DUPLICATE_NEAR_PX, and each outline within DUPLICATE_TOLERANCE_PX of the
    other along DUPLICATE_SHARE of it, every pair's two shares computed in one array pass."""
    pairs = []
    for k, i in enumerate(indices):
        one = ellipses[i]
        for j in indices[k + 1:]:
            other = ellipses[j]
            gap = math.hypot(one.cx - other.cx, one.cy - other.cy)
            if (gap <= max(one.b, other.b) and gap <= DUPLICATE_NEAR_PX
                    and abs(one.a - other.a) <= DUPLICATE_NEAR_PX
                    and abs(one.b - other.b) <= DUPLICATE_NEAR_PX):
                pairs.append((i, j))
    if not pairs:
        return set()
    shares = boundary_shares([w for i, j in pairs for w in ((ellipses[i], ellipses[j]),
                                                              (ellipses[j], ellipses[i]))],
                             DUPLICATE_TOLERANCE_PX)
    same: set[tuple[int, int]] = set()
    for k, (i, j) in enumerate(pairs):
        if shares[2 * k] >= DUPLICATE_SHARE and shares[2 * k + 1] >= DUPLICATE_SHARE:
            same.update(((i, j), (j, i)))
    return same


def _profile_refit(ellipse: Ellipse, work: NDArray[np.uint8], grad: EdgeImage) -> Ellipse:
    """:func:`~stackpick_sim.vision.refine.refine_on_profile` of ``ellipse`` on the unblurred
    gradients of the window of ``work`` around it (the window keeps the cost per face)."""
    u0, v0, u1, v1 = ellipse.bounds()
    margin = PROFILE_REACH_PX + PROFILE_WINDOW_MARGIN_PX
    h, w = work.shape[:2]
    c0, r0 = max(0, math.floor(u0 - margin)), max(0, math.floor(v0 - margin))
    c1, r1 = min(w, math.ceil(u1 + margin) + 1), min(h, math.ceil(v1 + margin) + 1)
    if min(c1 - c0, r1 - r0) < MIN_SIDE_PX:
        return ellipse
    window = np.ascontiguousarray(work[r0:r1, c0:c1])
    box = EdgeImage(edges=grad.edges[r0:r1, c0:c1], gx=grad.gx, gy=grad.gy, noise=grad.noise)
    raw = unblurred_gradients(window, box)
    fit = refine_on_profile(_moved(ellipse, -c0, -r0), raw, (r1 - r0, c1 - c0))
    return _moved(fit, c0, r0)


def _shifted(chains: tuple[NDArray[np.int32], ...], offset: NDArray[np.int32]
             ) -> tuple[NDArray[np.int32], ...]:
    """Each (N_i, 2) chain plus ``offset`` (2,), in one array pass (views of one array)."""
    if not chains:
        return chains
    every = np.concatenate(chains)
    every += offset
    out = []
    start = 0
    for c in chains:
        stop = start + c.shape[0]
        out.append(every[start:stop])
        start = stop
    return tuple(out)


def _moved(ellipse: Ellipse, du: float, dv: float) -> Ellipse:
    """``ellipse`` shifted by (du, dv) px (from ROI to frame coordinates)."""
    if du == dv == 0:
        return ellipse
    # Built directly: dataclasses.replace costs several times the constructor.
    return Ellipse.of(ellipse.cx + du, ellipse.cy + dv, ellipse.a, ellipse.b, ellipse.angle_deg)


def detect(image: NDArray, config: DetectorConfig | None = None) -> Detection:
    """Detect the top object and its pose in ``image`` ((H, W) or (H, W, 3) RGB)."""
    return TopObjectDetector(config).detect(image)

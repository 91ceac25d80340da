"""The top-object detector: an ordered tuple of named stages (:mod:`~stackpick_sim.vision.
stages`) from the image to the top face's pose.

The built-in stages, :data:`STAGES`, in order: ``roi`` (the box around the pile,
:mod:`~stackpick_sim.vision.roi`), ``edges`` (:mod:`~stackpick_sim.vision.edges`),
``segments`` (edge chains, :mod:`~stackpick_sim.vision.segments`), ``fitting`` (an ellipse per
chain, :mod:`~stackpick_sim.vision.fitting`), ``merging`` (:mod:`~stackpick_sim.vision.
merging`), ``refine`` (each ellipse refitted on the edge pixels along it, :mod:`~stackpick_sim.
vision.refine`), ``gate`` (with a depth range, ellipses of no face's size dropped), ``top``
(the top rule, :func:`~stackpick_sim.vision.occlusion.select_top`, its rest check and its
fallbacks, each named by the failure class it handles: :class:`~stackpick_sim.config.
vision_params.TopParams`) and ``pose`` (the reported ellipses, each face once, and the top
face's final fit and pose, :mod:`~stackpick_sim.vision.pose`). ``roi``, ``refine`` and
``gate`` may be skipped (:meth:`DetectorConfig.without`); any stage may be replaced by name
(:meth:`DetectorConfig.with_stage`). Each stage's tuned settings are a section of
:class:`DetectorConfig` (:mod:`~stackpick_sim.config.vision_params`).

Entry point :func:`detect` (or a reusable :class:`TopObjectDetector`). Any image gives a
:class:`~stackpick_sim.vision.detection.Detection` (falsy with a reason on a miss) or, for
input that is not an image at all (wrong dtype, shape, NaN), one
:class:`~stackpick_sim.exceptions.ImageError`.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.config.vision_params import (
    CompleteParams,
    FitParams,
    MergeParams,
    PoseParams,
    ReportParams,
    StageSections,
    TopParams,
    sections_of,
)
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels_refine
from stackpick_sim.vision.contrast import refit_on_contrast
from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.edges import (
    MIN_SIDE_PX,
    EdgeImage,
    as_rgb_or_gray,
    edge_image_points,
    unblurred_gradients,
)
from stackpick_sim.vision.faint_faces import complete_faces
from stackpick_sim.vision.fitting import (
    fit_all,
    plausible,
    rms_residual,
    within_gate,
)
from stackpick_sim.vision.inner_face import inner_refit, refitted
from stackpick_sim.vision.kind_size import depth_radius, kinds_by_size
from stackpick_sim.vision.leaning import select_leaning
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
    OcclusionEvidence,
    TopChoice,
    clearly_nearest,
    hidden_by_no_outline,
    holds_centre,
    rim_only,
    select_resting_rimmed,
    select_rimmed,
    select_top,
    select_unobstructed,
    unobstructed,
)
from stackpick_sim.vision.pose import Pose, estimate_pose
from stackpick_sim.vision.refine import (
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
from stackpick_sim.vision.resting import rest_test
from stackpick_sim.vision.roi import Roi, find_roi
from stackpick_sim.vision.segments import link_segments
from stackpick_sim.vision.stages import (
    Cues,
    OutOfTime,
    Stage,
    StageError,
    State,
    check_time,
    run_stages,
)
from stackpick_sim.vision.under_wall import under_a_wall
from stackpick_sim.vision.undistort import undistort
from stackpick_sim.vision.wall import FACE_SAMPLE_SCALE, face_colour
from stackpick_sim.vision.whole_refit import below, settled, whole_refits

#: Vertical field of view (deg) assumed when no intrinsics are given: the wrist camera's.
DEFAULT_FOVY_DEG = 45.0
#: The paper scene's cylinder radii, metres (large and small kind).
DEFAULT_RADII_M: tuple[float, ...] = (0.035, 0.025)
#: The stages a detection cannot do without (the others, SKIPPABLE_STAGES, may be skipped:
#: the whole frame, the merged fits, no size gate).
REQUIRED_STAGES: tuple[str, ...] = ("edges", "segments", "fitting", "merging", "top", "pose")
#: The report settings' defaults (the helpers' default argument).
DEFAULT_REPORT = ReportParams()
#: The top rule's default settings.
DEFAULT_TOP = TopParams()
#: The fits' default settings.
DEFAULT_FITS = FitParams()


@dataclass(frozen=True, kw_only=True)
class DetectorConfig(StageSections):
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

    ``roi``, ``edges``, ``segments``, ``fits``, ``merging``, ``refine``, ``gate``, ``top``,
    ``markings``, ``report``, ``pose``: each stage's tuned settings (the scene's
    ``[vision.SECTION]`` tables, :mod:`~stackpick_sim.config.vision_params`);
    ``ellipses``: the scoring of :func:`~stackpick_sim.vision.ellipses.find_ellipses` (the
    ellipse stages alone).
    ``stages``: the stages run, in order (default :data:`STAGES`; see :meth:`without` and
    :meth:`with_stage`).
    """

    intrinsics: CameraIntrinsics | None = None
    radii_m: tuple[float, ...] = DEFAULT_RADII_M
    depth_range_m: tuple[float, float] | None = None
    kind_colours: tuple[tuple[float, float, float], ...] | None = None
    heights_m: tuple[float, ...] | None = None
    limits: WorkLimits = field(default_factory=WorkLimits)
    marking_depth_ratio: float = VisionCfg.marking_depth_ratio
    marking_min_edge_share: float = VisionCfg.marking_min_edge_share
    stages: tuple[Stage, ...] = field(default_factory=lambda: STAGES)

    def __post_init__(self) -> None:
        if not self.radii_m or any(not r > 0 for r in self.radii_m):
            raise ConfigError(f"radii_m must be positive metres, got {self.radii_m}")
        if self.depth_range_m is not None:
            lo, hi = self.depth_range_m
            if not 0 < lo <= hi:
                raise ConfigError(f"depth_range_m must be 0 < min <= max, got {self.depth_range_m}")
        self._check_kinds()
        if not 0.5 <= self.marking_depth_ratio <= 2.0:
            raise ConfigError("marking_depth_ratio must lie in 0.5 to 2, got "
                              f"{self.marking_depth_ratio}")
        if not 0.0 <= self.marking_min_edge_share <= 10.0:
            raise ConfigError("marking_min_edge_share must lie in 0 to 10, got "
                              f"{self.marking_min_edge_share}")
        _check_stages(self.stages)

    def _check_kinds(self) -> None:
        """ConfigError unless the kinds' colours and heights match the radii."""
        if self.kind_colours is not None and (
                len(self.kind_colours) != len(self.radii_m)
                or any(len(c) != 3 or not all(0.0 <= x <= 1.0 for x in c)
                       for c in self.kind_colours)):
            raise ConfigError("kind_colours must give one RGB colour (components 0-1) per "
                              f"radius in radii_m, got {self.kind_colours}")
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

    def with_vision(self, vision: VisionCfg) -> DetectorConfig:
        """This config with the settings of a scene's ``[vision]`` table: the work limits, the
        marking test, every stage section and the stages it skips."""
        config = replace(self, limits=WorkLimits.of(vision),
                         marking_depth_ratio=vision.marking_depth_ratio,
                         marking_min_edge_share=vision.marking_min_edge_share,
                         **sections_of(vision))
        return config.without(*vision.skip_stages) if vision.skip_stages else config

    def without(self, *names: str) -> DetectorConfig:
        """This config with the stages ``names`` skipped; ConfigError for a stage it does
        not run or one of REQUIRED_STAGES."""
        present = {s.name for s in self.stages}
        for name in names:
            if name not in present:
                raise ConfigError(f"no stage {name!r} to skip; the stages are "
                                  f"{', '.join(s.name for s in self.stages)}")
            if name in REQUIRED_STAGES:
                raise ConfigError(f"the {name} stage cannot be skipped (required: "
                                  f"{', '.join(REQUIRED_STAGES)}); replace it instead")
        return replace(self, stages=tuple(s for s in self.stages if s.name not in names))

    def with_stage(self, name: str, run: Callable[[State, DetectorConfig], State]
                   ) -> DetectorConfig:
        """This config with stage ``name``'s function replaced by ``run`` (same place, same
        timing key); ConfigError for a stage it does not run."""
        if name not in {s.name for s in self.stages}:
            raise ConfigError(f"no stage {name!r} to replace; the stages are "
                              f"{', '.join(s.name for s in self.stages)}")
        return replace(self, stages=tuple(Stage(name, run) if s.name == name else s
                                          for s in self.stages))


def _check_stages(stages: tuple[Stage, ...]) -> None:
    """ConfigError unless ``stages`` are Stages with distinct names, every required one."""
    if not all(isinstance(s, Stage) for s in stages):
        raise ConfigError("stages must be Stage(name, run) values")
    names = [s.name for s in stages]
    missing = [n for n in REQUIRED_STAGES if n not in names]
    if missing or len(set(names)) != len(names):
        raise ConfigError(f"stages must have distinct names and include {', '.join(missing)}; "
                          f"got {', '.join(names)}")


class TopObjectDetector:
    """Finds the top cylinder's face and pose in one image; see :func:`detect`."""

    def __init__(self, config: DetectorConfig | None = None) -> None:
        self.config = config or DetectorConfig()

    def _intrinsics(self, shape: tuple[int, int]) -> CameraIntrinsics:
        if self.config.intrinsics is not None:
            return self.config.intrinsics
        return CameraIntrinsics.from_fovy(DEFAULT_FOVY_DEG, shape[1], shape[0])

    def _axis_range(self, k: CameraIntrinsics) -> tuple[float, float] | None:
        """(min, max) semi-major axis (px) of a face given the depth range (see
        :func:`axis_range`)."""
        return axis_range(k, self.config)

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
        """:meth:`detect` of a validated image within the pixel limit: the configured stages
        in order, each timed into the detection's ``timings_ms``."""
        timings: dict[str, float] = {}
        shape = (int(img.shape[0]), int(img.shape[1]))
        state = State.start(image=img, intrinsics=self._intrinsics(shape), deadline=deadline,
                            roi=Roi.of(0, 0, shape[1], shape[0]), work=img, crop=shape,
                            timings_ms=timings)
        try:
            state = run_stages(self.config.stages, state, self.config, t0)
        except OutOfTime as out:
            timings["total"] = (time.perf_counter() - t0) * 1e3
            return Detection(timings_ms=timings,
                             reason=f"time budget of {deadline.budget_ms:g} ms ran out after "
                                    f"the {out.stage} stage")
        timings["total"] = (time.perf_counter() - t0) * 1e3
        if state.detection is None:
            raise StageError("no stage made a detection (the pose stage makes it)")
        return state.detection


def axis_range(k: CameraIntrinsics, config: DetectorConfig) -> tuple[float, float] | None:
    """(min, max) semi-major axis (px) of a face given the depth range, or None without one
    (see :attr:`GateParams.slack <stackpick_sim.config.vision_params.GateParams.slack>`)."""
    if config.depth_range_m is None:
        return None
    near, far = config.depth_range_m
    radii = config.radii_m
    lo = config.gate.slack[0] * min(k.fx, k.fy) * min(radii) / far
    hi = config.gate.slack[1] * max(k.fx, k.fy) * max(radii) / near
    return lo, hi


def roi_stage(state: State, config: DetectorConfig) -> State:
    """The box around the pile (:func:`~stackpick_sim.vision.roi.find_roi`) and its crop;
    the whole frame when the box is too small to work on."""
    roi = find_roi(state.image, config.roi)
    work = np.ascontiguousarray(roi.crop(state.image))
    if min(work.shape[:2]) < MIN_SIDE_PX:
        return state
    return state.updated(roi=roi, work=work, crop=(int(work.shape[0]), int(work.shape[1])))


def edges_stage(state: State, config: DetectorConfig) -> State:
    """The crop's edge image (:func:`~stackpick_sim.vision.edges.edge_image`) and its edge
    pixels with their unit gradients (:func:`~stackpick_sim.vision.refine.edge_points`), in
    one pass (:func:`~stackpick_sim.vision.edges.edge_image_points`)."""
    grad, points, grads = edge_image_points(state.work, config.edges)
    return state.updated(grad=grad, points=points, grads=grads)


def segments_stage(state: State, config: DetectorConfig) -> State:
    """The edge chains (:func:`~stackpick_sim.vision.segments.link_segments`), the
    ``limits.max_chains`` longest."""
    cap = config.limits.max_chains
    segments = link_segments(state.edges("segments").edges, cap, config.segments,
                             state.points).chains
    if len(segments) > cap:
        segments = tuple(segments[i] for i in longest(segments, cap))
    return state.updated(segments=segments)


def fitting_stage(state: State, config: DetectorConfig) -> State:
    """An ellipse per chain (:func:`~stackpick_sim.vision.fitting.fit_all`), the
    ``limits.max_fits`` on the longest arcs."""
    found = fit_all(state.segments, state.crop, params=config.fits)
    if len(found) > config.limits.max_fits:
        found = [found[i] for i in longest([f[1] for f in found], config.limits.max_fits)]
    return state.updated(fits=tuple(found))


def merging_stage(state: State, config: DetectorConfig) -> State:
    """The fits of one ellipse merged (:func:`~stackpick_sim.vision.merging.merge_segments`),
    the ``limits.max_ellipses`` best-supported."""
    fits = state.fits
    merged = merge_segments(state.chains, [(i, f[2]) for i, f in enumerate(fits)],
                            state.edges("merging").edges, [f[3] for f in fits],
                            config.merging, config.fits)
    return state.updated(merged=_best_supported(merged, config.limits.max_ellipses))


def refine_stage(state: State, config: DetectorConfig) -> State:
    """Each ellipse refitted on the edge pixels along it (:func:`~stackpick_sim.vision.
    refine.refine_all`)."""
    merged = state.merged
    refined = refine_all([m.ellipse for m in merged], state.points, state.grads, state.crop,
                         config.refine, config.fits)
    # An ellipse the refit left as it was keeps its record.
    return state.updated(merged=[
        m if e is m.ellipse else MergedEllipse.of(e, m.segments, m.residual_px, m.support)
        for m, e in zip(merged, refined, strict=True)])


def gate_stage(state: State, config: DetectorConfig) -> State:
    """With a depth range, the size gate (:func:`axis_range`) and the ellipses within it (after
    the refit: a fit on a few short arcs can be far smaller than its face); the arc pairs of
    the top rule's fallbacks are held to it too."""
    gate = axis_range(state.intrinsics, config)
    return state.updated(gate=gate, merged=_within_gate(state.merged, gate))


def top_stage(state: State, config: DetectorConfig) -> State:
    """The top rule with every cue, then, when it chose a face, the rest check
    (``top.rest_check``), the check for a face leaning on it (``lean``), the hidden-face
    check (``top.hidden_check``) and the inner refit (``top.inner_refit``), and when it
    chose none, its fallbacks (``top.fallbacks``), then a face inside a fit that reads as
    occluded (``inner_face``) and a top face fitted round its own wall (``whole_refit``).
    Before those, when its first choice is not clear, faces the merge never fitted whose outline is
    faint along part of its length join it (``complete``), and when no ellipse passed the
    rule outright, faces with markings fitted on arc pairs (``top.marked_arcs``)."""
    cues = _cues(state, config)
    merged = list(state.merged)
    choice = _select([m.ellipse for m in merged], state, cues)
    if config.complete.enabled and not _clear(choice, config.complete):
        # A top face the merge never fitted, its outline faint along part of its length.
        merged, choice = _faint_faces(state, merged, choice, cues, config)
    if config.top.marked_arcs and (choice.index is None
                                   or choice.evidence[choice.index].occluded):
        # None passed the rule outright: faces with markings the merge never fitted.
        merged, choice = _marked_arc_faces(state, merged, choice, cues, config)
    if config.top.rest_check and choice.index is not None:
        choice = _rest_check(state, merged, choice, cues, config.top)
    choice = _lean_check(state, merged, choice, cues, config)
    if (config.top.hidden_check and choice.index is not None and cues.radius_of is not None
            and hidden_by_no_outline(choice, config.top.hidden_min_support)):
        # A face cut short by an occluder that shows no outline: a top face of its colour
        # and shade the merge never fitted.
        check_time(state.deadline, "top")
        merged, choice = _nearer_arcs(state, merged, choice, cues, config, every_arc=False)
    if choice.index is None:
        merged, choice = _fallbacks(state, merged, choice, cues, config)
        # Every face reads as occluded: a top face inside a lower face's fit.
        merged, choice = _inner_face(state, merged, choice, cues, config)
        # A top face fitted round its own wall, shown whole by its refit.
        merged, choice = _whole_refit(state, merged, choice, cues, config)
    elif config.top.inner_refit:
        merged, choice = _inner_refit(state, merged, choice, config)
    return _unless_under_wall(state, state.updated(cues=cues, merged=merged, choice=choice),
                              config)


def _unless_under_wall(state: State, found: State, config: DetectorConfig) -> State:
    """``found`` (the top stage's outcome on ``state``), unless its choice lies behind
    another face's cylinder (:func:`_under_wall`: a far rim): then the top stage again on
    ``state`` without that ellipse."""
    assert found.choice is not None and found.cues is not None
    choice, merged = found.choice, found.merged
    if not _under_wall(merged, choice, found.cues, config):
        return found
    return top_stage(state.updated(merged=[m for k, m in enumerate(merged)
                                           if k != choice.index]), config)


def _clear(choice: TopChoice, params: CompleteParams) -> bool:
    """Whether the top rule's ``choice`` is clear: a face that passed it outright and shows
    a consistent edge along at least ``params.min_contrast_share`` of its outline (a whole
    face; the rule's support, read from the edge contrast); never with ``params.always``."""
    i = choice.index
    return (not params.always and i is not None and not choice.evidence[i].occluded
            and choice.evidence[i].support >= params.min_contrast_share)


def _faint_faces(state: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                 config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """The faces the merge never fitted whose outline is faint along part of its length
    (:func:`~stackpick_sim.vision.faint_faces.complete_faces`, ``complete``, from the arcs
    of :func:`last_resort_arcs`) added to ``merged``, each with the chains lying on it, and
    the top rule's choice among them all; both unchanged when none is found."""
    check_time(state.deadline, "top")
    arc_chains, arcs = last_resort_arcs(list(state.pieces), state.segments, state.fitted,
                                        config.fits.min_fit_px, config.top.arc_split_reach_px)
    grad = state.edges("top")
    faces = complete_faces(merged, [ev.support for ev in choice.evidence], arc_chains, arcs,
                           grad, (state.points, state.grads), state.crop, state.gate, config,
                           config.complete, config.limits.max_arcs)
    if not faces:
        return merged, choice
    merged = [*merged, *_as_merged(faces, state.chains, grad, config.merging)]
    return merged, _select([m.ellipse for m in merged], state, cues)


def _inner_refit(state: State, merged: list[MergedEllipse], choice: TopChoice,
                 config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """The chosen face refitted on its innermost consistent edge (:func:`~stackpick_sim.
    vision.contrast.refit_on_contrast`, reaching ``top.inner_refit_reach_px`` inward) when it
    passed the rule outright and the refit is clearly smaller (``top.inner_refit_max_area``),
    leaves out a sliver of a lower face (the fit reaching at least
    ``top.inner_refit_min_inset_px`` beyond it somewhere: not the face's own soft rim),
    plausible, within the size gate and passes the rule too: a top face over lower faces of
    its colour and shade, fitted round slivers of them on their strong silhouette (its own
    boundary with them a faint step inside the fit that the edge map misses, so no edge
    shows inside it). The choice then says so (``inner``: the pose's final fit keeps off the
    silhouette's edge pixels). Otherwise both unchanged."""
    assert choice.index is not None
    i = choice.index
    if choice.evidence[i].occluded:  # chosen with markings, or by a later check
        return merged, choice
    grad = state.edges("top")
    refit = inner_refit(merged[i].ellipse, grad, state.crop, state.gate, config.top,
                        config.fits)
    if refit is None:
        return merged, choice
    evidence = select_top([refit], grad, edge_points=state.points,
                          params=config.top).evidence[0]
    if evidence.occluded:
        return merged, choice
    return _inner_choice(merged, choice, i, refit, evidence)


def _inner_face(state: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """When every face reads as occluded (the rule and its fallbacks chose none) and
    ``inner_face.enabled``: the top rule again with each fit that can enclose a face replaced
    by its inner refit (:func:`~stackpick_sim.vision.inner_face.refitted`); a refit it
    chooses replaces its fit in ``merged`` and is chosen (``inner``: the pose's final fit
    keeps off the silhouette's edge pixels beyond it). Otherwise both unchanged."""
    if choice.index is not None or not config.inner_face.enabled:
        return merged, choice
    check_time(state.deadline, "top")
    ellipses = [m.ellipse for m in merged]
    refits = refitted(ellipses, choice.evidence, state.edges("top"), state.crop, state.gate,
                      config.top, config.fits)
    if not refits:
        return merged, choice
    again = _select([refits.get(i, e) for i, e in enumerate(ellipses)], state, cues)
    i = again.index
    if i is None or i not in refits:
        return merged, choice
    merged, choice = _inner_choice(merged, choice, i, refits[i], again.evidence[i])
    return merged, replace(choice, reason="")


def _whole_refit(state: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                 config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """With ``whole_refit.enabled``, when the choice (a fallback's) is none, or fails the rule
    itself and moves when refitted on its innermost consistent edge (not :func:`~stackpick_
    sim.vision.whole_refit.settled`, ``whole_refit.settled_iou``): the top rule over the
    refits of the fits that fail it which pass it outright (:func:`~stackpick_sim.vision.
    whole_refit.whole_refits`), unless the fallback's face is one of them (it shows whole);
    the refit it chooses replaces its fit in ``merged`` and is chosen (``inner``: the pose's
    final fit keeps to it). Otherwise both unchanged."""
    params, i = config.whole_refit, choice.index
    if not params.enabled or (i is not None and not choice.evidence[i].occluded):
        return merged, choice
    check_time(state.deadline, "top")
    grad = state.edges("top")
    if i is not None and settled(merged[i].ellipse, grad, params.reach_px, config.top,
                                 params.settled_iou):
        return merged, choice
    refits = whole_refits([m.ellipse for m in merged], choice.evidence, grad, state.points,
                          state.crop, state.gate, params.min_support, params.reach_px,
                          config.top, config.fits)
    if i in refits:  # the fallback's face shows whole so refitted: it keeps the choice
        return merged, choice
    keys = list(refits)
    again = _select([refits[k] for k in keys], state, cues)
    if again.index is None:
        return merged, choice
    j = keys[again.index]
    if (i is not None and cues.depth_radius_of is not None
            and below(refits[j], merged[i].ellipse, cues.k_crop, cues.depth_radius_of,
                      config.top)):
        return merged, choice
    merged, choice = _inner_choice(merged, choice, j, refits[j], again.evidence[again.index])
    return merged, replace(choice, reason="")


def _under_wall(merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                config: DetectorConfig) -> bool:
    """Whether, with ``under_wall.enabled``, the chosen face lies under the cylinder of
    another face that shows at least ``top.min_support`` of its outline
    (:func:`~stackpick_sim.vision.under_wall.under_a_wall`, ``under_wall.min_share``,
    ``top.cover_depth_tolerance_m``); never without a choice or the kinds' radii and
    heights."""
    if (not config.under_wall.enabled or choice.index is None or cues.depth_radius_of is None
            or cues.height_of is None):
        return False
    covering = [k for k, ev in enumerate(choice.evidence)
                if k != choice.index and ev.support >= config.top.min_support]
    return bool(covering) and under_a_wall(
        [m.ellipse for m in merged], choice.index, covering, cues.k_crop,
        cues.depth_radius_of, cues.height_of, config.under_wall.min_share,
        config.top.cover_depth_tolerance_m)


def _inner_choice(merged: list[MergedEllipse], choice: TopChoice, i: int, refit: Ellipse,
                  evidence: OcclusionEvidence) -> tuple[list[MergedEllipse], TopChoice]:
    """``merged`` with ellipse ``i`` replaced by its inner ``refit``, and ``choice`` choosing
    it with the refit's ``evidence`` (``inner``: the pose's final fit keeps off the
    silhouette's edge pixels beyond it)."""
    merged = [replace(m, ellipse=refit) if k == i else m for k, m in enumerate(merged)]
    return merged, replace(choice, index=i, inner=True,
                           evidence=(*choice.evidence[:i], evidence, *choice.evidence[i + 1:]))


def _rest_check(state: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                params: TopParams = DEFAULT_TOP) -> TopChoice:
    """``choice``, unless a whole lower face that the chosen top face rests on takes it (that
    face's fit taking in a same-colour sliver beyond it: :func:`~stackpick_sim.vision.
    occlusion.select_resting_rimmed`, with the contrast refit's ``params``); unchanged
    without the kinds' radii and heights or without colour."""
    if cues.radius_of is None or cues.height_of is None or cues.rgb is None:
        return choice
    above = select_resting_rimmed([m.ellipse for m in merged], choice, state.edges("top"),
                                  state.points, cues.k_crop, cues.radius_of, cues.height_of,
                                  cues.rgb, cues.belt, params, cues.pose)
    return choice if above is None else replace(choice, index=above)


def _lean_check(state: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                config: DetectorConfig) -> TopChoice:
    """``choice``, unless, with ``lean.enabled``, it passed the rule outright and a face with
    no T-junction, its outline short of the rule's support, rests on it (:func:`~stackpick_sim.
    vision.leaning.select_leaning`): that face takes it. Unchanged without a choice, the
    kinds' heights and colour, or their radii (from colour, else of two kinds or more)."""
    if (not config.lean.enabled or choice.index is None
            or choice.evidence[choice.index].occluded):
        return choice
    rests = _rest_test_of(cues, config)
    if rests is None:
        return choice
    above = select_leaning([m.ellipse for m in merged], choice.evidence, choice.index,
                           state.points, rests, config.lean)
    return choice if above is None else replace(choice, index=above)


def _rest_test_of(cues: Cues, config: DetectorConfig
                  ) -> Callable[[Sequence[Ellipse]], list[bool]] | None:
    """The top rule's rest test on a list of faces with the cues' radii, heights and colours
    (:func:`~stackpick_sim.vision.resting.rest_test`), or None without heights, colour or
    radii."""
    if cues.rgb is None or cues.height_of is None:
        return None
    return rest_test(cues.k_crop, cues.radius_of, cues.radii, cues.height_of, cues.rgb,
                     belt=cues.belt, params=config.top, pose_params=config.pose,
                     kinds_of=cues.kinds_of)


def pose_stage(state: State, config: DetectorConfig) -> State:
    """The detection: the reported ellipses (supported, each face once, in frame pixels:
    :func:`_distinct`), and the top face's final fit (sub-pixel, then on the unblurred
    edge profile) and pose (:func:`~stackpick_sim.vision.pose.estimate_pose`)."""
    choice = state.choice
    if choice is None:
        raise StageError("the pose stage needs the top rule's choice: no top stage ran "
                         "before it")
    merged = state.merged
    du, dv = state.roi.offset
    keep = _distinct([i for i, ev in enumerate(choice.evidence)
                      if ev.support >= config.report.min_support or i == choice.index],
                     [m.ellipse for m in merged], choice, config.report)
    ellipses = tuple(
        DetectedEllipse.of(_moved(merged[i].ellipse, du, dv), merged[i].segments,
                           merged[i].residual_px, merged[i].support, choice.evidence[i])
        for i in keep)
    chains = state.chains
    frame_chains = chains if du == dv == 0 else _shifted(chains, du, dv)
    if choice.index is None:
        return state.updated(detection=Detection(ellipses=ellipses, segments=frame_chains,
                                                 timings_ms=state.timings_ms,
                                                 reason=choice.reason))
    pose = _top_pose(state, merged[choice.index].ellipse, config, choice.inner)
    return state.updated(detection=Detection(ellipses=ellipses, segments=frame_chains,
                                             top=keep.index(choice.index), pose=pose,
                                             timings_ms=state.timings_ms,
                                             reason=choice.reason))


def _top_pose(state: State, ellipse: Ellipse, config: DetectorConfig, inner: bool = False
              ) -> Pose:
    """The pose of the top face ``ellipse`` (crop pixels) after its final fit: the sub-pixel
    refit on the edge pixels along it (not for an ``inner`` refit, whose faint outline the
    edge map misses: the silhouette's edge pixels beyond it would pull it back), then the
    refit on the gradient profile."""
    work, grad = state.work, state.edges("pose")
    top_ellipse = ellipse if inner else refine_subpixel(
        ellipse, grad, state.points, state.grads, state.crop, config.pose,
        config.refine.min_normal_cos, config.fits, config.refine.min_pixels)
    top_ellipse = _profile_refit(top_ellipse, work, grad, config.pose, config.fits)
    # The face's colour once, for its radius and the pose's wall test (the same pixels in the
    # crop and in the frame while the face's interior lies in the crop).
    face = face_colour(top_ellipse, work) if work.ndim == 3 else None
    colours = config.kind_colours
    radius = (None if colours is None or face is None
              else _nearest_kind(face, _chromaticities(colours), config.radii_m))
    du, dv = state.roi.offset
    img = state.image
    return estimate_pose(_moved(top_ellipse, du, dv), state.intrinsics,
                         config.radii_m if radius is None else (radius,), None,
                         config.depth_range_m, image=img if img.ndim == 3 else None,
                         face_rgb=face, belt=None if state.cues is None else state.cues.belt,
                         params=config.pose)


#: The built-in stages, in order (see the module docstring).
STAGES: tuple[Stage, ...] = (
    Stage("roi", roi_stage), Stage("edges", edges_stage), Stage("segments", segments_stage),
    Stage("fitting", fitting_stage), Stage("merging", merging_stage),
    Stage("refine", refine_stage), Stage("gate", gate_stage), Stage("top", top_stage),
    Stage("pose", pose_stage))


def _cues(state: State, config: DetectorConfig) -> Cues:
    """What the top rule reads besides the ellipses: the crop's intrinsics, colours, the
    belt's colour and the radius and height of each candidate's kind."""
    k_crop = _crop_intrinsics(state.intrinsics, state.roi.offset)
    work = state.work
    rgb = work if work.ndim == 3 else None
    # Each candidate's face colour once, for its radius and the rest test's wall bands.
    colour_of = None if rgb is None else face_colours(rgb)
    colours = config.kind_colours
    radius_of = (None if colours is None else
                 radius_by_colour(work, config.radii_m, colours, colour_of))
    kinds_of = None
    if (radius_of is None and config.top.kind_by_size and len(config.radii_m) > 1
            and config.depth_range_m is not None):
        # Kinds of one colour: the kinds a face's size admits.
        kinds_of = kinds_by_size(k_crop, config.radii_m, config.depth_range_m)
    markings = marking_test(config, work, state.edges("top"))
    return Cues(k_crop=k_crop, rgb=rgb,
                belt=None if state.roi.belt is None else np.array(state.roi.belt),
                colour_of=colour_of, radius_of=radius_of, height_of=config.height_of(),
                markings=markings, top=config.top, pose=config.pose, radii=config.radii_m,
                kinds_of=kinds_of,
                depth_radius_of=depth_radius(radius_of, kinds_of))


def _crop_intrinsics(k: CameraIntrinsics, offset: tuple[int, int]) -> CameraIntrinsics:
    """The intrinsics ``k`` of the crop whose top-left pixel is at ``offset`` (u, v) of the
    frame: the principal point moved by it, the image size and lens kept as ``k``'s (as
    ``CameraIntrinsics(fx=k.fx, fy=k.fy, cx=k.cx - du, cy=k.cy - dv, width=k.width,
    height=k.height)``, an equal object, without re-running the checks ``k`` passed: a
    finite principal point less whole pixels stays finite)."""
    du, dv = offset
    crop = object.__new__(CameraIntrinsics)
    fields = crop.__dict__
    fields["fx"], fields["fy"], fields["cx"], fields["cy"] = k.fx, k.fy, k.cx - du, k.cy - dv
    fields["width"], fields["height"] = k.width, k.height
    fields["dist"] = CameraIntrinsics.dist  # the default: the crop of the undistorted frame
    return crop


def _select(ellipses: list[Ellipse], found: State, cues: Cues) -> TopChoice:
    """The top rule (:func:`~stackpick_sim.vision.occlusion.select_top`) with every cue."""
    return select_top(ellipses, found.edges("top"), cues.k_crop, cues.radius_of,
                      edge_points=found.points, image=cues.rgb, height_of=cues.height_of,
                      colour_of=cues.colour_of, belt=cues.belt, markings=cues.markings,
                      params=cues.top, pose_params=cues.pose, kind_radii=cues.radii,
                      kinds_of=cues.kinds_of)


def _marked_arc_faces(state: State, merged: list[MergedEllipse], choice: TopChoice,
                      cues: Cues, config: DetectorConfig
                      ) -> tuple[list[MergedEllipse], TopChoice]:
    """When no ellipse passed the top rule outright (none did, or a face with markings was
    chosen, :mod:`~stackpick_sim.vision.markings`) and some ellipse holds markings across it
    (interior edges along ``marking_min_edge_share`` of its perimeter; on plain faces the
    fallbacks decide, at no extra cost): the top rule again over the ellipses and those of
    pairs of every arc (:func:`_arc_pair_faces`; the merge joins no arcs across a face's
    artwork or a can end's rings, so a printed or tinplate face is often fitted only on arc
    pairs). A face with markings it chooses takes the choice (an arc pair's ellipse is then
    added to ``merged``); otherwise both come back unchanged."""
    test = cues.markings
    if test.image is None or not any(ev.interior_edge_px >= test.min_edge_share
                                     * ev.perimeter_px for ev in choice.evidence):
        return merged, choice
    grad, extra, alone = _every_arc_face(state, config)
    # Only whole faces with markings across them can be chosen so (the rule's evidence of
    # each ellipse is its own: the union's is the same).
    extra = [e for e, ev in zip(extra, alone.evidence, strict=True)
             if whole_with_edges_inside(ev)
             and ev.interior_edge_px >= test.min_edge_share * ev.perimeter_px]
    if not extra:
        return merged, choice
    n = len(merged)
    both = _select([m.ellipse for m in merged] + extra, state, cues)
    if both.index is None or not both.evidence[both.index].occluded:
        return merged, choice
    mine = TopChoice(index=None, evidence=both.evidence[:n])
    if both.index < n:
        return merged, replace(mine, index=both.index)
    face = extra[both.index - n]
    if choice.index is not None and _refit_round(face, merged[choice.index].ellipse,
                                                 config.top.interior_margin_px,
                                                 config.markings.rim_sample_scale):
        return merged, choice
    return _with_face(merged, mine, face, both.evidence[both.index], state.chains, grad,
                      config.merging)


def _refit_round(face: Ellipse, chosen: Ellipse, margin_px: float, rim_scale: float) -> bool:
    """Whether an arc pairs' ``face`` is the ``chosen`` face of the merge fitted again (one
    holds the other's centre) round it and beyond, the chosen face reaching into its rim band
    (:func:`~stackpick_sim.vision.markings.inside_rim_band`; the fit taking in the wall's
    silhouette or a lower face's arc beyond it): then the merge's fit is kept. A chosen fit
    lying within the arc face's rim band (``margin_px``, the rule's interior margin) is a fit
    on an arc of that face's outline and its artwork, and gives way (``rim_scale``: the rim
    band's, ``markings.rim_sample_scale``)."""
    return ((holds_centre(face, chosen) or holds_centre(chosen, face))
            and not inside_rim_band(chosen, face, margin_px, rim_scale))


def _fallbacks(found: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
               config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """When no ellipse passed the top rule, in order, until one gives a face, those of the
    ``top.fallbacks`` named (:class:`~stackpick_sim.config.vision_params.TopParams`): the
    unobstructed face (unless a face cut short by nothing, :func:`_nearer_hidden`, a rimmed
    face, :func:`_nearer_rimmed`, or a face of arc pairs is clearly nearer) and the contrast
    retry (unless a face of arc pairs is clearly nearer than its choice), then
    :func:`_arc_fallbacks`, then :func:`_nearest_cut`."""
    use, limits = config.top.fallbacks, config.limits
    grad = found.edges("top")
    spare: tuple[int, Ellipse, OcclusionEvidence] | None = None
    # Before the contrast retry: a refit of a lower face can shrink past the outline
    # crossing it and pass.
    fallback = select_unobstructed(choice.evidence) if "unobstructed" in use else None
    if fallback is not None:
        choice = replace(choice, index=fallback, reason="")
        if config.top.nearer_hidden:
            choice = _nearer_hidden(merged, choice, cues, config.top)
        if config.top.nearer_rimmed:
            merged, choice = _nearer_rimmed(found, merged, choice, cues, config.top)
        return _nearer_arcs(found, merged, choice, cues, config)
    check_time(found.deadline, "top")
    retried = False
    if "contrast" in use:
        # Only then: a refit that passes next to a passing face is more often a lower,
        # nearly whole face than the top.
        merged, retried, spare = _retry_on_contrast(merged, choice.evidence, grad, found.crop,
                                                    found.gate, limits.max_refits,
                                                    config.report.min_support, config.top,
                                                    config.fits)
    if retried:
        choice = _select([m.ellipse for m in merged], found, cues)
    if retried and choice.index is not None:
        # A face clearly nearer than such a refit is above it (a top face the merge never
        # fitted beside a lower, nearly whole face of its colour).
        return _nearer_arcs(found, merged, choice, cues, config)
    merged, choice = _arc_fallbacks(found, merged, choice, spare, cues, config)
    if choice.index is None and "nearest_cut" in use:
        merged, choice = _nearest_cut(found, merged, choice, cues, config)
    return merged, choice


def _nearest_cut(found: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                 config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """The last fallback (``nearest_cut``): of the fitted faces and those of pairs of every
    arc (:func:`last_resort_arcs`) at least half visible (support at least
    ``top.hidden_min_support``, as the scoring counts faces), the one clearly nearer the
    camera than every other (:func:`~stackpick_sim.vision.occlusion.clearly_nearest`,
    ``top.depth_tie_m``), in its best-supported fit cut short by nothing (no T-junction, no
    edge inside; a fit that took in part of its wall reads nearer still): a top
    face across faces of its colour and shade, whose boundary with them shows no contrast
    along more of its outline than the ``unobstructed`` fallback allows, while no face that
    passes or fails on support alone was found. An arc pairs' face so chosen is added to
    ``merged``; otherwise both come back unchanged (and without face radii)."""
    if cues.depth_radius_of is None:
        return merged, choice
    grad, extra, alone = _every_arc_face(found, config)
    faces = [m.ellipse for m in merged] + extra
    evidence = (*choice.evidence, *alone.evidence)
    half = [i for i, ev in enumerate(evidence) if ev.support >= config.top.hidden_min_support]
    nearest = (clearly_nearest([faces[i] for i in half], cues.k_crop, cues.depth_radius_of,
                               config.top) if len(half) > 1 else None)
    if nearest is None:
        return merged, choice
    # The nearest face's fits (one holds the other's centre: no rivals of it) cut short by
    # nothing, the best-supported first.
    face = faces[half[nearest]]
    cut = [i for i in half if not evidence[i].occluded_ends and not evidence[i].interior_edge_px
           and (holds_centre(faces[i], face) or holds_centre(face, faces[i]))]
    if not cut:
        return merged, choice
    i = max(cut, key=lambda k: evidence[k].support)
    if i < len(merged):
        return merged, replace(choice, index=i, reason="")
    return _with_face(merged, choice, faces[i], evidence[i], found.chains, grad,
                      config.merging)


def _nearer_rimmed(found: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                   params: TopParams) -> tuple[list[MergedEllipse], TopChoice]:
    """``choice`` (the ``unobstructed`` fallback's), unless a whole face whose only interior
    edges are its own rim (:func:`~stackpick_sim.vision.occlusion.rim_only`: no T-junction,
    support at least ``params.min_support``), refitted on its innermost consistent edge
    (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`; the fit itself took in a
    same-colour lower face's sliver beyond it, so it reads too near), lies clearly nearer the
    camera than it (:func:`~stackpick_sim.vision.occlusion.clearly_nearest`): a top face over
    lower faces of its colour, which fails the rule on its own rim alone, above the face the
    fallback chose, whose occluder only clips its rim. Its refit replaces it in ``merged``
    and is chosen (``inner``: the pose's final fit keeps off the silhouette's edge pixels
    beyond it). Both unchanged without face radii."""
    assert choice.index is not None
    if cues.depth_radius_of is None:
        return merged, choice
    ellipses = [m.ellipse for m in merged]
    rimmed = rim_only(ellipses, choice.evidence, found.points)
    if not rimmed:
        return merged, choice
    grad = found.edges("top")
    refits = [refit_on_contrast(ellipses[i], grad, True, params) or ellipses[i]
              for i in rimmed]
    nearest = clearly_nearest([ellipses[choice.index], *refits], cues.k_crop,
                              cues.depth_radius_of,
                              params)
    if not nearest:
        return merged, choice
    i, refit = rimmed[nearest - 1], refits[nearest - 1]
    if refit is ellipses[i]:
        return merged, replace(choice, index=i)
    # The refit is the face (the pose's final fit keeps off the lower face's silhouette
    # beyond it, as for the inner refit).
    evidence = select_top([refit], grad, edge_points=found.points, params=params).evidence[0]
    return _inner_choice(merged, choice, i, refit, evidence)


def _nearer_refit(found: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                  params: TopParams) -> tuple[list[MergedEllipse], TopChoice]:
    """``choice`` (the ``rimmed`` fallback's), unless a face with edges inside and no
    T-junction (support at least ``params.hidden_min_support``), refitted on its innermost
    consistent edge (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`), shows whole
    as that refit (passes the rule, or fails it on its own rim alone: :func:`~stackpick_sim.
    vision.occlusion.rim_only`) and lies clearly nearer the camera than the choice
    (:func:`~stackpick_sim.vision.occlusion.clearly_nearest`): a top face fitted round part
    of its own wall, whose rim then lies deeper inside the fit than the rim band, above a
    lower whole face it leans on. The refit replaces it in ``merged`` and is chosen
    (``inner``). Both unchanged without face radii."""
    assert choice.index is not None
    if cues.depth_radius_of is None:
        return merged, choice
    ellipses = [m.ellipse for m in merged]
    failed = [i for i, ev in enumerate(choice.evidence)
              if i != choice.index and not ev.occluded_ends
              and ev.support >= params.hidden_min_support and ev.edges_inside]
    whole = _whole_refits(found, [(i, ellipses[i]) for i in failed], params)
    if not whole:
        return merged, choice
    nearest = clearly_nearest([ellipses[choice.index], *(r for _, r, _ in whole)],
                              cues.k_crop, cues.depth_radius_of, params)
    if not nearest:
        return merged, choice
    i, refit, evidence = whole[nearest - 1]
    return _inner_choice(merged, choice, i, refit, evidence)


def _whole_refits(found: State, faces: list[tuple[int, Ellipse]], params: TopParams
                  ) -> list[tuple[int, Ellipse, OcclusionEvidence]]:
    """(index, refit, its evidence) of those of the indexed ``faces`` whose refit on their
    innermost consistent edge shows whole: passes the top rule, or fails it on its own rim
    alone (:func:`~stackpick_sim.vision.occlusion.rim_only`)."""
    grad = found.edges("top")
    refits = [(i, refit) for i, face in faces
              if (refit := refit_on_contrast(face, grad, True, params)) is not None]
    if not refits:
        return []
    ellipses = [r for _, r in refits]
    judged = select_top(ellipses, grad, edge_points=found.points, params=params).evidence
    rimmed = set(rim_only(ellipses, judged, found.points))
    return [(i, r, ev) for k, ((i, r), ev) in enumerate(zip(refits, judged, strict=True))
            if not ev.occluded or k in rimmed]


def _nearer_hidden(merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                   params: TopParams) -> TopChoice:
    """``choice`` (the ``unobstructed`` fallback's), unless a face cut short by nothing (no
    T-junction, no edge inside, support at least ``params.hidden_min_support``: at least half
    visible, as :func:`~stackpick_sim.vision.occlusion.hidden_by_no_outline` counts it) lies
    clearly nearer the camera than it (:func:`~stackpick_sim.vision.occlusion.
    clearly_nearest`): a top face over faces of its colour and shade, whose boundary with
    them shows no contrast along more of its outline than the unobstructed test allows; the
    chosen face is then a lower one whose occluder only clips its rim. Unchanged without face
    radii."""
    assert choice.index is not None
    if cues.depth_radius_of is None:
        return choice
    chosen = merged[choice.index].ellipse
    # A second fit of the chosen face (one holds the other's centre) is no other face: the
    # better-supported fit the fallback chose stays, though the other may read nearer.
    cut = [i for i, ev in enumerate(choice.evidence)
           if i != choice.index and not ev.occluded_ends and not ev.interior_edge_px
           and ev.support >= params.hidden_min_support
           and not (holds_centre(merged[i].ellipse, chosen)
                    or holds_centre(chosen, merged[i].ellipse))]
    if not cut:
        return choice
    faces = [chosen, *(merged[i].ellipse for i in cut)]
    nearest = clearly_nearest(faces, cues.k_crop, cues.depth_radius_of, params)
    return choice if not nearest else replace(choice, index=cut[nearest - 1])


def _nearer_arcs(found: State, merged: list[MergedEllipse], choice: TopChoice, cues: Cues,
                 config: DetectorConfig, every_arc: bool = True
                 ) -> tuple[list[MergedEllipse], TopChoice]:
    """A face of arc pairs clearly nearer than ``choice`` (:func:`_nearer_arc_face`), else
    ``choice``; unchanged without face radii. The arcs: with ``every_arc`` (a fallback's
    choice; only with the ``nearer_arcs`` fallback) those of :func:`last_resort_arcs`, else
    the fitted pieces that lie on none of the faces the rule weighed (a choice that passed
    the rule; an unfitted face's arcs are on no fitted face: ~20x cheaper)."""
    if cues.depth_radius_of is None or (every_arc and "nearer_arcs" not in config.top.fallbacks):
        return merged, choice
    if every_arc:
        arc_chains, arcs = _every_arc(found, config)
    else:
        weighed = {k for i in _weighed(choice) for k in merged[i].segments}
        arc_chains = found.chains
        arcs = _longest_arcs([k for k in range(len(found.pieces)) if k not in weighed],
                             arc_chains, config.limits.max_arcs)
    return _nearer_arc_face(merged, choice, arcs, found.chains, arc_chains, found.edges("top"),
                            (found.points, found.grads), found.crop, found.gate, cues.k_crop,
                            cues.depth_radius_of, config)


def _arc_fallbacks(found: State, merged: list[MergedEllipse], choice: TopChoice,
                   spare: tuple[int, Ellipse, OcclusionEvidence] | None, cues: Cues,
                   config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """The fallbacks after the contrast retry, those of ``top.fallbacks`` named, until one
    gives a face: a face with its own rim inside (unless a refitted face is clearly nearer,
    :func:`_nearer_refit`), arc pairs of the fitted pieces, the retry's ``spare`` refit, arc
    pairs of every arc."""
    use, limits, grad = config.top.fallbacks, config.limits, found.edges("top")
    edge_pixels = (found.points, found.grads)
    if choice.index is None and "rimmed" in use:
        # A face whose fit took in a same-colour lower face's sliver (see
        # TopParams.rim_band_px).
        rimmed = select_rimmed([m.ellipse for m in merged], choice.evidence, found.points)
        if rimmed is not None:
            choice = replace(choice, index=rimmed, reason="")
            if config.top.nearer_refit:
                merged, choice = _nearer_refit(found, merged, choice, cues, config.top)
            return merged, choice
    if choice.index is None and "arc_pairs" in use:
        # A face the merge never fitted, from pairs of its arcs (see regroup).
        check_time(found.deadline, "top")
        merged, choice = _regroup_arcs(
            merged, choice, _longest_arcs(range(len(found.pieces)), found.chains,
                                          limits.max_arcs),
            found.chains, grad, edge_pixels, found.crop, found.gate, config)
    if choice.index is None and spare is not None and "spare_refit" in use:
        # A contrast refit with no T-junction and no edge inside, most of its outline
        # showing (select_unobstructed's evidence: a top face over a lower face of its
        # colour, fitted with part of that one's outline, refits onto its own faint
        # boundary).
        i, refit, refit_evidence = spare
        merged[i] = replace(merged[i], ellipse=refit)
        return merged, TopChoice(index=i, evidence=(*choice.evidence[:i], refit_evidence,
                                                    *choice.evidence[i + 1:]))
    if choice.index is None and "all_arcs" in use:
        # After all: pairs that take in the chains no fit was kept for and the parts of
        # chains cut at junctions too (see regroup), else the one with nothing crossing
        # it (its boundary with a lower face of its colour shows no contrast), else one
        # with its own rim inside. Last, as the least constrained.
        check_time(found.deadline, "top")
        arc_chains, arcs = _every_arc(found, config)
        merged, choice = _regroup_arcs(merged, choice, arcs, found.chains, grad,
                                       edge_pixels, found.crop, found.gate, unobstructed=True,
                                       arc_chains=arc_chains, config=config)
    return merged, choice


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


def _every_arc_face(state: State, config: DetectorConfig
                    ) -> tuple[EdgeImage, list[Ellipse], TopChoice]:
    """The top stage's edge image, the faces of pairs of every arc
    (:func:`_every_arc`, :func:`_arc_pair_faces`) and the top rule's evidence of them alone;
    OutOfTime past the stage's deadline."""
    check_time(state.deadline, "top")
    grad = state.edges("top")
    arc_chains, arcs = _every_arc(state, config)
    extra, alone = _arc_pair_faces(arcs, arc_chains, grad, state.points, state.grads,
                                   state.crop, state.gate, config)
    return grad, extra, alone


def _every_arc(state: State, config: DetectorConfig
               ) -> tuple[tuple[NDArray[np.int32], ...], list[int]]:
    """The chains of :func:`last_resort_arcs` (the fitted pieces, then the edge chains cut at
    their junctions) and the ``limits.max_arcs`` longest of their arcs: what the marked
    arc-pair faces, the nearer arc-pair face and the last fallback draw pairs from."""
    arc_chains, arcs = last_resort_arcs(list(state.pieces), state.segments, state.fitted,
                                        config.fits.min_fit_px, config.top.arc_split_reach_px)
    return arc_chains, _longest_arcs(arcs, arc_chains, config.limits.max_arcs)


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


def object_kinds(kinds: Sequence[tuple[float, tuple[float, float, float], float]],
                 min_chroma_distance: float = DEFAULT_TOP.kind_min_chroma_distance
                 ) -> tuple[tuple[float, ...], tuple[tuple[float, float, float], ...] | None,
                            tuple[float, ...] | None]:
    """``radii_m``, ``kind_colours`` and ``heights_m`` for a DetectorConfig from a scene's
    object kinds, (radius m, RGB 0-1, height m) triples: each radius once, largest first, with
    its colour and height. The colours are None when the kinds cannot be told apart by colour
    (one radius in two colours, or two radii in colours within ``min_chroma_distance``,
    :attr:`TopParams.kind_min_chroma_distance`); the
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
    if float(apart.min(initial=np.inf)) < min_chroma_distance:
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
                                      face_colours(rgb, config.markings.rim_sample_scale)))
    return MarkingTest(radii=config.radii_m, rim_radius_of=rim_radius_of,
                       depth_ratio=config.marking_depth_ratio,
                       min_edge_share=config.marking_min_edge_share,
                       margin_px=config.top.interior_margin_px, image=rgb, gradients=grad,
                       params=config.markings)


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


def _chromaticities(colours: Sequence[Sequence[float]]) -> tuple[tuple[float, float, float], ...]:
    """(r, g, b) / (r + g + b) of each RGB colour (0-1); the kinds' colours (read three times
    a frame) once."""
    try:
        return _cached_chromaticities(colours)
    except TypeError:  # colours given as lists: unhashable
        return _cached_chromaticities.__wrapped__(colours)


@functools.lru_cache(maxsize=16)
def _cached_chromaticities(colours: Sequence[Sequence[float]]
                           ) -> tuple[tuple[float, float, float], ...]:
    """:func:`_chromaticities` (cached by the colours)."""
    out = []
    for r, g, b in colours:
        total = max(float(r) + float(g) + float(b), 1e-9)
        out.append((float(r) / total, float(g) / total, float(b) / total))
    return tuple(out)


def _nearest_kind(face: NDArray[np.float64], chroma: Sequence[tuple[float, float, float]],
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
                       gate: tuple[float, float] | None = None, max_refits: int = 8,
                       min_support: float = DEFAULT_REPORT.min_support,
                       params: TopParams = DEFAULT_TOP, fits_params: FitParams = DEFAULT_FITS
                       ) -> tuple[list[MergedEllipse], bool,
                                  tuple[int, Ellipse, OcclusionEvidence] | None]:
    """Refit on the edge contrast (:func:`~stackpick_sim.vision.contrast.refit_on_contrast`)
    each ellipse that failed the top rule on support or interior edges only (no T-junction,
    support at least ``min_support``), on the strongest and else on the innermost
    consistent edge (at most ``max_refits`` ellipses, the best-supported: each refit reads
    profiles along its whole outline); keep a refit where it passes the rule. Returns the
    ellipses, whether any changed, and, when none passed, the refit
    :func:`~stackpick_sim.vision.occlusion.select_unobstructed` takes among those within the
    size ``gate`` ((min, max) semi-major axis, px, or None) as (index of the ellipse it
    refits, refit, its evidence), else None. ``params``: the refit's reach, rounds and least
    share (the ``contrast_*`` fields) and the rule's settings; ``fits_params``: the refits'
    axis bounds."""
    todo = [i for i, ev in enumerate(evidence)
            if ev.occluded and not ev.occluded_ends and ev.support >= min_support]
    if len(todo) > max_refits:  # the best-supported, in their order
        best = sorted(todo, key=lambda i: (-evidence[i].support, i))[:max_refits]
        todo = sorted(best)
    # Refits outside the size gate are no faces, as fits are not (a refit onto an inner
    # contour can shrink to a sliver's arc).
    tries = [(i, r) for innermost in (False, True) for i in todo
             if (r := refit_on_contrast(merged[i].ellipse, grad, innermost, params)) is not None
             and plausible(r, shape, fits_params) and within_gate(r, gate)]
    if not tries:
        return merged, False, None
    checked = select_top([r for _, r in tries], grad, params=params).evidence
    passed: dict[int, Ellipse] = {}
    for (i, r), ev in zip(tries, checked, strict=True):
        if not ev.occluded and i not in passed:  # the strongest-edge refit first
            passed[i] = r
    if not passed:
        spare = select_unobstructed(checked)
        return merged, False, (None if spare is None else
                               (tries[spare][0], tries[spare][1], checked[spare]))
    return [replace(m, ellipse=passed[i]) if i in passed else m
            for i, m in enumerate(merged)], True, None


def last_resort_arcs(pieces: list[NDArray[np.int32]], chains: Sequence[NDArray[np.int32]],
                     fitted: set[int], min_arc_px: int = DEFAULT_FITS.min_fit_px,
                     split_reach_px: float = DEFAULT_TOP.arc_split_reach_px
                     ) -> tuple[tuple[NDArray[np.int32], ...], list[int]]:
    """The chains the last arc pairs are drawn from, and which of them are arcs (indices):
    the fitted ``pieces``, then the edge ``chains`` ((N_i, 2) pixels) cut at their junctions
    (:func:`~stackpick_sim.vision.regroup.split_at_junctions`, within ``split_reach_px``).
    Arcs are the pieces and the
    parts at least ``min_arc_px`` long of the chains that were cut or that are not in ``fitted``
    (the chains some piece of which was fitted)."""
    out = list(pieces)
    arcs = list(range(len(pieces)))
    for k, parts in enumerate(split_at_junctions(chains, split_reach_px)):
        for part in parts:
            if part.shape[0] >= min_arc_px and (len(parts) > 1 or k not in fitted):
                arcs.append(len(out))
            out.append(part)
    return tuple(out), arcs


def _regroup_arcs(merged: list[MergedEllipse], choice: TopChoice,
                  arcs: Sequence[int], chains: tuple[NDArray[np.int32], ...],
                  grad: EdgeImage, edge_pixels: tuple[NDArray[np.float64], NDArray[np.float64]],
                  shape: tuple[int, int], gate: tuple[float, float] | None,
                  config: DetectorConfig, unobstructed: bool = False,
                  arc_chains: tuple[NDArray[np.int32], ...] | None = None
                  ) -> tuple[list[MergedEllipse], TopChoice]:
    """When no ellipse passed the top rule: the ellipses of pairs of the ``arcs``
    (:func:`_arc_pair_faces`) through the top rule alone (no rival that already failed it can
    win), and with ``unobstructed``, when none passes, through its last resorts
    (:func:`~stackpick_sim.vision.occlusion.select_unobstructed`, then :func:`~stackpick_sim.
    vision.occlusion.select_rimmed`). Only one chosen so is added (with its evidence) to
    ``merged``; otherwise both come back unchanged. ``config``: the detector's settings."""
    found, extra = _arc_pair_faces(arcs, chains if arc_chains is None else arc_chains, grad,
                                   edge_pixels[0], edge_pixels[1], shape, gate, config)
    if not found:
        return merged, choice
    if extra.index is None and unobstructed:
        extra = replace(extra, index=select_unobstructed(extra.evidence))
    if extra.index is None and unobstructed:
        extra = replace(extra, index=select_rimmed(found, extra.evidence, edge_pixels[0]))
    if extra.index is None:
        return merged, choice
    return _with_face(merged, choice, found[extra.index], extra.evidence[extra.index], chains,
                      grad, config.merging)


def _arc_pair_faces(arcs: Sequence[int], arc_chains: tuple[NDArray[np.int32], ...],
                    grad: EdgeImage, points: NDArray[np.float64], grads: NDArray[np.float64],
                    shape: tuple[int, int], gate: tuple[float, float] | None,
                    config: DetectorConfig) -> tuple[list[Ellipse], TopChoice]:
    """The ellipses of pairs of the ``arcs`` (indices into ``arc_chains``;
    :func:`~stackpick_sim.vision.regroup.arc_pair_ellipses`), refined on the edge map (its
    pixels ``points`` and their gradients ``grads``) like the merged ones and within the size
    ``gate``, and the top rule's choice among them alone (no intrinsics: the depth, wall and
    rest tests need rivals; ``config``: the settings of the fits, refits and rule)."""
    found = arc_pair_ellipses(arc_chains, arcs, shape, gate, config)
    if found:
        found = [e for e in refine_all(found, points, grads, shape, fits_params=config.fits)
                 if within_gate(e, gate)]
    if not found:
        return [], TopChoice(index=None, evidence=())
    return found, select_top(found, grad, edge_points=points, params=config.top)


def _with_face(merged: list[MergedEllipse], choice: TopChoice, ellipse: Ellipse,
               evidence: OcclusionEvidence, chains: tuple[NDArray[np.int32], ...],
               grad: EdgeImage, params: MergeParams) -> tuple[list[MergedEllipse], TopChoice]:
    """``merged`` with ``ellipse`` added (:func:`_as_merged`), and the choice of it,
    ``evidence`` added to ``choice``'s."""
    merged = [*merged, *_as_merged([ellipse], chains, grad, params)]
    return merged, TopChoice(index=len(merged) - 1, evidence=(*choice.evidence, evidence))


def _as_merged(faces: list[Ellipse], chains: tuple[NDArray[np.int32], ...], grad: EdgeImage,
               params: MergeParams) -> list[MergedEllipse]:
    """Each of ``faces`` (ellipses fitted outside the merge) as a merged ellipse: its
    support, the ``chains`` on it by the merge's ``params`` and their residual."""
    support = support_shares(faces, support_map(grad.edges)).tolist()
    table = chain_table(chains)
    out = []
    for face, share in zip(faces, support, strict=True):
        on = chains_on(face, *table, params)
        residual = rms_residual(face, np.concatenate([chains[k] for k in on])) if on else 0.0
        out.append(MergedEllipse.of(face, on, residual, float(share)))
    return out


def _nearer_arc_face(merged: list[MergedEllipse], choice: TopChoice, arcs: Sequence[int],
                     chains: tuple[NDArray[np.int32], ...],
                     arc_chains: tuple[NDArray[np.int32], ...], grad: EdgeImage,
                     edge_pixels: tuple[NDArray[np.float64], NDArray[np.float64]],
                     shape: tuple[int, int], gate: tuple[float, float] | None,
                     intrinsics: CameraIntrinsics, radius_of: Callable[[Ellipse], float | None],
                     config: DetectorConfig) -> tuple[list[MergedEllipse], TopChoice]:
    """``choice`` (an index) unchanged, unless an ellipse of pairs of the ``arcs`` that passes
    the top rule (:func:`_arc_pair_faces`), or fails it on support alone with nothing crossing
    it (:func:`~stackpick_sim.vision.occlusion.unobstructed`: the rule's depth test hears
    those too), and is another face than the chosen one and those the depth test heard
    (neither holds the other's centre: a refit of a face already weighed, too large a refit
    reading too near) is clearly nearer the camera than the chosen one and every other such
    (:func:`~stackpick_sim.vision.occlusion.clearly_nearest`): then it is added to ``merged``
    and chosen. ``config``: the detector's settings."""
    assert choice.index is not None
    chosen = merged[choice.index].ellipse
    weighed = [merged[i].ellipse for i in _weighed(choice)]
    found, extra = _arc_pair_faces(arcs, arc_chains, grad, edge_pixels[0], edge_pixels[1],
                                   shape, gate, config)
    passed = [i for i, ev in enumerate(extra.evidence) if (not ev.occluded or unobstructed(ev))
              and not any(holds_centre(w, found[i]) or holds_centre(found[i], w)
                          for w in weighed)]
    if not passed:
        return merged, choice
    faces = [chosen, *(found[i] for i in passed)]
    nearest = clearly_nearest(faces, intrinsics, radius_of, config.top)
    if nearest is None or nearest == 0:  # no face clearly nearest, or the chosen one is
        return merged, choice
    i = passed[nearest - 1]
    return _with_face(merged, choice, found[i], extra.evidence[i], chains, grad, config.merging)


def _weighed(choice: TopChoice) -> list[int]:
    """The chosen index (first), then the other ellipses the top rule's depth test heard: those
    that passed, or failed on support alone with nothing crossing them."""
    assert choice.index is not None
    return [choice.index, *(i for i, ev in enumerate(choice.evidence)
                            if i != choice.index and (not ev.occluded or unobstructed(ev)))]


def _distinct(indices: list[int], ellipses: list[Ellipse], choice: TopChoice,
              params: ReportParams = DEFAULT_REPORT) -> list[int]:
    """``indices`` without duplicates, in their order: an ellipse whose outline lies within
    ``duplicate_tolerance_px`` of an ellipse already kept, along at least ``duplicate_share``
    of it (``params``)
    (and the other way round), is the same face fitted twice (two arcs the merge kept apart
    refine to one outline). The top face is kept first, then the better supported. Refits of
    the top face on other outlines too (:func:`_top_misfits`) and far rims of better-supported
    faces (:func:`_far_rim`) are dropped too."""
    order = sorted(indices, key=lambda i: (i != choice.index, -choice.evidence[i].support))
    same = _same_outlines(ellipses, order, params)
    misfits = _top_misfits(ellipses, order, choice.index, params)
    kept: list[int] = []
    for i in order:
        if i not in misfits and not any((i, j) in same for j in kept):
            kept.append(i)
    # Far rims: only of better-supported faces, never the top.
    return sorted(i for i in kept if i == choice.index or not any(
        choice.evidence[j].support > choice.evidence[i].support
        and _far_rim(ellipses[i], ellipses[j], params) for j in kept if j != i))


def _top_misfits(ellipses: list[Ellipse], indices: list[int], top: int | None,
                 params: ReportParams = DEFAULT_REPORT) -> set[int]:
    """Those of ``indices`` (other than ``top``) whose outline lies within
    ``duplicate_tolerance_px`` of the top ellipse's along at least ``misfit_share`` of it
    (``params``, see ReportParams.misfit_share), all in one array pass; empty without a
    top. Only ellipses whose centre lies within the top's semi-major axis of its centre are
    compared (the cost is in the array pass): a refit of the top on half its own outline
    keeps its centre near the top's."""
    if top is None:
        return set()
    face = ellipses[top]
    others = [i for i in indices if i != top
              and math.hypot(ellipses[i].cx - face.cx, ellipses[i].cy - face.cy) < face.a]
    if not others:
        return set()
    shares = boundary_shares([(ellipses[i], ellipses[top]) for i in others],
                             params.duplicate_tolerance_px)
    return {i for i, share in zip(others, shares, strict=True) if share >= params.misfit_share}


def _far_rim(rim: Ellipse, face: Ellipse, params: ReportParams = DEFAULT_REPORT) -> bool:
    """Whether ``rim`` is the far rim of the cylinder whose face is ``face``: the same size
    (within ``rim_size_tolerance``), shifted along the face's minor axis (the projected
    cylinder axis, within ``rim_angle_deg``) by ``rim_offset_range`` of its semi-major axis
    (``params``)."""
    tolerance = params.rim_size_tolerance
    if abs(rim.a - face.a) > tolerance * face.a or abs(rim.b - face.b) > tolerance * face.b:
        return False
    du, dv = rim.cx - face.cx, rim.cy - face.cy
    offset = math.hypot(du, dv)
    lo, hi = params.rim_offset_range
    if not lo * face.a <= offset <= hi * face.a:
        return False
    minor = math.radians(face.angle_deg + 90.0)
    along = abs(du * math.cos(minor) + dv * math.sin(minor)) / offset
    return along >= math.cos(math.radians(params.rim_angle_deg))


def _same_outlines(ellipses: list[Ellipse], indices: list[int],
                   params: ReportParams = DEFAULT_REPORT) -> set[tuple[int, int]]:
    """The pairs (i, j), both ways, of ``indices`` whose ellipses have the same outline (see
    :func:`_distinct`): centres within the larger semi-minor axis and within
    ``duplicate_near_px``, semi-axes within ``duplicate_near_px``, and each outline within
    ``duplicate_tolerance_px`` of the other along ``duplicate_share`` of it (``params``), every
    pair's two shares computed in one array pass."""
    near, share = params.duplicate_near_px, params.duplicate_share
    pairs = []
    for k, i in enumerate(indices):
        one = ellipses[i]
        for j in indices[k + 1:]:
            other = ellipses[j]
            gap = math.hypot(one.cx - other.cx, one.cy - other.cy)
            if (gap <= max(one.b, other.b) and gap <= near
                    and abs(one.a - other.a) <= near and abs(one.b - other.b) <= near):
                pairs.append((i, j))
    if not pairs:
        return set()
    shares = boundary_shares([w for i, j in pairs for w in ((ellipses[i], ellipses[j]),
                                                              (ellipses[j], ellipses[i]))],
                             params.duplicate_tolerance_px)
    same: set[tuple[int, int]] = set()
    for k, (i, j) in enumerate(pairs):
        if shares[2 * k] >= share and shares[2 * k + 1] >= share:
            same.update(((i, j), (j, i)))
    return same


def _profile_refit(ellipse: Ellipse, work: NDArray[np.uint8], grad: EdgeImage,
                   params: PoseParams, fits_params: FitParams) -> Ellipse:
    """:func:`~stackpick_sim.vision.refine.refine_on_profile` of ``ellipse`` on the unblurred
    gradients of the window of ``work`` around it (the window keeps the cost per face),
    ``params.profile_window_margin_px`` beyond the profile search (fits within
    ``fits_params``' axis bounds)."""
    u0, v0, u1, v1 = ellipse.bounds()
    margin = params.profile_reach_px + params.profile_window_margin_px
    h, w = work.shape[:2]
    c0, r0 = max(0, math.floor(u0 - margin)), max(0, math.floor(v0 - margin))
    c1, r1 = min(w, math.ceil(u1 + margin) + 1), min(h, math.ceil(v1 + margin) + 1)
    if min(c1 - c0, r1 - r0) < MIN_SIDE_PX:
        return ellipse
    window = np.ascontiguousarray(work[r0:r1, c0:c1])
    box = EdgeImage(edges=grad.edges[r0:r1, c0:c1], gx=grad.gx, gy=grad.gy, noise=grad.noise,
                    params=grad.params)
    raw = unblurred_gradients(window, box)
    fit = refine_on_profile(_moved(ellipse, -c0, -r0), raw, (r1 - r0, c1 - c0), params,
                            fits_params)
    return _moved(fit, c0, r0)


def _shifted(chains: tuple[NDArray[np.int32], ...], du: int, dv: int
             ) -> tuple[NDArray[np.int32], ...]:
    """Each (N_i, 2) chain plus (du, dv), in one compiled pass (views of one array)."""
    if not chains:
        return chains
    every = np.concatenate(chains)
    kernels_refine.shift_rows(every, du, dv)
    bounds = list(itertools.accumulate(map(len, chains), initial=0))
    return tuple(map(every.__getitem__, map(slice, bounds[:-1], bounds[1:])))


def _moved(ellipse: Ellipse, du: float, dv: float) -> Ellipse:
    """``ellipse`` shifted by (du, dv) px (from ROI to frame coordinates)."""
    if du == dv == 0:
        return ellipse
    # Built directly: dataclasses.replace costs several times the constructor.
    return Ellipse.of(ellipse.cx + du, ellipse.cy + dv, ellipse.a, ellipse.b, ellipse.angle_deg)


def detect(image: NDArray, config: DetectorConfig | None = None) -> Detection:
    """Detect the top object and its pose in ``image`` ((H, W) or (H, W, 3) RGB)."""
    return TopObjectDetector(config).detect(image)

"""The detector's tuned settings, one frozen section per stage.

Each section is a table of the scene's ``[vision]`` table (``[vision.report]``, keys
``vision.report.min_support`` and so on), so ``--set vision.SECTION.KEY=VALUE`` and
``stackpick sweep --param vision.SECTION.KEY=...`` reach every field, and a field of
:class:`~stackpick_sim.vision.detector.DetectorConfig` of the same name. Every field states
its unit and why its default is what it is; its allowed range is in the section's
``RANGES`` (checked on construction: one ConfigError naming the dotted key). The sections
are plain data with no dependency on the vision code, so that loading a scene does not load
the pipeline (:mod:`stackpick_sim.vision.params` is their home for users of the detector).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

from stackpick_sim.exceptions import ConfigError

#: The detector's stages that may be skipped (the others are required): without ``roi`` the
#: whole frame is searched, without ``refine`` the merged fits go on unrefined, without
#: ``gate`` no size gate applies.
SKIPPABLE_STAGES: tuple[str, ...] = ("roi", "refine", "gate")
#: The top rule's fallbacks, in the order they are tried when no ellipse passes the rule
#: (each is described by the failure class it handles in :class:`TopParams`).
FALLBACKS: tuple[str, ...] = ("unobstructed", "contrast", "nearer_arcs", "rimmed",
                              "arc_pairs", "spare_refit", "all_arcs", "nearest_cut")


@dataclass(frozen=True, kw_only=True)
class Section:
    """A section of settings: ``SECTION`` is its key under ``PREFIX`` (``vision``: the
    detector's); ``RANGES`` maps a field to its allowed (min, max, unit), checked for a
    number and for every number of a list."""

    PREFIX: ClassVar[str] = "vision"
    SECTION: ClassVar[str] = ""
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {}

    def __post_init__(self) -> None:
        for name, (lo, hi, unit) in self.RANGES.items():
            value = getattr(self, name)
            numbers = value if isinstance(value, tuple) else (value,)
            if not all(_number_within(v, lo, hi) for v in numbers):
                raise ConfigError(f"{self.PREFIX}.{self.SECTION}.{name} = {_shown(value)} is "
                                  f"out of range; allowed: {_allowed(lo, hi, unit)}"
                                  + (" each" if isinstance(value, tuple) else ""))


def _number_within(value: Any, lo: float, hi: float) -> bool:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return math.isfinite(value) and lo <= value <= hi


def _shown(value: Any) -> str:
    return repr(list(value)) if isinstance(value, tuple) else repr(value)


def _allowed(lo: float, hi: float, unit: str) -> str:
    return f"{lo:g} to {hi:g} {unit}".rstrip()


def _ordered(section: Section, name: str) -> None:
    """ConfigError unless the (low, high) pair ``name`` of ``section`` has low <= high."""
    lo, hi = getattr(section, name)
    if lo > hi:
        raise ConfigError(f"{section.PREFIX}.{section.SECTION}.{name} = {[lo, hi]!r} must be "
                          "[low, high] with low <= high")


@dataclass(frozen=True, kw_only=True)
class RoiParams(Section):
    """``roi`` stage: the box around everything that is not bare belt
    (:mod:`~stackpick_sim.vision.roi`)."""

    SECTION: ClassVar[str] = "roi"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "decimation": (1, 16, "(a power of two)"), "foreground_delta": (1.0, 128.0, "grey levels"),
        "margin_px": (0, 100, "px"), "belt_mode_window": (1, 64, "grey levels"),
        "belt_colour_levels": (0, 32, "grey levels")}

    decimation: int = 4
    """Side ratio of the small copy the box is found on, a power of two reached in halving
    steps: area averaging keeps thin walls, and a quarter-size copy costs a sixteenth."""
    foreground_delta: float = 14.0
    """Grey levels between a foreground pixel's brightest channel and the belt's: the belt
    varies by ~15 levels across the frame under the ring light (26-41 measured), the darkest
    object walls lie ~20 levels above it at their brightest channel."""
    margin_px: int = 10
    """Margin added around the box, px: covers the decimation's rounding, the edge stage's
    5x5 blur and 3x3 Sobel footprint, and a dark wall rim the threshold misses."""
    belt_mode_window: int = 9
    """Grey levels the histogram of brightest-channel levels is smoothed over before its mode
    (the belt's level) is taken: the belt spreads over ~15 levels, a face over a few."""
    belt_colour_levels: int = 2
    """Pixels within this many grey levels of the belt's level give the belt's colour (read
    by the side-wall tests to tell a grey object's wall from bare belt)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.decimation & (self.decimation - 1):
            raise ConfigError(f"vision.roi.decimation = {self.decimation!r} is out of range; "
                              "allowed: a power of two from 1 to 16")


@dataclass(frozen=True, kw_only=True)
class EdgeParams(Section):
    """``edges`` stage: one-pixel-wide edges with thresholds that adapt to the image
    (:mod:`~stackpick_sim.vision.edges`)."""

    SECTION: ClassVar[str] = "edges"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "blur_sigma_px": (0.3, 5.0, "px"), "noise_multiple": (0.0, 100.0, ""),
        "contrast_fraction": (0.0, 1.0, ""), "min_high_threshold": (0.0, 255.0, "grey levels/px"),
        "low_ratio": (0.05, 1.0, ""), "support_noise_multiple": (0.0, 100.0, ""),
        "support_min_contrast": (0.0, 255.0, "grey levels/px")}

    blur_sigma_px: float = 1.0
    """Gaussian smoothing sigma, px (the kernel covers +-2 sigma): suppresses pixel noise of a
    few grey levels while keeping the edges of 15 px ellipses separate."""
    noise_multiple: float = 6.0
    """The high Canny threshold is at least this multiple (ratio) of the median gradient
    magnitude, the noise level: Gaussian noise gives a Rayleigh magnitude whose 99.99th
    percentile is ~3.6 times its median; 6 keeps noise edges out with margin."""
    contrast_fraction: float = 0.04
    """The high threshold is at least this fraction [0, 1] of the 99th-percentile gradient
    magnitude (real edges' contrast): keeps smooth shading ramps, whose magnitude is small
    next to object boundaries, out."""
    min_high_threshold: float = 2.0
    """Floor of the high threshold, grey levels/px (an empty or nearly flat image)."""
    low_ratio: float = 0.4
    """Low hysteresis threshold as a ratio of the high one (Canny's recommended 1:2 to
    1:3)."""
    support_noise_multiple: float = 2.0
    """An outline sample shows consistent edge contrast (the support the top rule, the
    reported ellipses' check and the refits read) when its windowed contrast across the
    outline reaches this multiple (ratio) of the noise level (the median gradient
    magnitude): the window's averaging lowers the noise ~2.2 times, so 2 keeps noise out
    while faint boundaries between faces of one colour still count."""
    support_min_contrast: float = 0.5
    """...and at least this contrast, grey levels/px: a noiseless image's noise level is
    zero, and a flat face's rendering dither must not count as an edge."""


@dataclass(frozen=True, kw_only=True)
class SegmentParams(Section):
    """``segments`` stage: edge pixels linked into ordered chains, cut at junctions, corners
    and flips of the turning direction (:func:`~stackpick_sim.vision.segments.
    link_segments`)."""

    SECTION: ClassVar[str] = "segments"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_chain_px": (2, 1000, "px"), "poly_epsilon_px": (0.1, 10.0, "px"),
        "corner_angle_deg": (1.0, 180.0, "deg"), "spike_min_deg": (0.0, 180.0, "deg"),
        "spike_ratio": (1.0, 100.0, ""), "min_signed_turn_deg": (0.0, 90.0, "deg")}

    min_chain_px: int = 6
    """Chains shorter than this (px) are dropped: too short to constrain an ellipse."""
    poly_epsilon_px: float = 1.0
    """Tolerance (px) of the polygonal approximation whose vertices are read for turns: 1 px
    keeps pixel staircases out of the polygon."""
    corner_angle_deg: float = 80.0
    """Turn (deg) at one polygon vertex above which it is a corner. With a 1 px tolerance a
    vertex on an arc of curvature radius R turns by sqrt(8 / R) rad; the sharpest face end
    expected (a = 15 px, b = 10 px, R = b^2 / a = 6.7 px) gives ~63 deg, so 80 deg keeps
    every ellipse arc whole while a side wall meeting a face's arc is cut."""
    spike_min_deg: float = 30.0
    """A vertex turning by more than this (deg) and ``spike_ratio`` times either neighbour is
    a corner too: along an ellipse arc consecutive vertices turn alike, so a lone sharp turn
    is where one outline meets another (a T-junction Canny bridged without a junction
    pixel)."""
    spike_ratio: float = 2.0
    """Ratio of a spike vertex's turn to either neighbour's (see ``spike_min_deg``)."""
    min_signed_turn_deg: float = 4.0
    """Polygon vertices turning by less than this (deg) carry no reliable turning sign (a
    1 px staircase on a straight run), so they neither cut a chain nor set the sign a later
    vertex is compared with."""


@dataclass(frozen=True, kw_only=True)
class FitParams(Section):
    """``fitting`` stage: an ellipse-specific least-squares fit of every edge chain, a chain
    whose fit fails split in halves and retried (:func:`~stackpick_sim.vision.fitting.
    fit_all`)."""

    SECTION: ClassVar[str] = "fits"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_fit_px": (5, 1000, "px"), "min_bow_px": (0.0, 10.0, "px"),
        "max_residual_px": (0.05, 5.0, "px"), "min_axis_px": (1.0, 1000.0, "px"),
        "max_axis_diagonals": (0.05, 10.0, "diagonals")}

    min_fit_px: int = 10
    """Chains shorter than this (px) are not fitted: a few pixels of arc do not fix an
    ellipse's 5 parameters. The top rule's last-resort arc pairs take arcs this long too."""
    min_bow_px: float = 0.6
    """A chain whose pixels spread less than this (px, RMS across its principal line) is
    straight: a side-wall line or a chord too flat to tell an ellipse from a line."""
    max_residual_px: float = 0.6
    """Largest RMS Sampson residual (px) of an accepted segment fit: anti-aliased synthetic
    and rendered edges fit to ~0.2-0.3 px; 0.6 px rejects arcs that mix two curves."""
    min_axis_px: float = 5.0
    """Smallest semi-minor axis (px) of any ellipse the detector fits, merges, refines or
    pairs (every fit is held to this and ``max_axis_diagonals``): faces image with a
    semi-minor axis of ~10 px and more; thinner fits are arcs of wall lines and shading."""
    max_axis_diagonals: float = 1.0
    """Largest semi-major axis of any fitted ellipse, as a multiple of the searched image's
    diagonal (diagonals): a larger fit is a near-straight run fitted as a huge ellipse."""


@dataclass(frozen=True, kw_only=True)
class MergeParams(Section):
    """``merging`` stage: fits of one ellipse merged by the paper's Eq. 3, leftover segments
    absorbed, each ellipse validated by its edge support (:func:`~stackpick_sim.vision.
    merging.merge_segments`). The top rule's arc-pair regrouping holds to them too."""

    SECTION: ClassVar[str] = "merging"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "k": (0.0, 1.0, ""), "tolerance_px": (0.3, 10.0, "px"),
        "max_residual_px": (0.05, 5.0, "px"), "absorb_fraction": (0.0, 1.0, ""),
        "min_support": (0.0, 1.0, "")}

    k: float = 0.2
    """Eq. 3 threshold [0, 1] on C = N_{A/B} N_{B/A}: two halves of one face extrapolate ~1 px
    off each other's far side and score only 0.25-0.6, so k is low; wrong merges are kept
    out by the refit checks instead (``max_residual_px``, ``absorb_fraction``). Arcs of two
    different faces score ~0."""
    tolerance_px: float = 1.5
    """A pixel pertains to an ellipse within this distance, px: the RMS fit residual is
    ~0.3 px on anti-aliased edges, and 1.5 px admits two pixels of quantisation either
    way."""
    max_residual_px: float = 0.4
    """Largest RMS residual (px) of the refit on a merged pair, tighter than a single
    segment's (``fits.max_residual_px``): arcs of two different but similar faces can be
    fitted together to ~0.5 px while true arcs of one face refit to ~0.3 px."""
    absorb_fraction: float = 0.9
    """Share [0, 1] of a segment's pixels within ``tolerance_px`` of an ellipse for it to
    stay on a merged refit or to be absorbed as a leftover: a low residual alone lets a big
    ellipse pass between the arcs of two different faces."""
    min_support: float = 0.4
    """Share [0, 1] of its circumference along which a merged ellipse must have edge pixels
    to be kept: a face half hidden under another object keeps ~0.5; a cylinder's far rim
    (its wall's silhouette) also shows about half and is told apart later by the top
    rule."""


@dataclass(frozen=True, kw_only=True)
class RefineParams(Section):
    """``refine`` stage: each ellipse refitted on the edge pixels along it, in rounds of
    narrowing tolerance (:func:`~stackpick_sim.vision.refine.refine_all`)."""

    SECTION: ClassVar[str] = "refine"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "tolerances_px": (0.3, 20.0, "px"), "min_pixels": (5, 10_000, "px"),
        "min_normal_cos": (0.0, 1.0, "")}

    tolerances_px: tuple[float, ...] = (2.5, 1.5, 1.2)
    """Collection tolerances (px) of the successive refits, one round each: the first admits
    an arc fit that is ~2 px off on its far side, the last matches the merge's tolerance."""
    min_pixels: int = 20
    """Fewest edge pixels (px) collected along an ellipse for a refit; fewer keeps the fit in
    hand."""
    min_normal_cos: float = 0.87
    """Cosine [0, 1] of the largest angle between a collected edge pixel's gradient and the
    ellipse's normal (0.87: 30 deg): a face's own edge runs along its outline, while the
    outlines, walls and markings crossing it meet it at larger angles. The top face's final
    sub-pixel refit holds to it too."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.tolerances_px:
            raise ConfigError("vision.refine.tolerances_px = [] is out of range; allowed: "
                              "one or more tolerances, px")


@dataclass(frozen=True, kw_only=True)
class GateParams(Section):
    """``gate`` stage: with a depth range, ellipses too small or too large for any face
    radius in it are dropped after the refit."""

    SECTION: ClassVar[str] = "gate"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {"slack": (0.1, 10.0, "")}

    slack: tuple[float, float] = (0.9, 1.25)
    """(low, high) ratios: a face of radius r at depth z images with a semi-major axis of at
    least f r / z px (perspective only enlarges it, by up to 4% on the paper scene's frames);
    ellipses smaller than ``low`` times the smallest such axis at the farthest depth, or
    larger than ``high`` times the largest at the nearest, are arcs of rims, walls and shading
    fitted together. The slack covers fits on partial arcs."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _ordered(self, "slack")


@dataclass(frozen=True, kw_only=True)
class CompleteParams(Section):
    """The top stage's face completion: faces the merge never fitted, whose outline is faint
    along part of its length (a steep top face's boundary with its own wall or a neighbour
    of its colour and shade), proposed to the top rule from pairs of arcs when their whole
    outline shows a consistent edge in the gradients, whenever the rule's first choice is
    not clear (:mod:`~stackpick_sim.vision.faint_faces`)."""

    SECTION: ClassVar[str] = "complete"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_contrast_share": (0.0, 1.0, ""), "same_face_iou": (0.0, 1.0, ""),
        "max_faces": (0, 100, "faces")}

    enabled: bool = True
    """Whether the top stage proposes such faces: when the rule's first choice is no face
    that passed it outright showing a consistent edge along ``min_contrast_share`` of its
    outline (a clear choice: then nothing is proposed, at no cost), the faces are proposed
    and the rule run again over them all."""
    always: bool = False
    """Propose them after a clear choice too: a top face the merge never fitted can lie on
    a whole lower face whose boundary with it is faint, which then passes the rule
    outright. Off by default for its cost (pairs of every arc on every frame: about half of
    a paper-scene frame's detection); and a whole lower face the merge never fitted, which
    an object leans on, is proposed too, for the rule's rest test to reject. The cluttered
    scene, whose piles lay such faces often, turns it on."""
    min_contrast_share: float = 0.9
    """Share [0, 1] of a proposed face's outline that must show a consistent edge in the
    gradients (windowed normal gradient above the ``edges.support_*`` threshold): a top face
    shows its whole outline, its faint side too, while an ellipse through arcs of two
    outlines, or a lower face, shows none along a part of it (rendering dither and a
    pixel's rounding leave a few per cent of a whole face's samples below the threshold).
    Merged ellipses that show this share are whole faces already: their arcs are not
    paired; a chosen face that passed the rule outright and shows it is a clear choice."""
    same_face_iou: float = 0.85
    """An ellipse overlapping a merged one by at least this area intersection over union
    (ratio) is that ellipse's face fitted again, not a face the merge missed: not proposed
    (fits of one face on different arcs overlap by 0.9 and more; a face and the fit that
    took in part of its wall, or a neighbour's arc, by 0.8 and less)."""
    max_faces: int = 4
    """At most this many faces proposed per frame (the most contrast first): a cap on the
    top rule's extra work."""

@dataclass(frozen=True, kw_only=True)
class InnerFaceParams(Section):
    """The top stage's last step, when every face reads as occluded: a top face inside a
    lower face's fit (:mod:`~stackpick_sim.vision.inner_face`). Its refit is the top stage's
    inner refit, held to the ``top.inner_refit_*`` settings; the fits refitted show at least
    ``top.hidden_min_support`` of their outline."""

    SECTION: ClassVar[str] = "inner_face"

    enabled: bool = True
    """When the top rule and its fallbacks chose no face, each fit that fails on edges inside
    (a T-junction allowed) is refitted on its innermost consistent edge (``top.inner_refit_*``)
    and the rule run again with the refits in their fits' place; a refit it chooses is the
    top face. The failure class *a top face inside a lower face's fit*: a small top object
    standing on a larger one of its colour and shade, nearly concentric, is fitted round the
    lower face's strong silhouette, with its own wall's boundary inside the fit as edges, and
    no face passes the rule. Costs nothing on frames where a face is chosen (a contrast
    refit of the few such fits on the others)."""


@dataclass(frozen=True, kw_only=True)
class LeanParams(Section):
    """The top stage's check of a face that passed the rule outright against the faces
    leaning on it whose outline falls short of the rule's support
    (:mod:`~stackpick_sim.vision.leaning`). The contact is the rest test's
    (``top.rest_*``); the leaning face's edges inside may lie within ``top.rim_band_px``
    of its outline only."""

    SECTION: ClassVar[str] = "lean"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {"min_support": (0.0, 1.0, "")}

    enabled: bool = True
    """Whether a face with no T-junction, its outline short of ``top.min_support``, whose
    reconstructed cylinder rests on the chosen whole face's takes the choice. The failure
    class *a short-outlined face leaning on the chosen one*: a steep top object leaning its
    wall on a lower object's whole face shows no T-junction, and its boundary with its own
    wall or a neighbour of its colour is faint, so it fails the rule on support alone, below
    ``top.unobstructed_min_support``, and the rule's rest test never weighs it against the
    whole lower face, which passes. Needs a colour image and the object kinds' heights and
    radii (from colour, else every kind a face's size admits)."""
    min_support: float = 0.6
    """Least share [0, 1] of its outline a leaning face shows (edge support): 0.6, as
    ``top.hidden_min_support`` (a face at least half visible). A lower face's sliver, or an
    arc of a face with most of its outline hidden, is fitted too loosely for its cylinder to
    be placed: on rendered cluttered and grey development frames the faces found leaning
    show 0.73 or more, while fits below 0.6 read no lean or the contact the wrong way."""


@dataclass(frozen=True, kw_only=True)
class WholeRefitParams(Section):
    """The top stage's step after a fallback's choice that fails the rule itself: a top face
    whose fit took in its own wall or a neighbour's arc, shown whole by its refit on its
    innermost consistent edge (:mod:`~stackpick_sim.vision.whole_refit`; the refit's reach
    and rounds are the contrast refit's, ``top.contrast_*``)."""

    SECTION: ClassVar[str] = "whole_refit"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_support": (0.0, 1.0, ""), "reach_px": (1, 30, "px"),
        "settled_iou": (0.0, 1.0, "")}

    enabled: bool = True
    """When the fallbacks chose no face, or one that fails the rule itself and moves when
    refitted on its innermost consistent edge (``settled_iou``), each fit that fails the
    rule with at least ``min_support`` of its outline showing is refitted so; the rule runs
    again over the refits that pass it outright, and the refit it chooses is the top face,
    unless it is another face than the fallback's, clearly farther (``top.depth_tie_m``),
    or the fallback's face passes so refitted too (it shows whole: it keeps the choice).
    The failure class *a top face fitted round its own wall*: a top face over faces of its
    colour and shade, fitted on its strong arcs and its wall's silhouette beyond its rim (or
    a neighbour's arc running on from it), fails the rule on a T-junction, edges inside or
    support, while the fallbacks take a lower face, a misfit of one, or none. Costs nothing
    on frames where a face passes the rule outright."""
    min_support: float = 0.6
    """Share [0, 1] of its outline a fit must show to be refitted: at least half of a face
    (as the scoring counts faces, and ``top.hidden_min_support``); fits of arcs of two
    outlines and slivers of lower faces show less."""
    reach_px: int = 20
    """How far (px) inside a fit the refit looks for the face's innermost consistent edge:
    the widest band of its own wall a fit takes in beyond a top face's rim."""
    settled_iou: float = 0.95
    """A fallback's face whose refit on its innermost consistent edge overlaps its fit by at
    least this area intersection over union (ratio) lies on its own outline and keeps the
    choice: its boundary with a face of its colour shows no contrast, but what shows is its
    own. Fitted on their outline, such faces move by under a pixel (overlap 0.98 and more on
    rendered cluttered and grey frames); a fit round part of a face's wall or on arcs of two
    outlines moves by several (0.92 and less)."""


@dataclass(frozen=True, kw_only=True)
class UnderWallParams(Section):
    """The top stage's check of its choice against the other faces' cylinders: a face lying
    under a nearer cylinder's body (the cover test in reverse,
    :mod:`~stackpick_sim.vision.under_wall`). The covering faces show at least
    ``top.min_support`` of their outline (a whole face's, apart from a T-junction: its colour,
    hence its radius, is its own); the depth margin is ``top.cover_depth_tolerance_m``."""

    SECTION: ClassVar[str] = "under_wall"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {"min_share": (0.0, 1.0, "")}

    enabled: bool = True
    """Whether a chosen face lying under another face's cylinder gives up the choice: it is
    left out and the top stage runs again over the other faces. The failure class *the far
    rim of a steep cylinder*: its wall's silhouette beyond its face, closed by the face's near
    rim or a neighbour's arc, is fitted as an ellipse of about the face's size that passes
    the top rule, while the true face fails on a neighbour's outline touching it. Placed
    where its size and kind put it, that ellipse's face lies behind the cylinder's own wall
    (needs the object kinds' radii and heights)."""
    min_share: float = 0.9
    """Share [0, 1] of the chosen face's disc (its centre and 12 samples on each ring at
    0.35, 0.65 and 0.9 of its radius) that must lie behind another face's cylinder, under
    each of its own two pose solutions and one of the other's, for the face to lie under
    it: a far rim lies wholly behind its cylinder's wall (1.0 on rendered cluttered
    frames), while the true top faces chosen on rendered paper, grey and cluttered frames lie
    behind no well-supported face's cylinder at all (0.0); 0.9 leaves a few samples of the
    outer ring to a pose's fit and tilt errors."""


@dataclass(frozen=True, kw_only=True)
class TopParams(Section):
    """``top`` stage: the top rule (:func:`~stackpick_sim.vision.occlusion.select_top`) and
    what follows it.

    When no ellipse passes the rule, the ``fallbacks`` are tried in this order until one
    gives a face (drop a name to switch one off):

    - ``unobstructed``: a top face whose boundary with a lower face of its colour shows no
      contrast fails the rule on support alone; the best-supported face with no T-junction
      and no edge inside is taken.
    - ``contrast``: faces that failed on support or interior edges only are refitted on the
      edge contrast (a faint same-colour boundary the edge map missed), and the rule re-run.
    - ``nearer_arcs``: after the ``unobstructed`` choice or a passing contrast refit, a face
      of arc pairs the merge never joined that passes the rule and lies clearly nearer than
      that choice takes it (a top face the merge never fitted beside a lower, nearly whole
      face of its colour, or across faces of its colour and shade that hide part of its
      outline without a visible boundary).
    - ``rimmed``: a whole face whose interior edges all lie in a band along its outline (its
      own faint rim inside a same-colour lower face's sliver that its fit took in).
    - ``arc_pairs``: a face the merge never fitted, from pairs of the fitted arcs.
    - ``spare_refit``: a contrast refit with no T-junction and no edge inside, most of its
      outline showing (a top face fitted with part of a lower same-colour face's outline
      refits onto its own faint boundary).
    - ``all_arcs``: pairs that also take in the chains no fit was kept for and the parts of
      chains cut at junctions, else the unobstructed one, else one with its own rim inside:
      the least constrained of the arc pairs.
    - ``nearest_cut``: of the fitted faces and those of pairs of every arc at least half
      visible (``hidden_min_support``), one with no T-junction and no edge inside that lies
      clearly nearer (``depth_tie_m``) than every other: a top face across faces of its
      colour and shade, its boundary with them showing no contrast along more of its
      outline than ``unobstructed_min_support`` allows (needs the object kinds' colours).
    """

    SECTION: ClassVar[str] = "top"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "hidden_min_support": (0.0, 1.0, ""), "contrast_reach_px": (1, 20, "px"),
        "contrast_inner_reach_px": (1, 30, "px"), "contrast_rounds": (1, 10, "rounds"),
        "contrast_min_share": (0.0, 1.0, ""), "min_support": (0.0, 1.0, ""),
        "min_gap_px": (1, 1000, "px"), "junction_radius_px": (0.5, 20.0, "px"),
        "crossing_reach_px": (0.0, 50.0, "px"), "interior_margin_px": (0.0, 20.0, "px"),
        "max_interior_share": (0.0, 1.0, ""), "depth_tie_m": (0.0, 1.0, "m"),
        "support_tie": (0.0, 1.0, ""), "unobstructed_min_support": (0.0, 1.0, ""),
        "rim_band_px": (0.0, 30.0, "px"), "cover_min_share": (0.0, 1.0, ""),
        "cover_margin_px": (0.0, 20.0, "px"), "cover_depth_tolerance_m": (0.0, 0.1, "m"),
        "cover_min_samples": (1, 1000, "points"), "rest_contact_gap_m": (0.0, 0.1, "m"),
        "rest_max_penetration_m": (0.0, 0.1, "m"), "rest_min_up": (0.0, 1.0, ""),
        "arc_split_reach_px": (0.0, 50.0, "px"), "arc_grow_rounds": (0, 20, "rounds"),
        "off_outline_px": (0.0, 20.0, "px"), "rest_kind_margin_m": (0.0, 0.1, "m"),
        "cover_extra_depths": (0.0, 5.0, "radii"), "perspective_enlargement": (0.5, 2.0, ""),
        "kind_min_chroma_distance": (0.0, 2.0, ""), "inner_refit_max_area": (0.0, 1.0, ""),
        "inner_refit_reach_px": (1, 30, "px"), "inner_refit_min_inset_px": (0.0, 30.0, "px")}

    min_support: float = 0.9
    """Share [0, 1] of its outline along which an unoccluded face must show consistent edge
    contrast: the top face is >= 98% visible; 0.9 leaves room for Canny's gaps at junctions
    and along low-contrast arcs."""
    min_gap_px: int = 8
    """Runs of the outline without support shorter than this (px) are edge drop-outs, not
    occlusion: where a lower outline meets the top face in a T, Canny often breaks the
    through-going edge for 4-7 px too."""
    junction_radius_px: float = 3.0
    """Another contour passing within this distance (px) of where a gap in the outline ends
    makes the end a T-junction (Canny leaves a pixel or two of gap at a T instead of a
    junction pixel)."""
    off_outline_px: float = 1.5
    """An edge pixel farther than this (px) from the outline belongs to another contour
    (the T-junction test's; an occluder's pixels must lie farther inside the outline than
    this too): the outline's own edge lies within the merge's pertaining distance
    (``merging.tolerance_px``, the same default)."""
    crossing_reach_px: float = 6.0
    """An occluding contour runs on into the face it covers: besides passing within
    ``junction_radius_px`` of the gap end, it must have pixels inside the outline (by more
    than ``off_outline_px``) within this distance (px) of the end. A tilted cylinder's
    own wall lines (which touch the faint face-to-wall rim) and the outlines of objects lying
    under it stay outside its face."""
    interior_margin_px: float = 2.5
    """Edge pixels farther than this (px) inside the outline count as edges inside the face
    (the outline's own pixels, blurred and fitted to ~1 px, stay outside the count)."""
    max_interior_share: float = 0.05
    """Edge pixels inside a face allowed, as a share [0, 1] of its perimeter (px per px):
    isolated noise edges."""
    depth_tie_m: float = 0.01
    """A candidate face nearer the camera than every other by this much (m) is the top: an
    object resting on another's wall lies higher than it though both faces show whole. The
    face depths of one pile's candidates that are not clearly ordered differ by < 1 cm on
    rendered paper-scene frames; a fit's depth error is ~1 mm."""
    support_tie: float = 0.02
    """Candidates whose supports (shares [0, 1]) differ by less than this are tied; the
    ellipse of the longer semi-major axis, nearer the camera for equal radii whatever the
    tilt (a tilted face's area shrinks with the tilt's cosine), wins."""
    unobstructed_min_support: float = 0.75
    """Share [0, 1] of its outline a face with no T-junction and no edge inside must show for
    the ``unobstructed`` fallback (and to join the depth test): an occluder's outline runs
    into the face it covers, so such a face's gaps are boundaries too faint even for the
    contrast test, a top face over a lower face of its colour and shade (~0.80 on rendered
    paper-scene frames); far rims and arcs of two outlines fitted together show 0.5-0.6. Not
    proof on its own: lower faces whose occluder only clips their rim reach 0.75-0.88 with
    no edge inside, so this evidence is used only when nothing passes the rule, or with the
    ``depth_tie_m`` margin."""
    rim_band_px: float = 6.0
    """Edge pixels inside a face's outline by at most this (px) can be its own rim (the
    ``rimmed`` fallback and the rest check): a top face lying on a lower face of its own
    colour and about its size is fitted on the lower face's strong silhouette where that
    shows a sliver beyond it, and its own faint boundary then lies up to a few px inside the
    fit (3-4 px on rendered paper-scene frames, as ``contrast_inner_reach_px``); an
    occluder's outline runs across the face, deeper than this."""
    cover_min_share: float = 0.15
    """A face lies under another when at least this share [0, 1] of one pose solution's
    predicted wall band lies inside the other face (the T-junction rule for side walls,
    :mod:`~stackpick_sim.vision.wall_cover`): a false hit needs a second whole face right
    beside its rim, on the side a wall would show. Chosen on rendered paper-scene frames."""
    cover_margin_px: float = 1.0
    """Wall band points must lie this far (px) inside the other face to count as covered:
    its blurred outline and the fit error are no evidence."""
    cover_depth_tolerance_m: float = 0.003
    """A wall band point counts as covered only where the other face's plane lies nearer the
    camera than the point, or farther by at most this (m): a face's depth error (~1 mm) plus
    a 1-2 deg tilt error moving its far rim ~1 mm, on each of the two faces. A real cover has
    the covering object's body between its face and the wall, well in front."""
    cover_extra_depths: tuple[float, ...] = (0.8,)
    """Depths along the axis, in face radii, that the cover test's wall band samples beyond
    the pose's wall band (``pose.wall_depths``, which it samples first: the rest test reads
    those): 0.8 stays on the wall of the paper scene's squattest cylinder (height / radius =
    0.86). Deeper than the colour test's band because an object resting on a wall often
    covers only its far part. [] samples the pose's band alone."""
    cover_min_samples: int = 8
    """Points a solution's wall band needs outside its face for its covered share to count
    (fewer: 0), above the pose's ``min_band_samples``: a share over a few points of a thin
    band is noise, and can put a top face under a lower one."""
    rest_contact_gap_m: float = 0.003
    """Two reconstructed cylinders farther apart than this (m) do not touch (the rest check
    between whole faces, :mod:`~stackpick_sim.vision.resting`): a face's depth error is ~1 mm
    and a 1-2 deg tilt error moves a far rim ~1 mm."""
    rest_max_penetration_m: float = 0.004
    """Cylinders overlapping deeper than this (m) are no consistent reconstruction (a wrong
    pose solution, a misfitted face) and give no evidence: the pose errors above, both ways."""
    rest_min_up: float = 0.3
    """A contact normal (from the lower body to the upper, unit) with at least this upward
    component means the upper body rests on the lower: the ground truth's own threshold
    (an object is top when nothing touches it from above by more than this)."""
    perspective_enlargement: float = 1.04
    """Ratio by which perspective enlarges a face's semi-major axis beyond f r / z at most (4 %
    on the paper scene's frames, as ``gate.slack``): the rest check compares two faces'
    depths through r / a up to this factor to decide whether a face with its own rim inside
    reads nearer than the chosen one and is worth its refit and rest test (a cost gate, not a
    measurement: a face reading farther lies below the chosen one). Below 1, a rimmed face
    must read nearer by that ratio."""
    kind_min_chroma_distance: float = 0.1
    """Object kinds whose colours' chromaticities (r, g, b over their sum) differ by less than
    this (L1) cannot be told apart by colour: no face's radius is then read from its colour
    (the depth, cover and rest tests run without radii, or under every assignment of them).
    The paper scene's orange and blue lie 0.68 apart, the realistic scene's nearest kinds
    (grey and tan) 0.18; one object's face and wall differ by ~0.02-0.07 on rendered
    paper-scene frames (``pose.band_chroma_tolerance``), so kinds within 0.1 would be
    confused face by face."""
    depth_among_passing: bool = True
    """When the depth test over the passing faces and the faces that failed on support alone
    with nothing crossing them finds none clearly nearest, it runs again over the passing
    faces alone: the failure class *a lower face's tie voids the depth test* (a nearly whole
    lower face within ``depth_tie_m`` of the top face's depth would leave the best-supported
    passing face to win though another passing face lies clearly nearer). Of two passing
    faces, one clearly nearer is above the other whatever the failing face is."""
    kind_by_size: bool = True
    """With object kinds that colour cannot tell apart (``kind_min_chroma_distance``), a
    face's kind is read from its size (:mod:`~stackpick_sim.vision.kind_size`): the kinds
    whose radius places the face within the detector's depth range (the larger kind's would
    put a face imaged small beyond the belt, the smaller kind's a face imaged large above the
    highest face a pile shows). The depth tests run on the faces whose size admits one kind,
    and the rest test over every kind (``rest_kind_margin_m``) takes only the kinds each
    face's size admits; a face both kinds place within the range takes no part in a depth
    test (the ``hidden_check`` keeps to radii from colour). Needs a depth range and two
    kinds' radii or more."""
    rest_kind_margin_m: float = 0.01
    """With object kinds that colour cannot tell apart, the rest test
    (:mod:`~stackpick_sim.vision.resting`) reconstructs each pair of whole faces under every
    assignment of the kinds' radii: a rest found under one assignment counts only when under
    every other the two cylinders lie farther apart than this (m) or run through each other.
    A wrong radius moves a face by centimetres along its rays (the radii's ratio at
    0.2-0.3 m); scaling both faces alike keeps a touching pair within a few mm (3-5 mm on
    rendered grey paper-scene frames), which this leaves undecided."""
    rest_untold_solutions: bool = True
    """The rest test (:mod:`~stackpick_sim.vision.resting`) also judges a pair in which one
    face's wall bands cannot tell its two pose solutions apart: the failure class *a whole
    lower face chosen over the face leaning on it, its solution untold* (the leaning object
    hides the wall band that would tell the lower face's solution, so the pair gave no
    evidence, and the whole, best-supported lower face was taken over the partly seen top
    face). Each of the untold face's solutions is tried (with the other face's told one),
    and a rest counts when the combinations that find one all find it the same way, with
    the untold face as the lower body. An untold face found resting on another gives no
    evidence: nothing resting on it hides its band, so bands that cannot tell point to a
    rough fit (on rendered grey paper-scene frames, such a rest put a true top face under a
    partly seen, roughly fitted lower one). Off: such pairs give no evidence."""
    arc_split_reach_px: float = 6.0
    """For the arc-pair fallbacks, a chain is cut at its pixel nearest to another chain's end
    within this distance (px): Canny runs a face's outline on into a lower same-colour face's
    silhouette and leaves the faint boundary between them ending 4-7 px short of it (as
    ``min_gap_px``)."""
    arc_grow_rounds: int = 3
    """Rounds of growing an arc pair's ellipse by the chains lying on it (within the merge's
    tolerance and absorbing share) and refitting (within ``fits.max_residual_px``): the
    pair's own fit extrapolates up to a few px off the face's far arcs, and the first refit
    on the arcs near it pulls it within the merge's tolerance of the rest."""

    fallbacks: tuple[str, ...] = FALLBACKS
    """The fallbacks tried, by name, when no ellipse passes the top rule (see the section's
    list; always tried in the built-in order); [] turns them all off."""
    rest_check: bool = True
    """When an ellipse passes the rule, a whole face that failed on its own rim inside its fit
    and whose reconstructed cylinder rests on the chosen face's takes the choice instead:
    nothing may rest on a top object (needs the object kinds' colours and heights)."""
    marked_arcs: bool = True
    """When no ellipse passes the rule outright (none does, or a face with markings is
    chosen) and some ellipse holds markings across it (interior edges along
    ``marking_min_edge_share`` of its perimeter), whole faces with markings fitted on pairs
    of every arc join the rule: the merge joins no arcs across a printed face's artwork or a
    can end's rings, so such a face is often fitted only on arc pairs. Frames without faces
    with markings pay nothing; on frames of printed lids and cans the arc pairs cost several
    times the rest of the detector."""
    hidden_check: bool = True
    """When an ellipse passes the rule and another was cut short with nothing crossing it (no
    T-junction, no edge inside, support at least ``hidden_min_support``), a face from pairs
    of the fitted pieces on none of the faces the rule weighed that lies clearly nearer takes
    the choice: an occluder whose outline shows runs into the face it covers, so a face cut
    short by nothing lies under a face of its colour and shade the merge never fitted, which
    can be the top (needs the object kinds' colours)."""
    nearer_hidden: bool = True
    """After the ``unobstructed`` fallback's choice, a fitted face cut short by nothing (no
    T-junction, no edge inside, support at least ``hidden_min_support``) that lies clearly
    nearer (``depth_tie_m``) takes the choice: a top face over faces of its colour and
    shade shows no contrast along its boundary with them, which can leave it below the
    unobstructed test's support, while the face that test chose is a lower one whose
    occluder only clips its rim (needs the object kinds' colours)."""
    nearer_rimmed: bool = True
    """After the ``unobstructed`` fallback's choice, a whole face whose only interior edges
    lie in its rim band (``rim_band_px``: its own faint rim inside a same-colour lower face's
    sliver that its fit took in), refitted on its innermost consistent edge, that lies
    clearly nearer (``depth_tie_m``) takes the choice as that refit: a top face over lower
    faces of its colour fails the rule on that rim alone, while the face the fallback chose
    is a lower one whose occluder only clips its rim (needs the object kinds' colours)."""
    nearer_refit: bool = True
    """After the ``rimmed`` fallback's choice, a face with edges inside and no T-junction
    (support at least ``hidden_min_support``), refitted on its innermost consistent edge,
    that shows whole as that refit (it passes the rule, or fails it on its own rim alone)
    and lies clearly nearer (``depth_tie_m``) takes the choice as that refit: the failure
    class *a top face fitted round its own wall* (its rim lies deeper inside the fit than
    ``rim_band_px``, so it is no rimmed face), above a lower whole face it leans on, which
    the fallback took."""
    inner_refit: bool = False
    """When an ellipse passes the rule outright, it is refitted on its innermost consistent
    edge (the ``contrast_*`` fields' refit), and a refit clearly smaller
    (``inner_refit_max_area``) that passes the rule too replaces it: a top face over lower
    faces of its colour and shade is fitted round slivers of them on their strong
    silhouette, its own boundary with them a faint step of a few grey levels inside the fit
    that the edge map misses. A refit leaving out no sliver (``inner_refit_min_inset_px``)
    is a well-fitted face's own soft rim and changes nothing. Off by default for its cost: a
    contrast refit of every chosen face, ~0.2 ms a frame (7 % of a paper-scene frame's
    detection); the cluttered scene, whose piles lay such faces more often, turns it on."""
    inner_refit_reach_px: int = 20
    """Inward search reach (px) of the inner refit: the slivers of lower faces a fit takes in
    beyond a top face of their colour are as wide as the faces' offset plus the difference of
    their radii, 5-20 px on rendered cluttered and grey paper-scene frames (a small top face
    nearly concentric on a large lower one), beyond the contrast fallback's reach
    (``contrast_inner_reach_px``)."""
    inner_refit_max_area: float = 0.95
    """Largest ratio [0, 1] of the inner refit's area (product of semi-axes) to the fit's for
    the refit to replace the chosen face: a refit on a well-fitted face's own edge keeps
    0.97-1.05 of its area (on rendered paper, grey and cluttered frames), so less than 0.95
    is a fit that took in a sliver beyond the face."""
    inner_refit_min_inset_px: float = 6.0
    """Least width (px) of the sliver the inner refit must leave out for it to replace the
    chosen face (the fit reaching this far beyond the refit somewhere): the slivers of lower
    faces a fit takes in beyond a top face of their colour are 8-16 px wide where the edge
    map misses the top face's boundary, while a well-fitted face's outline blurred over a
    few pixels (a close, tracked view) shows a faint inner shoulder 1-5 px inside it (the
    most along an oblique view's near rim), on which the refit shrinks a face of semi-axes
    under ~40 px by more than ``inner_refit_max_area`` allows and moves its centre (on
    rendered cluttered and grey frames and a paper pick episode's tracked frames)."""
    hidden_min_support: float = 0.6
    """Share [0, 1] of its outline a face cut short with nothing crossing it must show for the
    hidden-face check: a face at least half visible, as the scoring counts faces (far rims
    and arcs of two outlines fitted together show about half theirs)."""
    contrast_reach_px: int = 3
    """Search reach (px) either side of the outline of the ``contrast`` fallback's refit on
    the strongest consistent edge: a face fitted on a partial outline (same-colour neighbours
    leave only faint edges) is off by up to ~3 px there (measured on rendered paper-scene
    frames)."""
    contrast_inner_reach_px: int = 6
    """Inward search reach (px) of the contrast refit on the innermost consistent edge: a top
    face lying on a lower face of its own colour and about its size ends at a faint boundary
    a few px inside the lower face's strong silhouette (4-5 px on rendered paper-scene
    frames: a rim offset of ~1.5 mm at 0.3 m); the face's smooth inside holds no other
    edge. The rest check's refit of a face with its own rim inside holds to it too (the
    band that rim is looked for in is ``rim_band_px``)."""
    contrast_rounds: int = 2
    """Contrast refit rounds, each re-centring the search on the previous fit: the first
    moves a fit that is a few px off onto the faint edge, the second fits on it whole."""
    contrast_min_share: float = 0.5
    """Fewest samples with a consistent edge, as a share [0, 1] of the outline, for a
    contrast refit (fewer: no refit): a face at least half visible, as the scoring counts
    faces."""

    def __post_init__(self) -> None:
        super().__post_init__()
        unknown = [f for f in self.fallbacks if f not in FALLBACKS]
        if unknown or len(set(self.fallbacks)) != len(self.fallbacks):
            raise ConfigError(f"vision.top.fallbacks = {list(self.fallbacks)!r} is not "
                              f"allowed; give distinct names of {', '.join(FALLBACKS)}")


@dataclass(frozen=True, kw_only=True)
class MarkingParams(Section):
    """The top rule's tests of whole faces with markings (printed artwork, a can end's rings)
    that the scene's ``marking_depth_ratio`` and ``marking_min_edge_share`` switch on
    (:mod:`~stackpick_sim.vision.markings`)."""

    SECTION: ClassVar[str] = "markings"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "surface_chroma_tolerance": (0.0, 2.0, ""),
        "surface_brightness_range": (0.01, 100.0, ""),
        "crossing_min_support": (0.0, 1.0, ""), "min_part_samples": (1, 64, "samples"),
        "max_off_rim_share": (0.0, 1.0, ""), "ring_hole_scale": (0.0, 1.0, ""),
        "ring_hole_share": (0.0, 1.0, ""), "rim_sample_scale": (0.5, 1.0, "")}

    surface_chroma_tolerance: float = 0.12
    """Two parts of a face's rim band (inside and outside an inner whole face) are two
    surfaces, the face a fit round another face and its wall or a lower face, when their
    median colours' chromaticities (r, g, b over their sum) differ by more than this (L1):
    face and wall of one object differ by ~0.02-0.07 on rendered paper-scene frames, the
    grey belt sits ~0.3 from a coloured face."""
    surface_brightness_range: tuple[float, float] = (0.7, 1.0 / 0.7)
    """...or when the outer part's brightness (channel sum) over the inner part's lies
    outside this (low, high) range of ratios: a cylinder's wall under the ring light is
    darker than its face (about tan(tilt) of it plus ambient light), while a face's own rim
    band, printed or tinplate, keeps within about 0.75-1.1 of itself round it (vignetting,
    shading, artwork at the rim; measured on rendered realistic-scene frames)."""
    crossing_min_support: float = 0.75
    """Where two whole faces with markings cross, the upper one's outline shows edge contrast
    along at least this share [0, 1] of its run over the lower one, and the lower one's
    hidden outline along less (a hidden arc still picks up contrast where the upper face's
    artwork or rings cross it; as ``top.unobstructed_min_support``)."""
    min_part_samples: int = 4
    """Fewest rim band or outline samples either part needs for the two-surface and the
    crossing tests to decide (fewer: no verdict), of 64 rim band and 32-plus outline
    samples."""
    max_off_rim_share: float = 0.2
    """Share [0, 1] of a whole face with markings' rim band (its ellipse at 0.94 of its
    semi-axes) that may be off the band's median colour (chromaticity farther than
    ``surface_chroma_tolerance``, or brightness outside ``surface_brightness_range`` of it)
    for it to stay a candidate for the top. A face's rim band is its own surface all round:
    a printed lid's stripe and lettering cross at most 16 % of it, a can end's tinplate rim
    and a tape roll's ring none (on rendered realistic-scene frames). More is another
    surface: a lower face whose fit the top object's outline completes has the top object
    across its band, and a fit round a face and its wall runs over the wall or the belt
    (20-50 % on those frames)."""
    ring_hole_scale: float = 0.45
    """Share [0, 1] of a face's semi-axes within which its interior edges are a hole's (a
    roll's ring face round its core, :mod:`~stackpick_sim.vision.rings`): a tape roll's core
    is about a quarter of its radius (25.4 mm in 100 mm), and the hole's outline and the
    core's wall seen through it lie within 0.4 of the face's semi-axes on rendered
    realistic-scene frames (edge blur included); printed artwork and a can end's rings
    spread to the rim. Capped per face at the smallest kind's radius over the face's: an
    object lying on the face reads nearer, so no smaller."""
    ring_hole_share: float = 0.95
    """Share [0, 1] of a whole face's interior edge pixels that must lie within
    ``ring_hole_scale`` for it to be judged a ring face round its hole: nearly all (a few
    stray edges of noise or the worn belt's texture aside); on rendered realistic-scene
    frames a tape roll's face has all of them there, printed lids and can ends under half."""

    rim_sample_scale: float = 0.94
    """Share [0, 1] of a face's semi-axes at which its rim band lies (the band whose colour
    gives its kind and whose samples the two-surface and off-rim tests read). An object lying
    wholly inside the face (inside by the interior-edge margin) can cover its middle, where
    its colour is read otherwise (at 0.5 of its semi-axes), but leaves most of this band; a
    can end's rim (its outer 12 %) lies on it."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _ordered(self, "surface_brightness_range")


@dataclass(frozen=True, kw_only=True)
class ReportParams(Section):
    """The ``pose`` stage's choice of the ellipses a detection reports: supported ones, each
    face once, no far rims."""

    SECTION: ClassVar[str] = "report"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_support": (0.0, 1.0, ""), "duplicate_tolerance_px": (0.0, 20.0, "px"),
        "duplicate_share": (0.0, 1.0, ""), "duplicate_near_px": (0.0, 100.0, "px"),
        "misfit_share": (0.0, 1.0, ""), "rim_size_tolerance": (0.0, 1.0, ""),
        "rim_offset_range": (0.0, 2.0, ""), "rim_angle_deg": (0.0, 90.0, "deg")}

    min_support: float = 0.6
    """Share [0, 1] of an ellipse's outline along which consistent edge contrast must show
    for it to be reported (the top face always is): arcs of two outlines fitted together and
    far rims stay below; a real face at least half visible keeps about its visible share, and
    the scoring counts faces >= 50% visible. The top rule's contrast retry takes only
    ellipses this well supported too."""
    duplicate_tolerance_px: float = 2.5
    """Two reported ellipses are one face fitted twice when each outline lies within this
    distance (px) of the other along ``duplicate_share`` of it: the edge refit's first
    collection tolerance, within which it pulls a fit onto the face's edge."""
    duplicate_share: float = 0.9
    """Share [0, 1] of each outline that must lie within ``duplicate_tolerance_px`` of the
    other for two ellipses to be one face."""
    duplicate_near_px: float = 5.0
    """Only ellipses whose centres and semi-axes each differ by at most this (px) are compared
    outline to outline: two outlines within ``duplicate_tolerance_px`` of each other along
    nearly all their length differ by about that much, twice it at most (on 400 rendered
    paper-scene frames the duplicates differ by <= 1.3 px, and 89% of the compared pairs by
    more than this)."""
    misfit_share: float = 0.5
    """Share [0, 1]: a reported ellipse whose outline lies within ``duplicate_tolerance_px``
    of the top face's along at least this share of its own is the top face fitted again on
    arcs of its outline and of another, not a face of its own. Two faces' outlines cross at
    points and run together along an arc only where a face of the top's size lies nearly in
    line under it, hidden (on 4000 paper-scene and 200 cluttered-scene frames, 350 ellipses
    reach this share, 4 of them true faces: two equal faces stacked in line)."""
    rim_size_tolerance: float = 0.1
    """Ratio: an ellipse is a cylinder's far rim (the end of its wall silhouette, half hidden
    behind its face), not a face, when it has a better-supported face's semi-axes within this
    share of them..."""
    rim_offset_range: tuple[float, float] = (0.15, 0.9)
    """...and is shifted from it along that face's minor axis by this (low, high) range of
    ratios to its semi-major axis: a rim at height h behind a face of radius r tilted by t
    lies (h / r) sin t semi-axes away; the paper scene's h <= r and t <= 45 deg give <= 0.71,
    the upper end adds perspective and fit error, the lower end keeps near-concentric
    ellipses (two faces stacked in line, square on) out of the test."""
    rim_angle_deg: float = 20.0
    """Largest angle, deg, between a far rim's offset and the face's minor axis (the image of
    the cylinder's axis)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _ordered(self, "rim_offset_range")


@dataclass(frozen=True, kw_only=True)
class PoseParams(Section):
    """``pose`` stage: the top face's final fit and its pose."""

    SECTION: ClassVar[str] = "pose"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "profile_window_margin_px": (2, 32, "px"), "min_band_samples": (1, 1000, "samples"),
        "band_tie": (0.0, 1.0, ""), "lone_band_min_share": (0.0, 1.0, ""),
        "wall_tie": (0.0, 1.0, ""), "wall_probe_radii": (0.1, 10.0, "radii"),
        "wall_rim_points": (8, 1024, "points"), "wall_end_skip_px": (0.0, 50.0, "px"),
        "subpixel_tolerance_px": (0.3, 10.0, "px"), "profile_reach_px": (0.5, 10.0, "px"),
        "profile_step_px": (0.1, 2.0, "px"), "profile_rounds": (0, 10, "rounds"),
        "profile_min_share": (0.0, 1.0, ""), "outlier_medians": (1.0, 100.0, ""),
        "outlier_min_px": (0.0, 10.0, "px"), "band_chroma_tolerance": (0.0, 2.0, ""),
        "band_min_brightness": (0.0, 1.0, ""), "band_brightness_margin": (0.0, 10.0, ""),
        "band_belt_delta": (0.0, 255.0, "grey levels"), "wall_depths": (0.0, 5.0, "radii"),
        "wall_margin_px": (0.0, 20.0, "px")}

    subpixel_tolerance_px: float = 1.2
    """Collection tolerance (px) of the top face's sub-pixel refit on the edge pixels along
    it: the edge refit's last round leaves the face's own edge pixels within ~1 px."""
    profile_reach_px: float = 2.0
    """Reach (px) either side of the outline of the gradient-profile refit that follows:
    covers the sub-pixel refit's error on a face whose faint arcs the edge map dropped."""
    profile_step_px: float = 0.5
    """Spacing (px) of the samples along each normal of the profile search: the peak is
    placed by a parabola through its neighbours, so half a pixel resolves a blurred edge's
    profile without the cost of a finer grid."""
    profile_rounds: int = 1
    """Profile refit rounds, each re-centring the search on the previous fit (0: none): one
    starts from the sub-pixel refit, already within a fraction of a pixel, and a second does
    not move rendered faces further."""
    profile_min_share: float = 0.5
    """Fewest outline samples with a gradient peak, as a share [0, 1] of the outline, for a
    profile refit (fewer keeps the fit in hand): a face at least half visible, as the scoring
    counts faces."""
    outlier_medians: float = 3.0
    """Profile peaks whose distance to the first profile fit exceeds this multiple of the
    median distance (and ``outlier_min_px``) are dropped before the final fit: a neighbour's
    edge met where two outlines run close."""
    outlier_min_px: float = 0.3
    """Least outlier distance (px): on a clean outline the median distance is a few
    hundredths of a pixel, and peaks within a third of a pixel are the face's own."""
    profile_window_margin_px: int = 3
    """Margin, px, beyond the profile search of the window whose unblurred gradients the top
    face's final fit reads: Sobel's 3x3 footprint and the bilinear neighbour."""
    min_band_samples: int = 4
    """Samples a pose solution's wall colour band needs to count as visible (fewer: the band
    hides behind the face, as for a face seen square on). On 1000 rendered paper-scene frames
    no band decision is wrong down to 3 samples, while the smaller-tilt choice misses 14 of 234
    faces, 5 of them with clear bands of 4-7 samples (a small face, or a tilt of 10-15 deg): 8
    would send those to it."""
    band_tie: float = 0.3
    """Band shares [0, 1] of the two solutions closer than this are a tie (the smaller tilt is
    then taken): on rendered paper-scene frames the true band scores 0.5-1.0, the wrong one
    0-0.3 (0.57 once, on a same-colour neighbour)."""
    lone_band_min_share: float = 0.5
    """A lone visible band showing the face's hue on less than this share [0, 1] is the wrong
    solution's."""
    band_chroma_tolerance: float = 0.12
    """A wall band sample shows the face's hue when the L1 distance between their
    chromaticities (r, g, b over their sum) is at most this: face and wall of one object
    differ by ~0.02-0.07 on rendered paper-scene frames, the grey belt sits ~0.35 from
    orange, ~0.3 from blue. The rest check reads the wall bands by the same test."""
    band_min_brightness: float = 0.12
    """A band sample darker than this share [0, 1] of the face's brightness carries no usable
    hue (deep shadow); an upright wall under the ring light measures ~0.27 of its face."""
    band_brightness_margin: float = 0.3
    """A wall sample is at most tan(tilt) plus this share of the face's brightness (ratio),
    the tilt being the face normal's angle to the viewing ray: under a ring light at the
    camera a Lambertian wall faces the light by at most sin(tilt) where the face does by
    cos(tilt). The margin covers ambient light on near-frontal walls (~0.2) and shading
    (rendered paper-scene frames: true walls at <= tan(tilt) + 0.2, the same-coloured lower
    faces the other solution's band lands on at ~1.0 with tan(tilt) ~ 0.3-0.4)."""
    band_belt_delta: float = 14.0
    """A band sample within this many grey levels of the bare belt's colour in every channel
    is belt, not wall (what tells them apart when the face has the belt's hue: a grey
    object): the belt's own spread under the ring light, as ``roi.foreground_delta``."""
    wall_depths: tuple[float, ...] = (0.2, 0.4, 0.6)
    """Depths along the axis, in face radii, at which a pose solution's predicted wall band is
    sampled (the colour test's band, which the rest and cover tests read too): the paper
    scene's squattest cylinder has height / radius = 0.03 / 0.035 = 0.86, so 0.6 stays on the
    wall of either kind."""
    wall_margin_px: float = 2.0
    """Wall band samples closer than this (px) to the face's outline are dropped (in the
    colour, cover and rest tests): the blurred face edge there mixes both colours."""
    wall_tie: float = 0.15
    """Without a colour image: edge support [0, 1] of the two solutions' predicted wall
    silhouette lines closer than this is a tie."""
    wall_probe_radii: float = 1.0
    """Without a colour image: how far down the axis the wall is probed, in face radii: the
    shortest cylinder of the paper scene has height / radius = 1.6, so 1.0 stays on the wall
    for either kind."""
    wall_rim_points: int = 48
    """Without a colour image: rim points the wall hull is predicted from (points)."""
    wall_end_skip_px: float = 2.0
    """Without a colour image: px skipped at each end of a predicted silhouette line, where it
    meets the face outline (whose own edge would support either solution)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.wall_depths:
            raise ConfigError("vision.pose.wall_depths = [] is out of range; allowed: one or "
                              "more depths, radii")


@dataclass(frozen=True, kw_only=True)
class EllipsesParams(Section):
    """Scoring of :func:`~stackpick_sim.vision.ellipses.find_ellipses` (ellipses only)."""

    SECTION: ClassVar[str] = "ellipses"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "min_normal_cos": (0.0, 1.0, ""), "stroke_reach_px": (0.0, 64.0, "px"),
        "stroke_reach_axis": (0.0, 4.0, ""), "stroke_min_ratio": (0.0, 1.0, ""),
        "max_stroke_share": (0.0, 1.0, "")}

    min_normal_cos: float = 0.87
    """Cosine of the largest angle between an outline sample's gradient and the outline's
    normal for the sample to count (0.87: 30 deg, as the edge refit's test): texture and glyph
    edges crossing an outline meet it at any angle, a rim's gradient runs along its normal."""
    stroke_reach_px: float = 12.0
    """Thin strokes (the rings of letters O, o, 0, @, printed circles, embossed outlines):
    how far (px of the searched image) outside and inside the outline to look for the
    stroke's other edge, an edge of the opposite polarity running along it (below 2: no
    stroke test). 12 px covers the strokes of bold print and glyphs (up to ~10 px wide) with
    the blur's spread; a disc's face holds no such edge near its rim."""
    stroke_reach_axis: float = 1.5
    """The inward reach as a multiple of the ellipse's semi-minor axis (the smaller of this
    and ``stroke_reach_px`` applying inside): below 2 so that the search never reaches a
    disc's own far rim (2 b across at the minor axis, of opposite polarity along the same
    normal), while the outer edge of a bold letter's stroke, about as wide as its hole, is."""
    stroke_min_ratio: float = 0.5
    """Smallest strength of the opposite edge, as a share of the outline's own edge there,
    for it to count as the stroke's other edge (0.5: a printed stroke's two edges are equally
    strong; texture crossing a disc's rim at random angles rarely reaches half its normal
    gradient)."""
    max_stroke_share: float = 0.5
    """Largest share (0-1) of the supported outline samples with a stroke's other edge within
    reach: above it, the ellipse is a stroke's outline and is not reported. Discs on glyph,
    logo and label backgrounds stay below 0.5 (their outside meets glyphs along a part of the
    rim only; benchmarks/bench_ellipses_precision.py), glyph rings lie near 1."""


@dataclass(frozen=True, kw_only=True)
class OutlineTrackingParams(Section):
    """Tracking mode: a tracked face's outline searched for around its predicted ellipse
    where the detector misses it (:func:`~stackpick_sim.vision.moving_edges.track_outline`;
    the scene's ``[episode.outline]`` table: the tracker's settings, not the detector's)."""

    PREFIX: ClassVar[str] = "episode"
    SECTION: ClassVar[str] = "outline"
    RANGES: ClassVar[dict[str, tuple[float, float, str]]] = {
        "search_px": (0.5, 100.0, "px"), "min_axis_px": (1.0, 1000.0, "px"),
        "samples": (8, 1024, "points"), "min_step": (0.0, 255.0, "grey levels/px"),
        "inlier_px": (0.1, 20.0, "px"), "min_inlier_share": (0.0, 1.0, ""),
        "size_tolerance": (0.0, 1.0, ""), "close_search_px": (0.5, 100.0, "px")}

    search_px: float = 6.0
    """How far (px) the outline is searched for along the predicted ellipse's normals: the
    prediction's error plus the face's motion between the tick of the prediction and the
    capture (~3 px at 0.3 m/s). Placeholder."""
    min_axis_px: float = 8.0
    """Predicted faces smaller than this (semi-major axis, px) are not searched for: too few
    pixels along their outline."""
    samples: int = 72
    """Points along the predicted outline where the edge is searched for (one every 5 deg)."""
    min_step: float = 4.0
    """Smallest grey-level step (grey levels/px along the normal, on the grey image smoothed
    over 3 px) taken for the outline: several times the camera's noise (std ~1 grey level).
    Placeholder."""
    inlier_px: float = 1.5
    """A sample's edge farther than this (px) from the fitted ellipse is an outlier (the
    edge of a neighbour or of the face's markings)."""
    min_inlier_share: float = 0.6
    """Share [0, 1] of the samples that must be inliers of the final fit: most of the outline
    must show."""
    size_tolerance: float = 0.2
    """The fit must keep its semi-axes within this share of the predicted semi-major axis
    (ratio): a fit on a neighbour's outline or on arcs of two faces changes size."""
    close_search_px: float = 2.0
    """Search reach (px) of the final search, along the normals of the fit itself (after the
    inlier refits on the ``search_px`` search): the fit then lies about a pixel from the
    outline; twice that with margin, so a neighbour's edge a few px off stays out."""


@dataclass(frozen=True, kw_only=True)
class StageSections:
    """One section per stage (fields named by each section's ``SECTION``): the scene's
    ``[vision]`` table (:class:`~stackpick_sim.config.scene_config.VisionCfg`) and
    :class:`~stackpick_sim.vision.detector.DetectorConfig` both carry them."""

    roi: RoiParams = field(default_factory=RoiParams)
    edges: EdgeParams = field(default_factory=EdgeParams)
    segments: SegmentParams = field(default_factory=SegmentParams)
    fits: FitParams = field(default_factory=FitParams)
    merging: MergeParams = field(default_factory=MergeParams)
    refine: RefineParams = field(default_factory=RefineParams)
    gate: GateParams = field(default_factory=GateParams)
    complete: CompleteParams = field(default_factory=CompleteParams)
    inner_face: InnerFaceParams = field(default_factory=InnerFaceParams)
    lean: LeanParams = field(default_factory=LeanParams)
    under_wall: UnderWallParams = field(default_factory=UnderWallParams)
    whole_refit: WholeRefitParams = field(default_factory=WholeRefitParams)
    top: TopParams = field(default_factory=TopParams)
    markings: MarkingParams = field(default_factory=MarkingParams)
    report: ReportParams = field(default_factory=ReportParams)
    pose: PoseParams = field(default_factory=PoseParams)
    ellipses: EllipsesParams = field(default_factory=EllipsesParams)


def sections_of(holder: StageSections) -> dict[str, Any]:
    """The sections ``holder`` (a VisionCfg or a DetectorConfig) carries, by key (keyword
    arguments for the other's constructor)."""
    return {f.name: getattr(holder, f.name) for f in fields(StageSections)}

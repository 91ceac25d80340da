"""Markings and relief inside a face: the top rule's evidence that a face's inner outlines are
its own.

Failure class: *an ellipse that is a marking or relief inside a larger face's outline*.
Printed lids carry artwork (a word, a stripe, a logo's ring) and a tinplate can end a raised
rim round a groove and a countersunk panel. Their edges lie inside the face's outline, so the
face fails the top rule on interior edges, and a closed inner outline (a groove, a ring, a fit
on the artwork) shows no T-junction and nothing inside it: it passes the rule and is taken for
an unoccluded top face lying inside the true one.

What tells such an outline from a smaller object lying on the face is where it would lie. A
face whose outline shows whole (support >= ``top.min_support``, no T-junction end) has nothing
across its outline: whatever lies on it lies wholly inside it, and an object resting on it is
nearer the camera than it, by about its own height. A face's depth from its image size is
proportional to r / a (its radius r, from its colour when the object kinds' colours are known,
and its semi-major axis a, px). Of the smaller ellipses centred on such a face:

* one lying wholly inside it by more than the interior-edge margin whose depth so read is not
  nearer than the face's (``depth_ratio`` of it or more, with its own kind's radius, else the
  smallest) is not an object on it: a marking or relief in the face's plane, whose radius is
  smaller than any kind's at that depth. It is no candidate for the top;
* one that passes the top rule itself, or lies wholly inside it and reads nearer, is a face
  on it: the face is under it;
* one that fails the rule and runs across the face's whole outline is a fit on its markings
  and outline together, when nothing else lies on the face; but when it shows whole itself
  and the face's rim band shows two surfaces, one inside it and one outside it (their colours
  apart in hue, ``surface_chroma_tolerance``, or in brightness, ``surface_brightness_range``), the
  face's outline runs over another surface beyond it: the outer ellipse is no face but a fit
  of the inner face's outline with an outline beyond it (its own cylinder's wall
  silhouette, a lower face's edge), and it is judged no further.

Failure class of the last: *a fit round a face and its wall*. A tilted cylinder's face
outline runs on into its wall's silhouette; the ellipse fitted to the face's far arc and the
silhouette holds the whole face and reads nearer than it (larger), and without the colour
test it takes the face for its marking. A face's rim band is its own surface all round (a
printed stripe or word crossing it is a small share of it: the medians of the two parts
agree).

Markings across a face (a word, a stripe, a logo, a can end's rings) leave interior edges
along about its perimeter or more; a plain face that fails on interior edges shows a stray
edge entering it (an occluder's, where the occluder's own fit is missing), a fraction of its
perimeter. So only faces with at least ``min_edge_share`` interior edge pixels per perimeter
pixel are judged. A whole face that fails the rule on interior edges alone, with no face on
it and no other face of its own reaching into it, has only its own markings inside: it is a
candidate, and the ellipses of the third kind are no candidates either. (A face whose interior
edges all lie in its rim band is left to the rule's rim fallbacks: :func:`~stackpick_sim.
vision.occlusion.rim_only`.)

A face of its own reaching into it is one that passes the rule, or a whole face with markings
crossing it (neither holds the other's centre) whose outline runs on across it as an edge
while its own outline under that face is hidden (``crossing_min_support``). Failure class: *a
lower lid fitted whole*: where a printed lid lies across another of its kind, the lower one's
ellipse (fitted on its visible arcs) shows no T-junction, its hidden arc picking up the upper
lid's artwork edges; both show whole with markings, and only the two outlines' runs across
each other tell which lies on which (the paper's rule of the occluding contour running
through).

A roll's ring face (a tape roll round its core) fails on its hole's outline, too few interior
edges for ``min_edge_share``; a whole face whose interior edges nearly all lie in a small
concentric ellipse is judged the same way (:mod:`~stackpick_sim.vision.rings`), the hole's
fit being its marking.

A face judged so is a candidate only if its rim band is its own surface: off the band's
median colour (another hue, or another brightness) along at most ``max_off_rim_share`` of it
(:func:`off_rim_share`). Failure classes: *a lower face whose outline the top object's
outline completes* (a lower lid's fit runs on along the upper lid's outline where its own is
hidden, shows whole, and the upper lid, fitted only in part, lies across its rim band) and *a
fit round a face and its wall* with no whole inner face to read it by (it runs over the
wall's darker band or the belt).

The tests read only ellipses, their evidence, the faces' colours, for crossing faces the
edge contrast along their outlines (a few hundred pixels each) and, for ring faces, the edge
pixels inside them: no image pass (cheap). Their settings:
:class:`~stackpick_sim.config.vision_params.MarkingParams`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import MarkingParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels_top
from stackpick_sim.vision.contrast import contrast_profiles, contrast_threshold, outlines
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.kernels import kernel_array
from stackpick_sim.vision.rings import hole_only
from stackpick_sim.vision.wall import column_median

if TYPE_CHECKING:  # the top rule (occlusion) calls this module
    from stackpick_sim.vision.occlusion import OcclusionEvidence

#: Outline samples per ellipse for the "wholly inside" test.
INSIDE_SAMPLES = 32
#: Rim band samples of the two-surface test.
BAND_SAMPLES = 64
#: The default settings of the two-surface and crossing tests (see MarkingParams).
DEFAULT = MarkingParams()


@dataclass(frozen=True, kw_only=True)
class MarkingTest:
    """What the test reads besides the ellipses: the object kinds' ``radii`` (m); a face's
    radius by the colour of its rim band (``rim_radius_of``, None when the kinds' colours are
    unknown; see MarkingParams.rim_sample_scale); ``depth_ratio``: an inner ellipse whose
    depth reads at least this multiple of the face's is a marking (ratio); ``min_edge_share``:
    the interior edge pixels, per pixel of its perimeter, a face holds at least for them to be
    read as markings across it; ``margin_px``: how far (px)
    inside the face a marking's whole outline lies (the margin of the interior-edge count);
    ``image``: the (H, W, 3) RGB image the ellipses are given in, for the two-surface test
    (:func:`two_surfaces`; None: no such test); ``gradients``: its edges and gradients, for
    the test of a whole face crossing another (:func:`_crosses_over`; None: no such test);
    ``params``: those tests' settings and those of the ring and rim band tests
    (:func:`ring_round_hole`, :func:`off_rim_share`)."""

    radii: tuple[float, ...]
    rim_radius_of: Callable[[Ellipse], float | None] | None
    depth_ratio: float
    min_edge_share: float
    margin_px: float
    image: NDArray[np.uint8] | None = None
    gradients: EdgeImage | None = None
    params: MarkingParams = DEFAULT
    #: The pair tests' verdicts on this image so far, by (test, ellipse, ellipse): when
    #: arc-pair faces join the top rule, it judges the merge's faces again. Not an argument:
    #: a copy by ``dataclasses.replace`` (another image, other gradients) starts empty.
    known: dict[tuple[object, ...], bool] = field(default_factory=dict, init=False,
                                                  compare=False, repr=False)


@dataclass(frozen=True, kw_only=True)
class Markings:
    """The outcome of :func:`find_markings`: ``markings``, indices of ellipses that are a
    marking or relief inside a whole face; ``marked``, indices of whole faces that failed the
    rule on interior edges alone and hold only markings."""

    markings: frozenset[int]
    marked: frozenset[int]


def whole_with_edges_inside(ev: OcclusionEvidence) -> bool:
    """No T-junction end, support >= ``top.min_support``, more interior edges than allowed: a
    face whose outline shows whole and that failed on interior edges alone."""
    return not ev.occluded_ends and not ev.weakly_supported and ev.edges_inside


def find_markings(ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
                  test: MarkingTest, radius_of: Callable[[Ellipse], float | None] | None,
                  edge_points: NDArray[np.float64] | None = None) -> Markings:
    """The markings and marked faces among ``ellipses`` (see the module docstring), given
    their top-rule ``evidence``, the ``test``'s settings and, when known, each ellipse's radius
    by its colour (``radius_of``). With the edge map's pixels ``edge_points`` ((M, 2) u, v),
    ring faces round their hole are judged too (:func:`ring_round_hole`)."""
    markings: set[int] = set()
    marked: set[int] = set()
    for f, ev in enumerate(evidence):
        if whole_with_edges_inside(ev) and (
                ev.interior_edge_px >= test.min_edge_share * ev.perimeter_px
                or ring_round_hole(ellipses[f], test, edge_points)):
            own, loose, blocked = _judge(f, ellipses, evidence, test, radius_of)
            markings.update(own)
            if not blocked and not _rim_of_two_surfaces(ellipses[f], test):
                marked.add(f)
                markings.update(loose)
    return Markings(markings=frozenset(markings), marked=frozenset(marked - markings))


def ring_round_hole(face: Ellipse, test: MarkingTest,
                    edge_points: NDArray[np.float64] | None) -> bool:
    """Whether ``face``'s interior edges (among ``edge_points``; False without them) are a
    hole's: at least ``ring_hole_share`` of them inside its concentric ellipse at
    ``ring_hole_scale`` of its semi-axes (``test.params``), or at the smallest kind's radius
    over the face's (read from its rim band's colour, else the largest radius) if that is
    less: an object lying on the face reads nearer, so no smaller (:func:`~stackpick_sim.
    vision.rings.hole_only`)."""
    if edge_points is None:
        return False
    return _kept(test, ("ring", face), lambda: _hole_only_at_size(face, test, edge_points))


def _hole_only_at_size(face: Ellipse, test: MarkingTest, edge_points: NDArray[np.float64]
                       ) -> bool:
    """:func:`ring_round_hole`'s verdict. The share inside the hole only shrinks with the
    hole, so the hole at ``ring_hole_scale`` is tried first and the face's rim band colour is
    read (for a smaller hole) only when that passes."""
    params = test.params
    if not hole_only(face, edge_points, test.margin_px, params.ring_hole_scale,
                     params.ring_hole_share):
        return False
    rim = None if test.rim_radius_of is None else test.rim_radius_of(face)
    scale = min(params.ring_hole_scale,
                min(test.radii) / (max(test.radii) if rim is None else rim))
    return scale == params.ring_hole_scale or hole_only(face, edge_points, test.margin_px,
                                                        scale, params.ring_hole_share)


def _judge(f: int, ellipses: Sequence[Ellipse], evidence: Sequence[OcclusionEvidence],
           test: MarkingTest, radius_of: Callable[[Ellipse], float | None] | None
           ) -> tuple[list[int], list[int], bool]:
    """For the whole face ``f``: its markings (wholly inside, not nearer), the failed fits
    across its outline (its markings too if nothing lies on it), and whether a face lies on
    it. Without the colours (or where they give None) an inner ellipse is read with the
    smallest radius and the face with the largest: the reading most in favour of an object.
    The face's radius is read from its rim band, not its middle, which an object lying on it
    can cover."""
    face = ellipses[f]
    rim = None if test.rim_radius_of is None else test.rim_radius_of(face)
    face_depth = (max(test.radii) if rim is None else rim) / face.a
    own: list[int] = []
    loose: list[int] = []
    blocked = False
    for i, e in enumerate(ellipses):
        if i == f:
            continue
        passes = not evidence[i].occluded
        if not (e.a < face.a and holds_centre(face, e)):
            blocked = blocked or _lies_across(e, evidence[i], face, test)
            continue
        r = None if radius_of is None else radius_of(e)
        farther = (min(test.radii) if r is None else r) / e.a >= test.depth_ratio * face_depth
        wholly = _kept(test, ("inside", e, face),
                       functools.partial(_inside, e, face, test.margin_px))
        if farther and wholly:
            own.append(i)
        elif passes or wholly:
            blocked = True  # a face of its own on it, or an object nearer than it
        elif _round_another_surface(face, e, evidence[i], test):
            blocked = True
        else:
            loose.append(i)  # a failed fit across its whole outline: no object's
    return own, loose, blocked


def _lies_across(other: Ellipse, evidence: OcclusionEvidence, face: Ellipse,
                 test: MarkingTest) -> bool:
    """Whether ``other`` (its top-rule ``evidence``), reaching into ``face``, is a face of its
    own lying on it: one that passes the rule, or a whole face with markings whose outline
    runs on across it (:func:`_crosses_over`)."""
    if math.hypot(other.cx - face.cx, other.cy - face.cy) >= other.a + face.a:
        return False  # too far apart to reach into it (_reaches_into's first test)
    if not evidence.occluded:
        return _reaches_into(other, face, test.margin_px)
    # Its verdict hangs on the evidence only through whether ``other`` is a whole face.
    return _kept(test, ("lies_across", other, face, whole_with_edges_inside(evidence)),
                 lambda: (_reaches_into(other, face, test.margin_px)
                          and _crosses_over(other, evidence, face, test)))


def _round_another_surface(face: Ellipse, inner: Ellipse, evidence: OcclusionEvidence,
                           test: MarkingTest) -> bool:
    """Whether ``face`` is a fit round the whole face ``inner`` (its top-rule ``evidence``)
    and another surface (:func:`two_surfaces`; False without the ``image``)."""
    if test.image is None or not whole_with_edges_inside(evidence):
        return False
    image = test.image
    return _kept(test, ("two_surfaces", face, inner),
                 lambda: two_surfaces(face, inner, image, test.margin_px, test.params))


def _rim_of_two_surfaces(face: Ellipse, test: MarkingTest) -> bool:
    """Whether more than ``max_off_rim_share`` (``test.params``) of ``face``'s rim band
    (:func:`rim_band`) is off its median colour (:func:`off_rim_share`; False without the
    ``image``): the face's fit runs round another surface, or another object lies across
    its rim."""
    if test.image is None:
        return False
    image = test.image
    return _kept(test, ("off_rim", face), lambda: (off_rim_share(face, image, test.params)
                                                   > test.params.max_off_rim_share))


def off_rim_share(face: Ellipse, image: NDArray[np.uint8],
                  params: MarkingParams = DEFAULT) -> float:
    """Share [0, 1] of ``face``'s rim band samples (:func:`rim_band`) in the (H, W, 3) RGB
    ``image`` whose colour is off the band's median colour: chromaticity farther than
    ``params.surface_chroma_tolerance`` (L1) from it, or brightness (channel sum) outside
    ``params.surface_brightness_range`` of it."""
    h, w = image.shape[:2]
    pix = np.rint(rim_band(face, params.rim_sample_scale)).astype(np.int64)
    np.clip(pix, 0, np.array([w - 1, h - 1]), out=pix)
    colours = image[pix[:, 1], pix[:, 0]].astype(np.float64)
    sums = np.maximum(colours.sum(axis=1), 1e-9)
    median = column_median(colours)
    median_sum = max(float(median.sum()), 1e-9)
    chroma = np.abs(colours / sums[:, None] - median / median_sum).sum(axis=1)
    lo, hi = params.surface_brightness_range
    ratio = sums / median_sum
    off = (chroma > params.surface_chroma_tolerance) | (ratio < lo) | (ratio > hi)
    return float(np.count_nonzero(off)) / len(off)


def _kept(test: MarkingTest, key: tuple[object, ...], verdict: Callable[[], bool]) -> bool:
    """The verdict kept in ``test.known`` under ``key``, computed (``verdict()``) the first
    time."""
    if key not in test.known:
        test.known[key] = verdict()
    return test.known[key]


def two_surfaces(face: Ellipse, inner: Ellipse, image: NDArray[np.uint8],
                 margin_px: float, params: MarkingParams = DEFAULT) -> bool:
    """Whether ``face``'s rim band (BAND_SAMPLES points at ``params.rim_sample_scale``) shows
    two surfaces in the (H, W, 3) RGB ``image``: the median colour of its points more than
    ``margin_px`` outside ``inner`` and that of those more than ``margin_px`` inside it differ
    in chromaticity by more than ``params.surface_chroma_tolerance``, or in brightness by a
    ratio outside ``params.surface_brightness_range`` (False with fewer than
    ``params.min_part_samples`` either side)."""
    # The two parts (inside ``inner`` by the margin, and not inside it beyond the margin) and
    # their median colours in one compiled pass (kernels_top.two_part_medians: the same
    # values as Ellipse.inside, the rounded and clamped pixels and column_median).
    t = math.radians(inner.angle_deg)
    both, own, other = kernels_top.two_part_medians(
        rim_band(face, params.rim_sample_scale), kernel_array(image, np.uint8),
        inner.cx, inner.cy,
        math.cos(t), math.sin(t),
        np.array([max(inner.a - margin_px, 1e-6), max(inner.b - margin_px, 1e-6)]),
        np.array([max(inner.a + margin_px, 1e-6), max(inner.b + margin_px, 1e-6)]),
        params.min_part_samples)
    if not both:
        return False
    own_sum, other_sum = max(float(own.sum()), 1e-9), max(float(other.sum()), 1e-9)
    chroma = float(np.abs(own / own_sum - other / other_sum).sum())
    lo, hi = params.surface_brightness_range
    return chroma > params.surface_chroma_tolerance or not lo <= other_sum / own_sum <= hi


def _crosses_over(other: Ellipse, evidence: OcclusionEvidence, face: Ellipse,
                  test: MarkingTest) -> bool:
    """Whether ``other``, a whole face that failed the rule on interior edges alone (its
    ``evidence``), crossing ``face`` (neither holds the other's centre), lies on it: where two
    faces overlap, the upper one's outline runs on as an edge across the lower one, whose own
    outline is hidden under it. So ``other`` lies on ``face`` when its outline samples
    inside ``face`` (by ``margin_px``) show consistent edge contrast
    (:mod:`~stackpick_sim.vision.contrast`) along at least ``crossing_min_support`` of them
    and ``face``'s samples inside ``other`` along less, each with at least
    ``min_part_samples`` samples there (``test.params``; False without the ``gradients``)."""
    if (test.gradients is None or not whole_with_edges_inside(evidence)
            or holds_centre(other, face) or holds_centre(face, other)):
        return False
    lines = outlines([other, face])
    shown = contrast_profiles(lines, test.gradients) >= contrast_threshold(test.gradients)
    split = int(lines.offsets[1])
    over = face.inside(lines.points[:split], test.margin_px)
    under = other.inside(lines.points[split:], test.margin_px)
    if min(int(over.sum()), int(under.sum())) < test.params.min_part_samples:
        return False
    return (float(shown[:split][over].mean()) >= test.params.crossing_min_support
            > float(shown[split:][under].mean()))


@functools.lru_cache(maxsize=1024)
def rim_band(face: Ellipse, scale: float = DEFAULT.rim_sample_scale) -> NDArray[np.float64]:
    """(BAND_SAMPLES, 2) pixels of ``face``'s rim band (its ellipse at ``scale`` of its
    semi-axes, :attr:`MarkingParams.rim_sample_scale`); each face's once (read-only: shared
    by the tests that read it)."""
    band = Ellipse.of(face.cx, face.cy, scale * face.a, scale * face.b,
                      face.angle_deg).points(BAND_SAMPLES)
    band.setflags(write=False)
    return band


def inside_rim_band(inner: Ellipse, face: Ellipse, margin_px: float,
                    scale: float = DEFAULT.rim_sample_scale) -> bool:
    """Whether no point of ``face``'s rim band (:func:`rim_band` at ``scale``) lies inside
    ``inner`` by more than ``margin_px``: ``inner`` lies within the band (a fit on an arc of
    the face's outline and its artwork does; a face that a larger fit runs round, beyond it on
    its wall or a lower face, reaches into the larger fit's band where their outlines run
    together)."""
    return not bool(kernels_top.inside(inner, rim_band(face, scale), margin_px).any())


@functools.lru_cache(maxsize=1024)
def _outline(ellipse: Ellipse) -> NDArray[np.float64]:
    """``ellipse``'s INSIDE_SAMPLES outline points (shared: not to be modified); each
    ellipse's once, a face being judged against every other."""
    return ellipse.points(INSIDE_SAMPLES)


def _reaches_into(other: Ellipse, face: Ellipse, margin_px: float) -> bool:
    """Whether any of ``other``'s outline (INSIDE_SAMPLES points) lies inside ``face`` by more
    than ``margin_px`` (never when their centres lie farther apart than their semi-major
    axes together)."""
    if math.hypot(other.cx - face.cx, other.cy - face.cy) >= other.a + face.a:
        return False
    return bool(kernels_top.inside(face, _outline(other), margin_px).any())


def _inside(inner: Ellipse, face: Ellipse, margin_px: float) -> bool:
    """Whether ``inner``'s whole outline (INSIDE_SAMPLES points) lies inside ``face`` by more
    than ``margin_px``."""
    return bool(kernels_top.inside(face, _outline(inner), margin_px).all())


def holds_centre(outer: Ellipse, inner: Ellipse) -> bool:
    """Whether ``inner``'s centre lies inside ``outer``."""
    t = math.radians(outer.angle_deg)
    du, dv = inner.cx - outer.cx, inner.cy - outer.cy
    x = (math.cos(t) * du + math.sin(t) * dv) / outer.a
    y = (-math.sin(t) * du + math.cos(t) * dv) / outer.b
    return x * x + y * y < 1.0

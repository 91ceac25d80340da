"""Edge contrast along a predicted ellipse, read from the gradients rather than the edge map.

Canny keeps an edge only where its gradient passes a global threshold, so the boundary between
two faces of the same colour and nearly the same shade (common in the simulator: two orange
cylinders under one ring light) drops out of the edge map, and a fully visible top face looks
"gapped" exactly where it lies over its neighbour. Once an ellipse is hypothesised, a much
weaker edge can be trusted if it is *consistent*: the gradient component along the ellipse
normal keeps one sign along a stretch of boundary, while noise flips sign at random and
averages out. The profile here is that signed normal gradient, averaged over a short window
of the outline, in grey levels per pixel.

An arc hidden under another object runs through that object's smooth face: its profile stays
at the noise level, so hidden arcs remain gaps.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import TopParams
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.edges import SOBEL_GAIN, EdgeImage
from stackpick_sim.vision.fitting import fit_ellipse

#: The normal gradient is read at these offsets (px) across the outline; the strongest wins,
#: absorbing sub-pixel fit error and the blur's spread of the edge.
NORMAL_OFFSETS_PX: tuple[float, ...] = (-1.0, 0.0, 1.0)
#: Window (samples, ~1 px each) of the signed average: noise drops by sqrt(5) ~ 2.2x while
#: a 5 px gap of an occluded arc still shows.
WINDOW_SAMPLES = 5


def perimeter_px(ellipse: Ellipse) -> float:
    """Ramanujan's approximation of the ellipse's perimeter, px."""
    a, b = ellipse.a, ellipse.b
    h = ((a - b) / (a + b)) ** 2
    return math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))


@functools.lru_cache(maxsize=1024)
def unit_circle(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(cos t, sin t), each (n,), of n parameters t evenly spaced on [0, 2 pi) (read-only;
    cached: outlines of a few hundred sizes are sampled many times a frame, and float64
    trigonometry costs ~10 ns a value)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ct, st = np.cos(t), np.sin(t)
    ct.setflags(write=False)
    st.setflags(write=False)
    return ct, st


def outline(ellipse: Ellipse) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(n, 2) points about 1 px apart along the ellipse and their (n, 2) unit outward normals."""
    n = max(16, math.ceil(perimeter_px(ellipse)))
    th = math.radians(ellipse.angle_deg)
    c, s = math.cos(th), math.sin(th)
    ct, st = unit_circle(n)
    x, y = ellipse.a * ct, ellipse.b * st
    pts = np.stack([ellipse.cx + c * x - s * y, ellipse.cy + s * x + c * y], axis=1)
    nx, ny = ellipse.b * ct, ellipse.a * st  # gradient of the implicit form, scaled by a*b
    norm = np.hypot(nx, ny)
    nx, ny = nx / norm, ny / norm
    normals = np.stack([c * nx - s * ny, s * nx + c * ny], axis=1)
    return pts, normals


def outline_columns(ellipse: Ellipse) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                               NDArray[np.float64], NDArray[np.float64]]:
    """:func:`outline` of ``ellipse`` (the same values) as four (n,) columns: points u, v
    and unit outward normals nu, nv, in one compiled pass (kernels.outline_columns: the same
    arithmetic as the array form)."""
    n = max(16, math.ceil(perimeter_px(ellipse)))
    th = math.radians(ellipse.angle_deg)
    ct, st = unit_circle(n)
    return kernels.outline_columns(ellipse.cx, ellipse.cy, ellipse.a, ellipse.b,
                                   math.cos(th), math.sin(th), ct, st)


def contrast_profile(ellipse: Ellipse, image: EdgeImage,
                     samples: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
                     ) -> NDArray[np.float64]:
    """(n,) windowed |signed normal gradient| (grey levels/px) along the outline samples.

    Samples whose neighbourhood leaves the image read 0 (unseen). ``samples`` is
    :func:`outline` of the ellipse when the caller has it already.
    """
    pts, normals = outline(ellipse) if samples is None else samples
    h, w = image.gx.shape
    offsets = np.asarray(NORMAL_OFFSETS_PX)[:, None, None]
    q = np.rint(pts[None, :, :] + offsets * normals[None, :, :]).astype(np.int64)  # (k, n, 2)
    u, v = q[..., 0], q[..., 1]
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    np.clip(u, 0, w - 1, out=u)
    np.clip(v, 0, h - 1, out=v)
    g = image.gx[v, u] * normals[None, :, 0] + image.gy[v, u] * normals[None, :, 1]
    g = np.where(inside, g, 0.0)
    # The strongest offset per sample (the first of equals, as a running strict maximum).
    best = np.take_along_axis(g, np.argmax(np.abs(g), axis=0)[None, :], axis=0)[0]
    k = WINDOW_SAMPLES
    padded = np.concatenate([best[-(k // 2):], best, best[: k // 2]])
    smooth = np.convolve(padded, np.ones(k) / k, mode="valid")
    return np.abs(smooth) / SOBEL_GAIN


#: NORMAL_OFFSETS_PX as the compiled pass takes them.
_OFFSETS = np.array(NORMAL_OFFSETS_PX, np.float64)


@functools.lru_cache(maxsize=1024)
def _window_table(n: int) -> NDArray[np.int64]:
    """(WINDOW_SAMPLES, n) index along an outline of n samples of each sample's window, rows
    as :attr:`Outlines.window`'s (read-only; cached like :func:`unit_circle`)."""
    half = WINDOW_SAMPLES // 2
    shifts = np.array([0, *range(-half, 0), *range(1, half + 1)], np.int64)
    table = (np.arange(n, dtype=np.int64) + shifts[:, None]) % n
    table.setflags(write=False)
    return table


@dataclass(frozen=True, kw_only=True)
class Outlines:
    """The :func:`outline` samples of several ellipses, concatenated.

    ``points``, ``normals``: (N, 2) px and unit outward normals; ``offsets``: (E + 1,) int,
    ellipse e owns samples ``offsets[e]:offsets[e + 1]``; ``box``: (u_min, v_min, u_max,
    v_max) px, the ellipses' bounding box (every sample lies in it, up to rounding).
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    offsets: NDArray[np.int64]
    box: tuple[float, float, float, float]

    @functools.cached_property
    def counts(self) -> NDArray[np.int64]:
        """(E,) samples per ellipse."""
        return np.asarray(self.offsets[1:] - self.offsets[:-1], np.int64)

    @functools.cached_property
    def owner(self) -> NDArray[np.int64]:
        """(N,) ellipse index of each sample."""
        return np.arange(self.counts.size, dtype=np.int64).repeat(self.counts)

    @functools.cached_property
    def local(self) -> NDArray[np.int64]:
        """(N,) each sample's index along its own outline."""
        return np.arange(int(self.offsets[-1]), dtype=np.int64) - self.offsets[self.owner]

    @functools.cached_property
    def _starts_and_counts(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(N,) first sample and sample count of each sample's own outline."""
        return self.offsets[self.owner], self.counts[self.owner]

    @functools.cached_property
    def window(self) -> NDArray[np.int64]:
        """(WINDOW_SAMPLES, N) index of the samples of each sample's window along its own
        outline: row 0 the sample itself, then the shifts -W//2 .. -1, 1 .. W//2 (for W =
        WINDOW_SAMPLES) in that order (the order of a running sum)."""
        counts = self.counts
        tables = [_window_table(n) for n in counts.tolist()]
        if not tables:
            return np.zeros((WINDOW_SAMPLES, 0), np.int64)
        return np.concatenate(tables, axis=1) + self.offsets[:-1].repeat(counts)

    def cyclic(self, shift: int) -> NDArray[np.int64]:
        """(N,) index of the sample ``shift`` steps further along each sample's own outline."""
        counts = self.counts
        if counts.size and abs(shift) >= int(counts.min()):
            starts, each = self._starts_and_counts
            return np.asarray(starts + (self.local + shift) % each, np.int64)
        # Every sample but the |shift| at an outline's end (start) moves by shift; those wrap.
        index = np.arange(int(self.offsets[-1]), dtype=np.int64) + shift
        for j in range(abs(shift)):
            if shift > 0:
                index[self.offsets[1:] - 1 - j] -= counts
            else:
                index[self.offsets[:-1] + j] += counts
        return index


def outline_rows(ellipses: Sequence[Ellipse]
                 ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64],
                            NDArray[np.float64]]:
    """What the compiled passes over the :func:`outline` samples of several ellipses take:
    (E, 6) rows (cx, cy, a, b and the angle's cosine and sine), the (E,) sample counts and
    the cosines and sines of every sample's parameter (ellipse by ellipse); the rows and
    counts in one compiled pass (kernels.outline_rows: :func:`perimeter_px`'s arithmetic)."""
    sizes, rows = kernels.outline_rows(np.array(
        [(e.cx, e.cy, e.a, e.b, e.angle_deg) for e in ellipses], np.float64).reshape(-1, 5))
    if not ellipses:
        return rows, sizes, np.zeros(0), np.zeros(0)
    tables = [unit_circle(n) for n in sizes.tolist()]
    return (rows, sizes, np.concatenate([t[0] for t in tables]),
            np.concatenate([t[1] for t in tables]))


def outlines(ellipses: Sequence[Ellipse]) -> Outlines:
    """:func:`outline` of every ellipse in one pass (the same samples, concatenated)."""
    rows, sizes, ct, st = outline_rows(ellipses)
    offsets = np.zeros(sizes.shape[0] + 1, np.int64)
    np.cumsum(sizes, out=offsets[1:])
    u0 = v0 = math.inf
    u1 = v1 = -math.inf
    for cx, cy, a, b, c, s in rows.tolist():
        hw, hh = math.hypot(a * c, b * s), math.hypot(a * s, b * c)
        u0, v0 = min(u0, cx - hw), min(v0, cy - hh)
        u1, v1 = max(u1, cx + hw), max(v1, cy + hh)
    # Points cx + c x - s y, cy + s x + c y (x = a cos t, y = b sin t) and the unit normals
    # of the implicit form's gradient (b cos t, a sin t), rotated: one compiled pass, as
    # (2, N) arrays (the (N, 2) views below have contiguous columns).
    pts, normals = kernels.outline_samples(rows, sizes, ct, st)
    return Outlines(points=pts.T, normals=normals.T, offsets=offsets, box=(u0, v0, u1, v1))


#: The window's shifts along the outline, in :attr:`Outlines.window`'s row order.
_SHIFTS = np.array([0, *range(-(WINDOW_SAMPLES // 2), 0), *range(1, WINDOW_SAMPLES // 2 + 1)],
                   np.int64)


def supported_samples(rows: tuple[NDArray[np.float64], NDArray[np.int64],
                                   NDArray[np.float64], NDArray[np.float64]],
                      image: EdgeImage) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The (2, N) :func:`outlines` samples of the ellipses of ``rows`` (:func:`outline_rows`)
    and which of them show a consistent edge (:func:`contrast_support`),
    in one compiled pass (kernels_pose.contrast_ok: the samples of :func:`outlines`, the
    profile of :func:`contrast_profiles`, the same values)."""
    table, sizes, ct, st = rows
    return kernels_pose.contrast_ok(table, sizes, ct, st, image.gx, image.gy, _OFFSETS,
                                    _SHIFTS, SOBEL_GAIN, contrast_threshold(image))


def contrast_profiles(lines: Outlines, image: EdgeImage) -> NDArray[np.float64]:
    """(N,) :func:`contrast_profile` of every outline of ``lines`` in one pass (the same
    values: every offset of every sample read in one gather, the window summed from
    :attr:`Outlines.window`)."""
    # One compiled pass (kernels.outline_contrasts: the same values as the array form).
    pts, normals = lines.points, lines.normals
    return kernels.outline_contrasts(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
        np.ascontiguousarray(normals[:, 0]), np.ascontiguousarray(normals[:, 1]),
        image.gx, image.gy, _OFFSETS, lines.window, SOBEL_GAIN)


def contrast_threshold(image: EdgeImage) -> float:
    """Grey levels/px a boundary sample needs to count as supported (the image's
    ``support_noise_multiple`` times its noise level, at least ``support_min_contrast``:
    :class:`~stackpick_sim.config.vision_params.EdgeParams`)."""
    params = image.params
    return max(params.support_min_contrast, params.support_noise_multiple * image.noise)


def contrast_support(ellipse: Ellipse, image: EdgeImage,
                     samples: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
                     ) -> NDArray[np.bool_]:
    """(n,) bool per outline sample: does a consistent edge run there (``samples``: the
    ellipse's :func:`outline`, if already computed)."""
    return contrast_profile(ellipse, image, samples) >= contrast_threshold(image)


#: The default settings of the contrast refit (the ``contrast_*`` fields of TopParams: the
#: reasons for each).
REFIT_DEFAULT = TopParams()


def refit_on_contrast(ellipse: Ellipse, image: EdgeImage, innermost: bool = False,
                      params: TopParams = REFIT_DEFAULT, *, inner_reach_px: int | None = None,
                      rounds: int | None = None) -> Ellipse | None:
    """Refit ``ellipse`` on the strongest consistent edge within ``params.contrast_reach_px``
    across each outline sample, or None when less than ``params.contrast_min_share`` of the
    outline shows one (in ``params.contrast_rounds`` rounds).

    Unlike the edge-map refit (:func:`~stackpick_sim.vision.refine.refine`) this sees edges
    too faint for Canny's global threshold, such as the boundary between two faces of one
    colour, so a face fitted mostly on its strong arcs can find its faint arcs too.

    With ``innermost`` each sample takes the innermost local peak of the contrast that
    passes the threshold instead of the strongest: a top face over a lower face of its own
    colour ends at a faint boundary just inside the lower face's strong silhouette, and a fit
    on both outlines is too large. The search then reaches ``params.contrast_inner_reach_px``
    inward (``inner_reach_px``, when given: the inner refit's reach). ``rounds``, when given,
    stands for ``params.contrast_rounds`` (both without building another TopParams, whose
    range checks cost several times the refit's round).
    """
    current = ellipse
    reach = params.contrast_reach_px
    inward = ((params.contrast_inner_reach_px if inner_reach_px is None else inner_reach_px)
              if innermost else reach)
    offsets = np.arange(-inward, reach + 1, dtype=np.float64)
    threshold = contrast_threshold(image)
    for _ in range(params.contrast_rounds if rounds is None else rounds):
        pu, pv, nu, nv = outline_columns(current)
        # The offsets' gradients, their windowed means and each sample's pick, in one
        # compiled pass (kernels.contrast_peaks: the same values as the array form).
        found = kernels.contrast_peaks(pu, pv, nu, nv, image.gx, image.gy, offsets,
                                       WINDOW_SAMPLES, SOBEL_GAIN, threshold, innermost)
        if found.shape[0] < params.contrast_min_share * pu.shape[0]:
            return None
        fit = fit_ellipse(found)
        if fit is None:
            return None
        current = fit
    return current


def widest_inset_px(outer: Ellipse, inner: Ellipse) -> float:
    """How far (px) ``outer``'s outline reaches beyond ``inner`` at most, measured along the
    rays from ``inner``'s centre (negative when it lies wholly inside): the width of the
    widest sliver a fit ``outer`` takes in beyond a face ``inner``."""
    pts, _ = outline(outer)
    th = math.radians(inner.angle_deg)
    c, s = math.cos(th), math.sin(th)
    dx, dy = pts[:, 0] - inner.cx, pts[:, 1] - inner.cy
    # The point's distance from the centre times (1 - 1/r), r its ellipse "radius" in
    # inner's axes: the distance along the ray beyond inner's outline.
    r = np.hypot((c * dx + s * dy) / inner.a, (c * dy - s * dx) / inner.b)
    beyond = np.hypot(dx, dy) * (1.0 - 1.0 / np.maximum(r, 1e-9))
    return float(beyond.max())

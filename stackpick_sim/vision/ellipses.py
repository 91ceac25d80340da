"""Ellipses only: the detector's ellipse stages on any image, each ellipse scored.

:func:`find_ellipses` runs edges, segments, fits, merge and the edge refit on the whole image
(no region of interest, no top rule, no pose) and reports an ellipse only when a consistent
edge runs along enough of its outline: the signed gradient across the outline, averaged over
a few samples (:mod:`~stackpick_sim.vision.contrast`), must reach the image's noise-relative
contrast threshold along ``min_support`` of it. Arcs of texture, glyphs and reliefs fit
ellipses whose outlines leave the arcs they were fitted on after a short stretch: their
support stays low, while a whole or mostly visible rim keeps it high. The outline of a thin
stroke (a letter O, a printed ring, an embossed contour) is supported too; it is rejected by
its other edge, of the opposite polarity, running alongside (``max_stroke_share`` of
:class:`~stackpick_sim.config.vision_params.EllipsesParams`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import EllipsesParams
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.contrast import contrast_profiles, contrast_threshold, outlines
from stackpick_sim.vision.edges import (
    MIN_SIDE_PX,
    SOBEL_GAIN,
    EdgeImage,
    as_rgb_or_gray,
    edge_image,
)
from stackpick_sim.vision.fitting import fit_all
from stackpick_sim.vision.limits import (
    WorkLimits,
    downscale_factor,
    downscaled,
    longest,
    upscaled,
)
from stackpick_sim.vision.merging import merge_segments
from stackpick_sim.vision.refine import edge_points, refine_all


@dataclass(frozen=True, kw_only=True)
class ScoredEllipse:
    """One ellipse of :func:`find_ellipses`.

    ``support``: share (0-1) of its outline along which a consistent edge runs (the score);
    ``edge_support``: share with an edge pixel within 1 px; ``residual_px``: RMS distance of
    the edge segments it was merged from.
    """

    ellipse: Ellipse
    support: float
    edge_support: float
    residual_px: float

    def as_dict(self) -> dict[str, float]:
        """JSON-friendly {cx, cy, a, b, angle_deg, support, edge_support, residual_px}."""
        return {**self.ellipse.as_dict(), "support": self.support,
                "edge_support": self.edge_support, "residual_px": self.residual_px}


def find_ellipses(image: NDArray, *, min_axis_px: float = 5.0,
                  max_axis_px: float | None = None, min_support: float = 0.6,
                  limits: WorkLimits | None = None,
                  params: EllipsesParams | None = None) -> list[ScoredEllipse]:
    """Ellipses in an (H, W) or (H, W, 3) RGB image, best-supported first.

    ``min_axis_px``: smallest semi-minor axis, px; ``max_axis_px``: largest semi-major axis,
    px (None: the image's diagonal); ``min_support``: smallest share (0-1) of the outline with
    a consistent edge along it (see the module docstring); ``limits``: the work caps
    (:class:`~stackpick_sim.vision.limits.WorkLimits`; an image beyond ``max_pixels`` is
    searched downscaled and the ellipses mapped back, the axis bounds applying in the full
    image's pixels); ``params``: the scoring's settings (:class:`~stackpick_sim.config.
    vision_params.EllipsesParams`, the scene's ``[vision.ellipses]``). ConfigError for
    bounds out of range, ImageError for input that is not an image.
    """
    _check_bounds(min_axis_px, max_axis_px, min_support)
    limits = limits or WorkLimits()
    img = as_rgb_or_gray(image)
    factor = downscale_factor((int(img.shape[0]), int(img.shape[1])), limits.max_pixels)
    work = img if factor == 1 else downscaled(img, factor)
    if min(work.shape[:2]) < MIN_SIDE_PX:
        return []
    params = params or EllipsesParams()
    found, grad = _scored(work, limits, params)
    top = np.inf if max_axis_px is None else max_axis_px
    found = [s for s in found if s.ellipse.b * factor >= min_axis_px
             and s.ellipse.a * factor <= top and s.support >= min_support]
    found = [s for s, stroke in zip(found, _stroke_shares(found, grad, params), strict=True)
             if stroke <= params.max_stroke_share]
    if factor > 1:
        found = [ScoredEllipse(ellipse=upscaled(s.ellipse, factor), support=s.support,
                               edge_support=s.edge_support,
                               residual_px=s.residual_px * factor) for s in found]
    return found


def _check_bounds(min_axis_px: float, max_axis_px: float | None, min_support: float) -> None:
    """ConfigError for :func:`find_ellipses`' bounds out of range."""
    if not min_axis_px > 0 or (max_axis_px is not None and not max_axis_px >= min_axis_px):
        raise ConfigError(f"find_ellipses: need 0 < min_axis_px <= max_axis_px, got "
                          f"{min_axis_px}, {max_axis_px}")
    if not 0.0 <= min_support <= 1.0:
        raise ConfigError(f"find_ellipses: min_support must be 0-1, got {min_support}")


def _aligned(points: NDArray[np.float64], normals: NDArray[np.float64],
             gx: NDArray[np.int16], gy: NDArray[np.int16], min_cos: float
             ) -> NDArray[np.bool_]:
    """(N,) bool per outline sample: the gradient at its pixel lies within the cone of its
    normal (either way) whose half-angle's cosine is ``min_cos``."""
    h, w = gx.shape
    u = np.clip(np.rint(points[:, 0]), 0, w - 1).astype(np.int64)
    v = np.clip(np.rint(points[:, 1]), 0, h - 1).astype(np.int64)
    g0, g1 = gx[v, u].astype(np.float64), gy[v, u].astype(np.float64)
    dot = g0 * normals[:, 0] + g1 * normals[:, 1]
    return np.asarray(dot * dot >= min_cos ** 2 * (g0 * g0 + g1 * g1))


def _normal_gradient(points: NDArray[np.float64], normals: NDArray[np.float64],
                     grad: EdgeImage, offset: float) -> NDArray[np.float64]:
    """(N,) signed gradient along the normal (Sobel units) at the pixel nearest each outline
    sample moved ``offset`` px along its normal; 0 off the image."""
    h, w = grad.gx.shape
    q = np.rint(points + offset * normals).astype(np.int64)
    inside = (q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < h)
    u, v = np.clip(q[:, 0], 0, w - 1), np.clip(q[:, 1], 0, h - 1)
    g = grad.gx[v, u] * normals[:, 0] + grad.gy[v, u] * normals[:, 1]
    return np.where(inside, g, 0.0)


def _stroke_shares(found: list[ScoredEllipse], grad: EdgeImage, params: EllipsesParams
                   ) -> list[float]:
    """Per ellipse, the share of its supported outline samples along which a stroke's other
    edge runs: an edge of the opposite polarity, at least ``stroke_min_ratio`` as strong as
    the outline's own, between 2 px and the stroke reach outside or inside (see
    :class:`~stackpick_sim.config.vision_params.EllipsesParams`). A disc's rim has none
    along most of it; the two edges of a glyph's or a printed ring's stroke run side by
    side."""
    reach = [min(params.stroke_reach_px, params.stroke_reach_axis * s.ellipse.b)
             for s in found]
    if not found or params.stroke_reach_px < 2.0:
        return [0.0] * len(found)
    lines = outlines([s.ellipse for s in found])
    pts, normals = lines.points, lines.normals
    strong = contrast_profiles(lines, grad) >= contrast_threshold(grad)
    near = np.stack([_normal_gradient(pts, normals, grad, d) for d in (-1.0, 0.0, 1.0)])
    rim = np.take_along_axis(near, np.argmax(np.abs(near), axis=0)[None, :], axis=0)[0]
    floor = np.maximum(params.stroke_min_ratio * np.abs(rim),
                       contrast_threshold(grad) * SOBEL_GAIN)
    sample_reach = np.repeat(np.asarray(reach), lines.counts)
    partner = np.zeros(rim.shape, np.bool_)
    for step in range(2, int(params.stroke_reach_px) + 1):
        for d, within in ((step, True), (-step, step <= sample_reach)):
            g = _normal_gradient(pts, normals, grad, float(d))
            partner |= (g * rim < 0) & (np.abs(g) >= floor) & within
    both = np.add.reduceat((partner & strong).astype(np.float64), lines.offsets[:-1])
    supported = np.add.reduceat(strong.astype(np.float64), lines.offsets[:-1])
    return (both / np.maximum(supported, 1.0)).tolist()


def _scored(work: NDArray[np.uint8], limits: WorkLimits, params: EllipsesParams
            ) -> tuple[list[ScoredEllipse], EdgeImage]:
    """Every merged and refitted ellipse of ``work`` with its scores, best first, and the
    image's edges and gradients."""
    from stackpick_sim.vision.segments import link_segments

    shape = (int(work.shape[0]), int(work.shape[1]))
    grad = edge_image(work)
    chains = link_segments(grad.edges, limits.max_chains).chains
    chains = tuple(chains[i] for i in longest(chains, limits.max_chains))
    fitted = fit_all(chains, shape)
    fitted = [fitted[i] for i in longest([f[1] for f in fitted], limits.max_fits)]
    pieces = tuple(points for _, points, _, _ in fitted)
    merged = merge_segments(pieces + chains,
                            [(k, e) for k, (_, _, e, _) in enumerate(fitted)], grad.edges,
                            [r for _, _, _, r in fitted])[:limits.max_ellipses]
    if not merged:
        return [], grad
    points, grads = edge_points(grad)
    refined = refine_all([m.ellipse for m in merged], points, grads, shape)
    lines = outlines(refined)
    strong = contrast_profiles(lines, grad) >= contrast_threshold(grad)
    strong &= _aligned(lines.points, lines.normals, grad.gx, grad.gy, params.min_normal_cos)
    shares = np.add.reduceat(strong.astype(np.float64), lines.offsets[:-1])
    sizes = np.diff(lines.offsets)
    out = [ScoredEllipse(ellipse=e, support=float(k / n), edge_support=m.support,
                         residual_px=m.residual_px)
           for e, m, k, n in zip(refined, merged, shares.tolist(), sizes.tolist(), strict=True)]
    return sorted(out, key=lambda s: -s.support), grad

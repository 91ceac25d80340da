"""Ellipses only: the detector's ellipse stages on any image, each ellipse scored.

:func:`find_ellipses` runs edges, segments, fits, merge and the edge refit on the whole image
(no region of interest, no top rule, no pose) and reports an ellipse only when a consistent
edge runs along enough of its outline: the signed gradient across the outline, averaged over
a few samples (:mod:`~stackpick_sim.vision.contrast`), must reach the image's noise-relative
contrast threshold along ``min_support`` of it. Arcs of texture, glyphs and reliefs fit
ellipses whose outlines leave the arcs they were fitted on after a short stretch: their
support stays low, while a whole or mostly visible rim keeps it high.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import EllipsesParams
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.contrast import contrast_profiles, contrast_threshold, outlines
from stackpick_sim.vision.edges import MIN_SIDE_PX, as_rgb_or_gray, edge_image
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
    found = _scored(work, limits, params or EllipsesParams())
    if factor > 1:
        found = [ScoredEllipse(ellipse=upscaled(s.ellipse, factor), support=s.support,
                               edge_support=s.edge_support,
                               residual_px=s.residual_px * factor) for s in found]
    top = np.inf if max_axis_px is None else max_axis_px
    return [s for s in found if s.ellipse.b >= min_axis_px and s.ellipse.a <= top
            and s.support >= min_support]


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


def _scored(work: NDArray[np.uint8], limits: WorkLimits, params: EllipsesParams
            ) -> list[ScoredEllipse]:
    """Every merged and refitted ellipse of ``work`` with its scores, best first."""
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
        return []
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
    return sorted(out, key=lambda s: -s.support)

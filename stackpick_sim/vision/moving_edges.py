"""Tracking-mode measurement of a known face: its outline searched for around the prediction.

Once a face is tracked its ellipse in the next frame is known to a few pixels. Where the
detector misses it (on the approach a top face often overlaps faces of its own colour, and
its outline's contrast drops below what whole-image edge linking keeps), the outline can
still be found by looking only where it should be: ViSP's moving edges (``vpMeEllipse``,
Marchand et al.). Along the normal of the predicted ellipse at ``samples`` points the
grey level's derivative is sampled over +-``search_px``; the strongest step above
``min_step`` is the outline there. A direct least-squares ellipse fit on those points,
refit without the ones far from it, is the measurement; it is accepted only if most
samples found an edge close to it and it keeps the predicted size and place. The settings:
:class:`~stackpick_sim.config.vision_params.OutlineTrackingParams` (the scene's
``[episode.outline]`` table).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import OutlineTrackingParams
from stackpick_sim.geometry import Ellipse

FloatArray = NDArray[np.float64]

#: The default settings (see OutlineTrackingParams: the reasons for each).
DEFAULT = OutlineTrackingParams()


def _normals(e: Ellipse, n: int) -> tuple[FloatArray, FloatArray]:
    """(n, 2) outline points and (n, 2) unit outward normals of ``e``."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    th = math.radians(e.angle_deg)
    c, s = math.cos(th), math.sin(th)
    x, y = e.a * np.cos(t), e.b * np.sin(t)
    pts = np.stack([e.cx + c * x - s * y, e.cy + s * x + c * y], axis=1)
    nx, ny = np.cos(t) / e.a, np.sin(t) / e.b  # gradient of the implicit form, ellipse frame
    nrm = np.stack([c * nx - s * ny, s * nx + c * ny], axis=1)
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _edge_points(gray: NDArray[np.float32], e: Ellipse, search_px: float,
                 params: OutlineTrackingParams) -> FloatArray:
    """(m, 2) strongest grey-level steps along the normals of ``e`` within +-``search_px``
    (at ``params.samples`` points, at least ``params.min_step``)."""
    pts, nrm = _normals(e, params.samples)
    offsets = np.arange(-search_px, search_px + 0.5, 1.0)
    grid = pts[:, None, :] + offsets[None, :, None] * nrm[:, None, :]  # (S, K, 2)
    h, w = gray.shape
    inside = ((grid[..., 0] >= 1) & (grid[..., 0] <= w - 2) & (grid[..., 1] >= 1)
              & (grid[..., 1] <= h - 2)).all(axis=1)
    mx = grid[..., 0].astype(np.float32)
    my = grid[..., 1].astype(np.float32)
    prof = cv2.remap(gray, mx, my, cv2.INTER_LINEAR).astype(np.float64)  # (S, K)
    step = np.abs(prof[:, 2:] - prof[:, :-2]) / 2.0  # central difference, per px
    best = np.argmax(step, axis=1)
    strong = step[np.arange(len(best)), best] >= params.min_step
    keep = inside & strong
    s = offsets[1:-1][best]
    return np.asarray((pts + s[:, None] * nrm)[keep])


def _fit(points: FloatArray) -> Ellipse | None:
    if len(points) < 6:
        return None
    try:
        (cx, cy), (w, h), ang = cv2.fitEllipseDirect(points.astype(np.float32))
    except cv2.error:
        return None
    if not (w > 0 and h > 0 and math.isfinite(cx) and math.isfinite(cy)):
        return None
    if w >= h:
        return Ellipse(cx=cx, cy=cy, a=w / 2.0, b=h / 2.0, angle_deg=ang % 180.0)
    return Ellipse(cx=cx, cy=cy, a=h / 2.0, b=w / 2.0, angle_deg=(ang + 90.0) % 180.0)


def _distances(e: Ellipse, points: FloatArray) -> FloatArray:
    """Approximate distance (px) of ``points`` (m, 2) to ``e``: algebraic over gradient."""
    c = e.conic()
    h = np.c_[points, np.ones(len(points))]
    f = np.einsum("ij,jk,ik->i", h, c, h)
    g = 2.0 * (h @ c[:, :2])
    return np.asarray(np.abs(f) / np.maximum(np.linalg.norm(g, axis=1), 1e-12))


def track_outline(gray: NDArray[np.float32], predicted: Ellipse,
                  search_px: float | None = None,
                  params: OutlineTrackingParams = DEFAULT) -> Ellipse | None:
    """The face's ellipse found around ``predicted`` in ``gray``, or None.

    ``gray`` (H, W) float32 grey levels 0-255 (smoothed by the caller), ``predicted`` the
    tracked face's ellipse at the frame's capture (px), ``search_px`` how far the outline
    may be from it along its normals (None: ``params.search_px``); ``params``: the search's
    and the acceptance tests' settings.
    """
    if search_px is None:
        search_px = params.search_px
    points = _edge_points(gray, predicted, search_px, params)
    fit = _fit(points)
    for _ in range(2):
        if fit is None:
            return None
        inliers = points[_distances(fit, points) <= params.inlier_px]
        fit = _fit(inliers)
    if fit is None:
        return None
    # A final search close to the fit itself, then the acceptance tests.
    points = _edge_points(gray, fit, params.close_search_px, params)
    fit2 = _fit(points)
    if fit2 is None:
        return None
    inl = _distances(fit2, points) <= params.inlier_px
    fit2 = _fit(points[inl]) if inl.sum() >= 6 else None
    if fit2 is None or inl.sum() < params.min_inlier_share * params.samples:
        return None
    tolerance = params.size_tolerance
    if (abs(fit2.a - predicted.a) > tolerance * predicted.a
            or abs(fit2.b - predicted.b) > tolerance * predicted.a
            or math.hypot(fit2.cx - predicted.cx, fit2.cy - predicted.cy) > search_px):
        return None
    return fit2

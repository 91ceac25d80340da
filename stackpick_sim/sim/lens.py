"""Lens distortion of the wrist camera: a pinhole render warped by Brown-Conrady coefficients.

MuJoCo renders an ideal pinhole. A barrel-distorted image (k1 < 0) sees farther out than the
pinhole of the same focal length, so the render is made :func:`render_padding` pixels larger
on every side (same focal length and principal point, a wider field of view) and each
distorted pixel takes its value from where the pinhole image has that ray
(``cv2.undistortPoints`` of the distorted pixel grid, iterated to convergence, then ``cv2.remap``).
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics

#: Iterations and tolerance of cv2.undistortPoints (normalised units): ample for |k1| <= 1.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-6)
#: Extra pixels of render around the farthest ray the distorted image needs (bilinear taps).
_PAD_MARGIN_PX = 2


def _grid(width: int, height: int) -> NDArray[np.float64]:
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def undistorted_pixels(k: CameraIntrinsics, pixels: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 2) distorted pixels of camera ``k`` to the pinhole pixels of the same rays."""
    pts = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    out = cv2.undistortPoints(pts, k.K, np.asarray(k.dist, dtype=np.float64), None, None, k.K,
                              _UNDISTORT_CRITERIA)
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)


@lru_cache(maxsize=8)
def _lens(k: CameraIntrinsics) -> tuple[int, NDArray[np.float32], NDArray[np.float32]]:
    src = undistorted_pixels(k, _grid(k.width, k.height))
    reach = max(float(-src[:, 0].min()), float(src[:, 0].max() - (k.width - 1)),
                float(-src[:, 1].min()), float(src[:, 1].max() - (k.height - 1)), 0.0)
    pad = math.ceil(reach) + _PAD_MARGIN_PX
    map_u = (src[:, 0] + pad).reshape(k.height, k.width).astype(np.float32)
    map_v = (src[:, 1] + pad).reshape(k.height, k.width).astype(np.float32)
    return pad, map_u, map_v


def render_padding(k: CameraIntrinsics) -> int:
    """Pixels the pinhole render needs on every side for camera ``k``'s distorted image."""
    return _lens(k)[0] if k.distorted else 0


def padded_fovy_deg(k: CameraIntrinsics) -> float:
    """Vertical field of view (deg) of the padded render: ``k``'s focal length, taller image."""
    pad = render_padding(k)
    return math.degrees(2.0 * math.atan((k.height + 2 * pad) / (2.0 * k.fy)))


def distort(padded: NDArray[np.float32], k: CameraIntrinsics) -> NDArray[np.float32]:
    """The (H, W, C) image camera ``k`` sees, from a pinhole render padded by
    :func:`render_padding` on every side."""
    _, map_u, map_v = _lens(k)
    return np.asarray(cv2.remap(padded, map_u, map_v, cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE), dtype=np.float32)

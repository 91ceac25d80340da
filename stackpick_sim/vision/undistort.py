"""Undo the lens's distortion before detection: detections are in pinhole (undistorted) pixels.

The camera's :class:`~stackpick_sim.geometry.CameraIntrinsics` carries its Brown-Conrady
coefficients (``dist``); the pose and every ground-truth ellipse use the pinhole model, so a
distorted frame is remapped once to the pinhole view (``cv2.initUndistortRectifyMap`` +
``cv2.remap``, the maps cached per camera). For a few points, :func:`undistort_points` is
cheaper than remapping the image.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics


@lru_cache(maxsize=8)
def _maps(k: CameraIntrinsics) -> tuple[NDArray[np.int16], NDArray[np.uint16]]:
    m1, m2 = cv2.initUndistortRectifyMap(k.K, np.asarray(k.dist, dtype=np.float64), None, k.K,
                                         (k.width, k.height), cv2.CV_16SC2)
    return np.asarray(m1, dtype=np.int16), np.asarray(m2, dtype=np.uint16)


def undistort(image: NDArray, k: CameraIntrinsics | None) -> NDArray:
    """``image`` as an ideal pinhole camera of ``k`` would see it; unchanged when ``k`` is
    None, does not distort, or is of another size."""
    if k is None or not k.distorted or image.shape[:2] != (k.height, k.width):
        return image
    m1, m2 = _maps(k)
    # Replicated borders: a constant border would draw a false outline round the view.
    return np.asarray(cv2.remap(image, m1, m2, cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE), dtype=image.dtype)


def undistort_points(pixels: NDArray[np.float64], k: CameraIntrinsics) -> NDArray[np.float64]:
    """(N, 2) distorted pixels of camera ``k`` to pinhole pixels of the same rays."""
    pts = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    if not k.distorted:
        return pts.reshape(-1, 2).copy()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9)
    out = cv2.undistortPoints(pts, k.K, np.asarray(k.dist, dtype=np.float64), None, None, k.K,
                              criteria)
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)

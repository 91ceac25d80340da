"""Edge pixels with tangents for RHT.

Two sources of the one-pixel edge map, both with Sobel gradients (hence tangents) from the
same Gaussian-smoothed image:

* ``"paper"``: the paper's section 2.1, Gaussian, Sobel-magnitude threshold, thinning
  (``cv2.ximgproc.thinning``, Zhang-Suen). A fixed threshold.
* ``"shared"``: the package's own edge stage, :func:`stackpick_sim.vision.edges.detect_edges`
  (Canny with image-adaptive thresholds), so RHT and the edge-segment detector can be
  compared on identical edges.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.vision.edges import detect_edges

FloatArray = NDArray[np.float64]
EdgeSource = Literal["paper", "shared"]

#: Gaussian sigma, px. sigma 1 removes sensor-level noise while keeping 15 px semi-axes round.
GAUSSIAN_SIGMA_PX = 1.0
#: Sobel-magnitude threshold on a 0-255 image (3x3 Sobel after the Gaussian, magnitude ~3.2
#: per grey level of step contrast): 40 keeps steps of ~13 grey levels and above and sits
#: ~10 sigma above the gradient noise of sigma-5 sensor noise. Placeholder, not identified on
#: rendered frames.
SOBEL_MAGNITUDE_THRESHOLD = 40.0


@dataclass(frozen=True)
class EdgePixels:
    """Thinned edge pixels.

    ``points``: (N, 2) float (u, v) px. ``gradients``: (N, 2) unit Sobel gradient directions.
    ``tangents``: (N, 2) unit tangents, the gradients turned by +90 deg. Signs follow the
    contrast polarity, which says nothing about the shape, so users compare them up to sign.
    """

    points: FloatArray
    gradients: FloatArray
    tangents: FloatArray


def extract_edges(gray: NDArray[np.uint8], *, sigma_px: float = GAUSSIAN_SIGMA_PX,
                  threshold: float = SOBEL_MAGNITUDE_THRESHOLD,
                  source: EdgeSource = "paper") -> EdgePixels:
    """Edge pixels of an (H, W) uint8 image with their Sobel gradient directions.

    ``source="paper"``: Gaussian (``sigma_px``) + Sobel magnitude >= ``threshold`` +
    Zhang-Suen thinning. ``source="shared"``: the package's edge map (``threshold`` unused).
    """
    blur = cv2.GaussianBlur(gray.astype(np.float32), (0, 0), sigma_px)
    gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3)
    if source == "shared":
        thin = detect_edges(gray)
    else:
        binary = np.where(np.hypot(gx, gy) >= threshold, 255, 0).astype(np.uint8)
        thin = np.asarray(cv2.ximgproc.thinning(
            binary, thinningType=cv2.ximgproc.THINNING_ZHANGSUEN), dtype=np.uint8)
    rows, cols = np.nonzero(thin)
    g = np.stack([gx[rows, cols], gy[rows, cols]], axis=1).astype(np.float64)
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    points = np.stack([cols, rows], axis=1).astype(np.float64)
    return EdgePixels(points=points, gradients=g,
                      tangents=np.stack([-g[:, 1], g[:, 0]], axis=1))

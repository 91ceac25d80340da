"""What every baseline and peer detector shares: the result type, the interface, image checks.

A detector is any callable ``detector(image) -> list[ScoredEllipse]`` (see
:class:`EllipseDetector`). ``image`` is an (H, W) grayscale or (H, W, 3) BGR ``uint8`` array;
the list is sorted by descending score and is empty when nothing is found. A detector raises
only :class:`~stackpick_sim.exceptions.ImageError`, and only for an array that is not an image
(wrong dtype, dimensionality or channel count, or empty). Detectors hold no state between
calls, so the caller times one call with ``time.perf_counter`` around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ImageError
from stackpick_sim.geometry import Ellipse

#: Images smaller than this on either side cannot hold a detectable ellipse (a 3 x 3 Sobel
#: and a 5 x 5 Gaussian need at least this much support); detectors return [] for them.
MIN_IMAGE_SIDE_PX = 8


@dataclass(frozen=True, kw_only=True)
class ScoredEllipse:
    """One detection: an ellipse in the package convention and a confidence in [0, 1].

    The score's meaning is the detector's own (documented on each detector) but always
    "higher is more believable", so sorting by it is meaningful within one detector.
    """

    ellipse: Ellipse
    score: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.score <= 1.0 or math.isnan(self.score):
            raise ValueError(f"score {self.score!r} outside [0, 1]")


class EllipseDetector(Protocol):
    """The one interface of baselines and peers: image in, sorted detections out."""

    @property
    def name(self) -> str:
        """Short display name, e.g. for benchmark tables."""
        ...

    def __call__(self, image: NDArray[np.uint8]) -> list[ScoredEllipse]:
        """Detect ellipses in an (H, W) gray or (H, W, 3) BGR uint8 image."""
        ...


def as_gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Validate ``image`` and return it as a C-contiguous (H, W) uint8 gray image.

    Accepts (H, W), (H, W, 1), (H, W, 3) BGR and (H, W, 4) BGRA uint8 arrays. Raises
    ImageError for anything else (another dtype, ndim, channel count, or zero size).
    """
    if not isinstance(image, np.ndarray):
        raise ImageError(f"image must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ImageError(f"image dtype {image.dtype} not supported; expected uint8")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        gray = image
    elif image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        gray = np.asarray(cv2.cvtColor(np.ascontiguousarray(image), code), dtype=np.uint8)
    else:
        raise ImageError(
            f"image shape {image.shape} not supported; expected (H, W), (H, W, 1), "
            "(H, W, 3) BGR or (H, W, 4) BGRA"
        )
    if gray.size == 0:
        raise ImageError(f"image shape {image.shape} is empty")
    return np.ascontiguousarray(gray)


def too_small(gray: NDArray[np.uint8]) -> bool:
    """True when an (H, W) image is below :data:`MIN_IMAGE_SIDE_PX` on either side."""
    return min(gray.shape[:2]) < MIN_IMAGE_SIDE_PX


def sort_by_score(found: list[ScoredEllipse]) -> list[ScoredEllipse]:
    """Detections by descending score; ties keep the detector's order (stable sort)."""
    return sorted(found, key=lambda d: -d.score)


def edge_distance_map(edge_mask: NDArray[np.bool_]) -> NDArray[np.float32]:
    """(H, W) float32 Euclidean distance in px from each pixel to the nearest edge pixel.

    ``edge_mask`` is (H, W) bool; with no edge pixel at all every distance is +inf.
    """
    if not edge_mask.any():
        return np.full(edge_mask.shape, np.inf, dtype=np.float32)
    # distanceTransform measures the distance to the nearest zero, so edges become zeros.
    src = np.where(edge_mask, 0, 255).astype(np.uint8)
    return np.asarray(cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE),
                      dtype=np.float32)


def outline_coverage(ellipse: Ellipse, edge_distance: NDArray[np.float32], *,
                     tolerance_px: float) -> float:
    """Share in [0, 1] of the ellipse's outline lying within ``tolerance_px`` of an edge pixel.

    ``edge_distance`` is the (H, W) map of :func:`edge_distance_map`. The outline is sampled
    about one point per pixel of perimeter; samples outside the image count as unsupported.
    """
    h, w = edge_distance.shape
    a, b = ellipse.a, ellipse.b
    perimeter = math.pi * (3 * (a + b) - math.sqrt((3 * a + b) * (a + 3 * b)))  # Ramanujan
    pts = ellipse.points(max(16, math.ceil(perimeter)))
    col = np.rint(pts[:, 0]).astype(np.int64)
    row = np.rint(pts[:, 1]).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    near = np.zeros(len(pts), dtype=bool)
    near[inside] = edge_distance[row[inside], col[inside]] <= tolerance_px
    return float(np.count_nonzero(near)) / len(pts)

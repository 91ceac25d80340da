"""Stage 1: one-pixel-wide edges with thresholds that adapt to the image (paper section 2.1).

Gaussian smoothing, Sobel gradients per colour channel (the strongest channel wins at each
pixel, so two faces of equal brightness but different colour still give an edge), Canny's
non-maximum suppression and hysteresis (OpenCV), then a table-driven pass removing Canny's
stair-step corners so that every edge pixel has at most two edge neighbours except at true
junctions.

Thresholds adapt to the image: the median gradient magnitude estimates the noise (most
pixels of a conveyor scene are flat), the 99th percentile the contrast of real edges; the
high threshold is the larger of a noise multiple and a contrast fraction, so dimmer light or
more noise needs no retuning. The settings and their reasons:
:class:`~stackpick_sim.config.vision_params.EdgeParams`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import EdgeParams
from stackpick_sim.exceptions import ImageError
from stackpick_sim.vision import kernels

#: The default settings (see EdgeParams: the reasons for each).
DEFAULT = EdgeParams()
#: Sobel 3x3 gives 8x the grey-level slope per pixel; thresholds are in grey levels/px.
SOBEL_GAIN = 8.0
#: Pixels of the magnitude sample used for the statistics (every 4th row and column).
STATS_STRIDE = 4
#: Images smaller than this on either side carry no usable ellipse.
MIN_SIDE_PX = 16
#: Images larger than this many pixels are refused (memory and time).
MAX_PIXELS = 4096 * 4096


def as_rgb_or_gray(image: NDArray) -> NDArray[np.uint8]:
    """Validate and normalise an image to uint8 (H, W) or (H, W, 3).

    Accepts uint8, uint16 (scaled by 1/257), bool (0/255) and float images in [0, 1] (or
    [0, 255] when their maximum exceeds 1), with 1, 3 or 4 channels (alpha dropped). Raises
    ImageError for anything else, naming what was given and what is allowed.
    """
    if not isinstance(image, np.ndarray):
        raise ImageError(f"image must be a numpy array, got {type(image).__name__}")
    img = image
    if img.ndim == 3 and img.shape[2] in (1, 3, 4):
        img = img[:, :, 0] if img.shape[2] == 1 else img[:, :, :3]
    elif img.ndim != 2:
        raise ImageError(f"image shape {image.shape} not allowed; expected (H, W) or "
                         "(H, W, C) with C in 1, 3, 4")
    if img.shape[0] * img.shape[1] > MAX_PIXELS:
        raise ImageError(f"image of {img.shape[1]}x{img.shape[0]} px exceeds the "
                         f"{MAX_PIXELS} pixel limit")
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype == np.bool_:
        return img.astype(np.uint8) * np.uint8(255)
    if img.dtype == np.uint16:
        return (img // 257).astype(np.uint8)
    if np.issubdtype(img.dtype, np.floating):
        if not np.all(np.isfinite(img)):
            raise ImageError("float image contains NaN or infinity")
        scale = 255.0 if img.size and float(img.max()) <= 1.0 else 1.0
        return np.clip(np.round(img * scale), 0, 255).astype(np.uint8)
    raise ImageError(f"image dtype {image.dtype} not allowed; expected uint8, uint16, bool, "
                     "float32 or float64")


def colour_gradients(image: NDArray[np.uint8]) -> tuple[NDArray[np.int16], NDArray[np.int16]]:
    """Sobel (dx, dy) of an (H, W) or (H, W, C) uint8 image; (H, W) int16 each.

    Per pixel, the channel with the largest L1 gradient |dx| + |dy| wins (the first of
    equals): an edge between two colours of equal brightness is as strong as in the channel
    that separates them.
    """
    if image.ndim == 2:
        dx, dy = cv2.spatialGradient(image)
        return cast("NDArray[np.int16]", dx), cast("NDArray[np.int16]", dy)
    # The planes in one split (a third less than extracting them one by one), each plane's
    # 3x3 Sobel pair by spatialGradient (a third of the cost of two Sobel calls) into one
    # stacked buffer, then the strongest channel per pixel in one compiled pass
    # (kernels.strongest_gradients).
    h, w, channels = image.shape
    stacked = np.empty((channels, 2, h, w), np.int16)
    for c, plane in enumerate(cv2.split(image)):
        cv2.spatialGradient(plane, stacked[c, 0], stacked[c, 1])
    return kernels.strongest_gradients(stacked)


def adaptive_thresholds(dx: NDArray[np.int16], dy: NDArray[np.int16],
                        params: EdgeParams = DEFAULT) -> tuple[float, float, float]:
    """(low, high) Canny thresholds in Sobel units for gradients (H, W) int16 dx, dy, and the
    noise level (median magnitude, grey levels/px), by the ``params``' rule."""
    floor, low_ratio = params.min_high_threshold, params.low_ratio
    median, p99, size = _magnitude_quantiles(dx, dy)
    if size == 0:
        return floor * low_ratio * SOBEL_GAIN, floor * SOBEL_GAIN, 0.0
    high = max(floor, params.noise_multiple * median, params.contrast_fraction * p99)
    return low_ratio * high * SOBEL_GAIN, high * SOBEL_GAIN, median


def _magnitude_quantiles(dx: NDArray[np.int16], dy: NDArray[np.int16]
                         ) -> tuple[float, float, int]:
    """The statistics' sample: the float32 gradient magnitudes (grey levels/px) of every
    STATS_STRIDE-th row and column (``np.sqrt(sx * sx + sy * sy) / SOBEL_GAIN`` of the
    float32 samples ``sx``, ``sy``); its median and 99th percentile (the N // 2-th and the
    min(N - 1, int(0.99 N))-th smallest value of N) and N, in one compiled pass
    (kernels.stride_quantiles: the values a partition of the sample puts there)."""
    return kernels.stride_quantiles(np.ascontiguousarray(dx), np.ascontiguousarray(dy),
                                    STATS_STRIDE, SOBEL_GAIN)


def noise_level(dx: NDArray[np.int16], dy: NDArray[np.int16]) -> float:
    """The noise level of :func:`adaptive_thresholds` alone (the same value)."""
    return _magnitude_quantiles(dx, dy)[0]


def _ring_groups(code: int) -> tuple[int, int]:
    """(8-connected groups, count) of the neighbours set in an 8-bit ring ``code``."""
    on = [i for i in range(8) if code >> i & 1]
    seen: set[int] = set()
    groups = 0
    for start in on:
        if start in seen:
            continue
        groups += 1
        stack = [start]
        seen.add(start)
        while stack:
            i = stack.pop()
            for j in on:
                (ri, ci), (rj, cj) = RING[i], RING[j]
                if j not in seen and max(abs(ri - rj), abs(ci - cj)) == 1:
                    seen.add(j)
                    stack.append(j)
    return groups, len(on)


def _stair_luts() -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Two 256-entry tables: 1 where a pixel of that neighbour code is a removable stair.

    Removable: not an end point, its neighbours stay one 8-connected group without it, and it
    has a 4-neighbour above (first pass) or below (second pass) plus one to a side. Splitting
    by above/below keeps the two pixels of a stair step from being removed together.
    """
    north, east, south, west = 1, 3, 5, 7
    first, second = np.zeros(256, np.uint8), np.zeros(256, np.uint8)
    for code in range(256):
        groups, count = _ring_groups(code)
        if count < 2 or groups != 1:
            continue
        side = bool(code >> east & 1 or code >> west & 1)
        first[code] = int(side and bool(code >> north & 1))
        second[code] = int(side and bool(code >> south & 1))
    return first, second


#: 8-neighbour ring, clockwise from north-west, as (row, col) offsets; bit i of a code.
RING: tuple[tuple[int, int], ...] = ((-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0),
                                     (1, -1), (0, -1))
#: 3x3 correlation kernel giving each pixel its 8-bit neighbour code.
RING_KERNEL = np.zeros((3, 3), np.float32)
for _bit, (_r, _c) in enumerate(RING):
    RING_KERNEL[_r + 1, _c + 1] = float(1 << _bit)
STAIR_LUTS = _stair_luts()


def neighbour_codes(binary: NDArray[np.uint8], out: NDArray[np.uint8] | None = None
                    ) -> NDArray[np.uint8]:
    """(H, W) uint8 8-bit code of each pixel's set neighbours in a 0/1 image (see RING),
    written into ``out`` when given (uint8, of the image's shape)."""
    return cast("NDArray[np.uint8]", cv2.filter2D(binary, cv2.CV_8U, RING_KERNEL, out,
                                                borderType=cv2.BORDER_CONSTANT))


def remove_stairs(edges: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Thin Canny output to 8-connected one-pixel curves; (H, W) 0/1 uint8.

    Canny's non-maximum suppression leaves 4-connected stair steps, whose corner pixels have
    three edge neighbours and would read as junctions. Two table-driven passes (after
    Zhang-Suen's two sub-iterations) delete exactly those corners, keeping connectivity.
    OpenCV's ``ximgproc.thinning`` leaves them in place and costs 10x more here.
    """
    # Both passes over the edge pixels alone, in one compiled call (kernels.stairs_removed:
    # the same pixels as the whole-image passes of neighbour_codes and the tables).
    b = edges if edges.dtype == np.uint8 else (edges > 0).astype(np.uint8)
    return kernels.stairs_removed(np.ascontiguousarray(b), *STAIR_LUTS)


@dataclass(frozen=True, kw_only=True)
class EdgeImage:
    """The edge stage's output: the edge map and the gradients it came from.

    ``edges``: (H, W) uint8 0/1, one pixel wide. ``gx``, ``gy``: (H, W) int16 Sobel gradients
    of the smoothed image (strongest colour channel per pixel), SOBEL_GAIN x grey levels/px.
    ``noise``: median gradient magnitude, grey levels/px (the flat background's noise level).
    ``params``: the settings it was made with (their ``support_*`` fields set the contrast
    an outline needs, :func:`~stackpick_sim.vision.contrast.contrast_threshold`).
    """

    edges: NDArray[np.uint8]
    gx: NDArray[np.int16]
    gy: NDArray[np.int16]
    noise: float
    params: EdgeParams = DEFAULT


def edge_image(image: NDArray[np.uint8], params: EdgeParams = DEFAULT) -> EdgeImage:
    """Edges and gradients of a uint8 (H, W) gray or (H, W, 3) RGB image (settings:
    ``params``)."""
    gx, gy, canny, noise = _canny(image, params)
    edges = remove_stairs(canny)
    return EdgeImage(edges=edges, gx=gx, gy=gy, noise=noise, params=params)


def edge_image_points(image: NDArray[np.uint8], params: EdgeParams = DEFAULT
                      ) -> tuple[EdgeImage, NDArray[np.float64], NDArray[np.float64]]:
    """:func:`edge_image` and its edge pixels (M, 2) (u, v) in row-major order with their
    unit gradient directions (M, 2), each with contiguous columns (as
    :func:`~stackpick_sim.vision.refine.edge_points` of it), the stair passes and the
    pixel list in one compiled call."""
    gx, gy, canny, noise = _canny(image, params)
    edges, pts, g = kernels.stairs_removed_pixels(np.ascontiguousarray(canny), *STAIR_LUTS,
                                                  gx, gy)
    return EdgeImage(edges=edges, gx=gx, gy=gy, noise=noise, params=params), pts.T, g.T


def _canny(image: NDArray[np.uint8], params: EdgeParams
           ) -> tuple[NDArray[np.int16], NDArray[np.int16], NDArray[np.uint8], float]:
    """The gradients of the smoothed image, Canny's 0/255 edge map on them and the noise
    level (see :func:`edge_image`)."""
    # The colour image blurred in one call (the same values as channel by channel, at about
    # half the cost), then split into the planes the gradients need; the kernel covers
    # +-2 sigma.
    sigma = params.blur_sigma_px
    side = 2 * math.ceil(2.0 * sigma) + 1
    blurred = cast("NDArray[np.uint8]", cv2.GaussianBlur(image, (side, side), sigma))
    gx, gy = colour_gradients(blurred)
    low, high, noise = adaptive_thresholds(gx, gy, params)
    canny = cast("NDArray[np.uint8]", cv2.Canny(gx, gy, low, high, L2gradient=True))
    return gx, gy, canny, noise


def unblurred_gradients(image: NDArray[np.uint8], edges: EdgeImage) -> EdgeImage:
    """``edges`` with the gradients (and noise level) of the unsmoothed uint8 image.

    For the top face's final fit (:func:`~stackpick_sim.vision.refine.refine_on_profile`):
    on the simulator's frames, fits on the smoothed gradients came out with a semi-minor
    axis 0.3-0.6 px short on faces beside other outlines (rendered paper-scene frames),
    enough for several degrees of tilt on a nearly square-on face; on these gradients the
    error halves and the theta p95 over 300 such frames is ~1.3 deg against ~3 deg on the
    smoothed ones. Smoothing moves a gradient peak where other structure lies within its
    footprint; the fit's averaging over the whole outline and its outlier test take the place
    of the smoothing against noise.
    """
    gx, gy = colour_gradients(image)
    return EdgeImage(edges=edges.edges, gx=gx, gy=gy, noise=noise_level(gx, gy),
                     params=edges.params)


def detect_edges(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(H, W) 0/1 uint8 edge map, one pixel wide, of a uint8 gray or RGB image."""
    return edge_image(image).edges

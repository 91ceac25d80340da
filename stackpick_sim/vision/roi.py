"""Region of interest: the box around everything that is not bare belt.

The belt is a uniform dark grey; the pile covers a fraction of the frame. Working on the box
around the pile (plus a margin) cuts every per-pixel stage in proportion, and the stages past
the edges never look outside it. The box is found on a ``decimation``-times smaller copy (area
averages, taken in halving steps): a pixel is foreground when its brightest channel differs
from the belt's by ``foreground_delta``. The belt's level is the most common brightest-channel
level of the small copy (its histogram smoothed over ``belt_mode_window`` levels): the belt is
the frame's largest surface. (Not the median over the frame's border: that is taken by
whatever lies beyond the belt's sides once the camera sees them: from 0.40 m up, the frame's
top and bottom rows.) The belt's colour (the mean of the small copy's pixels within
``belt_colour_levels`` of that level) is kept as well: the side-wall tests tell a grey
object's wall from bare belt by it (``pose.band_belt_delta``).
Anything uncertain (a frame too small, foreground everywhere) falls back to the whole frame.
The settings and their reasons: :class:`~stackpick_sim.config.vision_params.RoiParams`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import RoiParams
from stackpick_sim.vision import kernels

#: The default settings (see RoiParams).
DEFAULT = RoiParams()


def _mode_kernel(window: int) -> NDArray[np.float64]:
    """Triangular weights of the histogram smoothing over ``window`` levels: one peak, at the
    middle of a narrow mode (a flat window would tie over a mode narrower than itself)."""
    return np.asarray(np.bartlett(window + 2)[1:-1], np.float64)


_MODE_KERNEL = _mode_kernel(DEFAULT.belt_mode_window)


@dataclass(frozen=True, kw_only=True)
class Roi:
    """A box of the frame: columns u0..u1, rows v0..v1 (end exclusive), pixels, and the bare
    belt's colour (one value per channel, see the module docstring; None when unread)."""

    u0: int
    v0: int
    u1: int
    v1: int
    belt: tuple[float, ...] | None = None

    @classmethod
    def of(cls, u0: int, v0: int, u1: int, v1: int, belt: tuple[float, ...] | None = None
           ) -> Roi:
        """``Roi(u0=u0, ...)`` (an equal object) without the frozen dataclass constructor's
        cost, as :meth:`~stackpick_sim.geometry.Ellipse.of`."""
        r = object.__new__(cls)
        d = r.__dict__
        d["u0"], d["v0"], d["u1"], d["v1"], d["belt"] = u0, v0, u1, v1, belt
        return r

    @property
    def offset(self) -> tuple[int, int]:
        """(u, v) of the box's top-left pixel in the frame."""
        return self.u0, self.v0

    def crop(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The box of an (H, W[, C]) image (a view)."""
        return image[self.v0:self.v1, self.u0:self.u1]


def decimate(image: NDArray[np.uint8], factor: int = DEFAULT.decimation) -> NDArray[np.uint8]:
    """The ``factor``-times smaller copy (a power of two) of an (H, W[, C]) uint8 image, each
    pixel the mean of a block, taken in halving steps of 2x2 area averages.

    Each step rounds, so a pixel can differ by one grey level from the block's mean in one
    step; OpenCV's 2x area reduction costs a third of its 4x one on colour frames (measured
    on 320x240, 27 against 84 us), which is most of this stage.
    """
    small = image
    step = 1
    while step < factor:
        h, w = small.shape[:2]
        small = cast("NDArray[np.uint8]", cv2.resize(small, (max(1, w // 2), max(1, h // 2)),
                                                     interpolation=cv2.INTER_AREA))
        step *= 2
    return small


def find_roi(image: NDArray[np.uint8], params: RoiParams = DEFAULT) -> Roi:
    """The box around the non-belt pixels of a uint8 (H, W) or (H, W, 3) frame (settings:
    ``params``).

    The whole frame when no foreground is found (nothing to crop to: the later stages then
    report the miss) or when the frame is too small to read the belt's level on.
    """
    h, w = image.shape[:2]
    small = decimate(image, params.decimation)
    if min(small.shape[:2]) < 3:
        return Roi.of(0, 0, w, h)
    # (H, W, C), C-ordered and writable: the one argument type of the compiled passes.
    small = small.reshape(small.shape[0], small.shape[1], -1)
    if not (small.flags.c_contiguous and small.flags.writeable):
        small = small.copy()
    # The brightest channel and its histogram in one compiled pass; the belt's level from
    # the smoothed histogram; then its colour and the foreground's box in a second pass.
    level, counts = kernels.level_histogram(small)
    belt = _mode(counts, params.belt_mode_window)
    colour, near, (bu, bv, bw, bh) = kernels.belt_box(
        small, level, belt, params.belt_colour_levels, params.foreground_delta)
    channels = int(small.shape[2])
    if near == 0:  # the smoothed peak between two close modes
        belt_colour: tuple[float, ...] = (float(belt),) * channels
    else:
        belt_colour = tuple(colour.tolist())
    if bw == 0 or bh == 0:
        return Roi.of(0, 0, w, h, belt_colour)
    step, margin = params.decimation, params.margin_px
    u0 = max(0, int(bu) * step - margin)
    v0 = max(0, int(bv) * step - margin)
    u1 = min(w, int(bu + bw) * step + margin)
    v1 = min(h, int(bv + bh) * step + margin)
    return Roi.of(u0, v0, u1, v1, belt_colour)


def _mode(counts: NDArray[np.float64], window: int) -> int:
    """The most common level of a 256-bin histogram ``counts`` smoothed over ``window``
    levels (the first of equals)."""
    kernel = _MODE_KERNEL if window == DEFAULT.belt_mode_window else _mode_kernel(window)
    return int(np.argmax(np.convolve(counts, kernel, mode="same")))


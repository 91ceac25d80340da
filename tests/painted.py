"""Synthetic RGB frames of coloured faces on a dark belt, shared by the marking and ring
tests."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from stackpick_sim.geometry import Ellipse

#: A layer: (ellipse, rgb colour in [0, 1]) or (ellipse, colour, ring): with ``ring`` a 2 px
#: line (a printed or embossed ring) on what lies under it instead of a filled face.
Layer = tuple[Ellipse, tuple[float, float, float]] | tuple[
    Ellipse, tuple[float, float, float], bool]


def painted(shape: tuple[int, int], layers: Sequence[Layer], seed: int) -> np.ndarray:
    """uint8 RGB frame of ``shape``: belt grey 30, then each layer painted in order, then
    Gaussian noise of std 1.5 grey levels (``seed``)."""
    rng = np.random.default_rng(seed)
    image = np.full((*shape, 3), 30.0)
    for layer in layers:
        ellipse, colour = layer[0], layer[1]
        mask = _ring(ellipse, shape) if len(layer) == 3 and layer[2] else ellipse.mask(shape)
        image[mask] = 255.0 * np.asarray(colour)
    image += rng.normal(0.0, 1.5, image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def _ring(ellipse: Ellipse, shape: tuple[int, int]) -> np.ndarray:
    """Mask of the 2 px line along ``ellipse``."""
    outer = Ellipse(cx=ellipse.cx, cy=ellipse.cy, a=ellipse.a + 1, b=ellipse.b + 1,
                    angle_deg=ellipse.angle_deg)
    inner = Ellipse(cx=ellipse.cx, cy=ellipse.cy, a=ellipse.a - 1, b=ellipse.b - 1,
                    angle_deg=ellipse.angle_deg)
    return np.asarray(outer.mask(shape) & ~inner.mask(shape))

"""Drawing ellipses and labels over images (ground truth, detections), for people to look at."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse

#: Drawing colours, BGR (OpenCV's order): ground truth of a top object, of any other object.
TOP_COLOUR = (60, 220, 60)
OTHER_COLOUR = (60, 160, 255)
#: Sub-pixel precision of drawn outlines: coordinates are scaled by 2**SHIFT.
SHIFT = 4


def draw_ellipse(image: NDArray[np.uint8], ellipse: Ellipse, colour: tuple[int, int, int],
                 thickness: int = 1) -> None:
    """Draw ``ellipse``'s outline into the BGR ``image`` in place, with sub-pixel accuracy."""
    pts = np.round(ellipse.points(180) * (1 << SHIFT)).astype(np.int32)
    cv2.polylines(image, [pts], isClosed=True, color=colour, thickness=thickness,
                  lineType=cv2.LINE_AA, shift=SHIFT)


def draw_marker(image: NDArray[np.uint8], uv: tuple[float, float], colour: tuple[int, int, int],
                size: int = 6) -> None:
    """A small cross at pixel ``uv`` (u, v)."""
    cv2.drawMarker(image, (round(uv[0]), round(uv[1])), colour, cv2.MARKER_CROSS, size, 1,
                   cv2.LINE_AA)


def draw_label(image: NDArray[np.uint8], text: str, uv: tuple[float, float],
               colour: tuple[int, int, int]) -> None:
    """Small text near pixel ``uv`` with a dark outline so it reads on any background."""
    org = (round(uv[0]), round(uv[1]))
    for col, th in (((0, 0, 0), 3), (colour, 1)):
        cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.35, col, th, cv2.LINE_AA)


def upscale(image: NDArray[np.uint8], factor: int) -> NDArray[np.uint8]:
    """Nearest-neighbour enlargement so thin overlays stay readable on small frames."""
    return np.repeat(np.repeat(image, factor, axis=0), factor, axis=1)

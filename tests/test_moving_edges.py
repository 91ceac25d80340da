"""The tracked face's outline found around its prediction (vision/moving_edges.py)."""

from __future__ import annotations

import cv2
import numpy as np

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.moving_edges import track_outline

TRUE = Ellipse(cx=161.3, cy=118.6, a=42.0, b=37.0, angle_deg=20.0)


def _image(rng: np.random.Generator) -> np.ndarray:
    """(240, 320) float32: the face (grey 150) over a neighbour of nearly its colour (138)
    and the belt (40), camera noise std 1, smoothed as the sensor does."""
    img = np.full((240 * 8, 320 * 8), 40, np.uint8)  # drawn 8x larger: sub-pixel edges

    def fill(e: Ellipse, grey: int) -> None:
        cv2.ellipse(img, (round((e.cx + 0.5) * 8), round((e.cy + 0.5) * 8)),
                    (round(e.a * 8), round(e.b * 8)), e.angle_deg, 0, 360, grey, -1)

    fill(Ellipse(cx=200.0, cy=100.0, a=40.0, b=36.0, angle_deg=0.0), 138)
    fill(TRUE, 150)
    small = cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA).astype(np.float32)
    small += rng.normal(0.0, 1.0, small.shape).astype(np.float32)
    return np.asarray(cv2.GaussianBlur(small, (3, 3), 0), dtype=np.float32)


def test_outline_is_found_around_an_offset_prediction() -> None:
    gray = _image(np.random.default_rng(3))
    predicted = Ellipse(cx=TRUE.cx + 3.0, cy=TRUE.cy - 2.0, a=TRUE.a * 1.05, b=TRUE.b * 0.96,
                        angle_deg=TRUE.angle_deg + 4.0)
    fit = track_outline(gray, predicted, 6.0)
    assert fit is not None
    assert abs(fit.cx - TRUE.cx) < 0.3 and abs(fit.cy - TRUE.cy) < 0.3
    assert abs(fit.a - TRUE.a) < 0.5 and abs(fit.b - TRUE.b) < 0.5


def test_no_outline_where_the_prediction_has_no_edges() -> None:
    rng = np.random.default_rng(4)
    flat = np.asarray(cv2.GaussianBlur(
        (100 + rng.normal(0.0, 1.0, (240, 320))).astype(np.float32), (3, 3), 0))
    assert track_outline(flat, TRUE, 6.0) is None
    # An outline far off the prediction (beyond the search range) is not taken either.
    gray = _image(np.random.default_rng(5))
    far = Ellipse(cx=TRUE.cx - 20.0, cy=TRUE.cy, a=TRUE.a, b=TRUE.b, angle_deg=TRUE.angle_deg)
    fit = track_outline(gray, far, 6.0)
    assert fit is None

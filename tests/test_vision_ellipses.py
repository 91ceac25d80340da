"""find_ellipses: the ellipse stages alone, each ellipse scored by its outline's support."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from stackpick_sim.exceptions import ConfigError
from stackpick_sim.vision import find_ellipses

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from stress_images import stress_image


def _discs() -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
    img = np.full((240, 320, 3), 90, np.uint8)
    truth = [(80.0, 70.0, 40.0, 30.0), (220.0, 150.0, 25.0, 25.0)]
    for (cx, cy, a, b), colour in zip(truth, [(230, 120, 40), (40, 160, 230)], strict=True):
        cv2.ellipse(img, ((cx, cy), (2 * a, 2 * b), 0.0), colour, -1, cv2.LINE_AA)
    return img, truth


def test_finds_the_discs_with_high_support_best_first() -> None:
    img, truth = _discs()
    found = find_ellipses(img)
    assert len(found) == 2
    for cx, cy, a, b in truth:
        assert any(abs(s.ellipse.cx - cx) < 1 and abs(s.ellipse.cy - cy) < 1
                   and abs(s.ellipse.a - a) < 1.5 and abs(s.ellipse.b - b) < 1.5
                   for s in found)
    assert all(s.support > 0.9 for s in found)
    assert found[0].support >= found[1].support


def test_axis_bounds_select_by_size() -> None:
    img, _ = _discs()
    small = find_ellipses(img, max_axis_px=30)
    assert len(small) == 1 and abs(small[0].ellipse.a - 25) < 1.5
    large = find_ellipses(img, min_axis_px=28)
    assert len(large) == 1 and abs(large[0].ellipse.a - 40) < 1.5


def test_a_half_hidden_outline_fails_a_high_support_bound() -> None:
    img = np.full((240, 320, 3), 90, np.uint8)
    cv2.ellipse(img, ((160.0, 120.0), (100.0, 80.0), 0.0), (230, 120, 40), -1, cv2.LINE_AA)
    cv2.rectangle(img, (160, 0), (319, 239), (90, 90, 90), -1)  # its right half hidden
    assert find_ellipses(img, min_support=0.3)
    assert not find_ellipses(img, min_support=0.8)


@pytest.mark.parametrize("kind", ["noise", "texture"])
def test_no_ellipses_in_noise_or_straight_textures(kind: str) -> None:
    assert all(not find_ellipses(stress_image(kind, seed)) for seed in range(5))


def test_bounds_are_checked() -> None:
    img, _ = _discs()
    with pytest.raises(ConfigError):
        find_ellipses(img, min_axis_px=10, max_axis_px=5)
    with pytest.raises(ConfigError):
        find_ellipses(img, min_support=1.5)


def _strokes() -> np.ndarray:
    """Printed rings and bold round letters on a plain background: outlines of thin strokes."""
    img = np.full((240, 320, 3), 225, np.uint8)
    for (cx, cy), r, width in [((60, 60), 30, 2), ((170, 55), 22, 4), ((260, 70), 40, 6)]:
        cv2.circle(img, (cx, cy), r, (30, 30, 30), width, cv2.LINE_AA)
    cv2.putText(img, "O0o@Q", (10, 210), cv2.FONT_HERSHEY_SIMPLEX, 2.5, (20, 20, 120), 3,
                cv2.LINE_AA)
    return img


def test_stroke_outlines_are_not_reported() -> None:
    from stackpick_sim.config.vision_params import EllipsesParams

    img = _strokes()
    assert len(find_ellipses(img, params=EllipsesParams(max_stroke_share=1.0))) >= 5
    assert find_ellipses(img) == []


def test_discs_among_strokes_are_kept() -> None:
    img = _strokes()
    truth = [(100.0, 130.0, 28.0, 20.0, 0.0), (225.0, 150.0, 18.0, 18.0, 0.0)]
    for cx, cy, a, b, ang in truth:
        cv2.ellipse(img, ((cx, cy), (2 * a, 2 * b), ang), (200, 120, 40), -1, cv2.LINE_AA)
    found = find_ellipses(img)
    for cx, cy, a, b, _ in truth:
        assert any(abs(s.ellipse.cx - cx) < 1 and abs(s.ellipse.cy - cy) < 1
                   and abs(s.ellipse.a - a) < 1.5 and abs(s.ellipse.b - b) < 1.5
                   for s in found)

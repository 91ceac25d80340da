"""Work limits of the detector: downscaling of large images, caps, the time budget."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.vision import DetectorConfig, detect
from stackpick_sim.vision.limits import WorkLimits, downscale_factor


def _disc_image(width: int, height: int, centre: tuple[int, int], axes: tuple[int, int],
                angle: float) -> np.ndarray:
    img = np.full((height, width, 3), 60, np.uint8)
    cv2.ellipse(img, centre, axes, angle, 0, 360, (220, 60, 40), -1, cv2.LINE_AA)
    return img


def test_downscale_factor_is_the_smallest_within_the_limit() -> None:
    assert downscale_factor((480, 640), 640 * 480) == 1
    assert downscale_factor((481, 640), 640 * 480) == 2
    assert downscale_factor((3000, 4000), 640 * 480) == 7  # 428 x 571


def test_a_large_image_is_detected_downscaled_in_full_image_pixels() -> None:
    img = _disc_image(1600, 1200, (820, 590), (300, 200), 30.0)
    full = detect(img, DetectorConfig(limits=WorkLimits(max_pixels=1600 * 1200)))
    small = detect(img)  # default limit: downscaled by 3
    assert full.ellipses and small.ellipses
    e, f = small.ellipses[0].ellipse, full.ellipses[0].ellipse
    assert abs(e.cx - 820) < 3 and abs(e.cy - 590) < 3
    assert abs(e.a - f.a) < 3 and abs(e.b - f.b) < 3
    assert abs(e.angle_deg - 30.0) < 1.0
    # Chains are in full-image pixels too.
    top = max(int(c[:, 1].max()) for c in small.segments)
    assert 700 < top < 1200


def test_a_spent_time_budget_gives_a_falsy_detection_naming_the_stage() -> None:
    img = _disc_image(320, 240, (160, 120), (60, 40), 10.0)
    result = detect(img, DetectorConfig(limits=WorkLimits(time_budget_ms=1e-6)))
    assert not result
    assert "time budget" in result.reason and "roi" in result.reason


def test_chain_cap_keeps_the_longest_chains() -> None:
    img = np.full((240, 320, 3), 60, np.uint8)
    cv2.ellipse(img, (160, 120), (80, 60), 0, 0, 360, (220, 60, 40), -1, cv2.LINE_AA)
    for k in range(6):
        cv2.circle(img, (30 + 50 * k, 20), 8, (40, 200, 40), -1, cv2.LINE_AA)
    capped = detect(img, DetectorConfig(limits=WorkLimits(max_chains=1)))
    whole = detect(img)
    # The small discs' outlines (rows 12-28) are dropped, the large one's kept.
    assert any(int(c[:, 1].max()) < 40 for c in whole.segments)
    assert all(int(c[:, 1].min()) > 40 for c in capped.segments)
    assert capped.ellipses and abs(capped.ellipses[0].ellipse.a - 80) < 3


@pytest.mark.parametrize("field", ["max_pixels", "max_chains", "max_fits", "max_ellipses",
                                   "max_arcs", "max_refits"])
def test_caps_must_be_positive_integers(field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        WorkLimits(**{field: 0})
    with pytest.raises(ConfigError, match="time_budget_ms"):
        WorkLimits(time_budget_ms=0.0)


def test_scene_vision_table_reaches_the_detector_through_the_cli(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from stackpick_sim.cli.main import main

    path = tmp_path / "disc.png"
    cv2.imwrite(str(path), _disc_image(320, 240, (160, 120), (60, 40), 10.0))
    assert main(["detect", str(path), "--set", "vision.time_budget_ms=1e-6"]) == 0
    assert "time budget of 1e-06 ms ran out" in capsys.readouterr().out
    assert main(["detect", str(path), "--set", "vision.max_arcs=0"]) == 2
    assert "vision.max_arcs" in capsys.readouterr().err


def test_scene_gives_the_detector_its_kinds_and_depth_range() -> None:
    import argparse

    from stackpick_sim.cli.detect_cmd import detector_config

    args = argparse.Namespace(scene="paper", overrides=["vision.max_fits=9"], fovy=None,
                              radii=None, depth_range=None)
    config = detector_config(args, 320, 240)
    assert config.radii_m == (0.035, 0.025) and config.kind_colours is not None
    assert config.depth_range_m is not None and 0.1 < config.depth_range_m[0] < 0.3
    assert config.limits.max_fits == 9
    explicit = detector_config(argparse.Namespace(scene=None, overrides=[], fovy=60.0,
                                                  radii=[0.05], depth_range=None), 320, 240)
    assert explicit.radii_m == (0.05,) and explicit.depth_range_m is None


def test_scene_gives_the_detector_its_lens_distortion() -> None:
    import argparse

    from stackpick_sim.cli.detect_cmd import detector_config

    args = argparse.Namespace(scene="realistic", overrides=[], fovy=None, radii=None,
                              depth_range=None)
    config = detector_config(args, 320, 240)
    assert config.intrinsics is not None
    assert config.intrinsics.dist == load_scene("realistic").camera.distortion
    assert config.intrinsics.distorted
    paper = detector_config(argparse.Namespace(scene="paper", overrides=[], fovy=None,
                                               radii=None, depth_range=None), 320, 240)
    assert paper.intrinsics is not None and not paper.intrinsics.distorted

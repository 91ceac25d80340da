"""The compiled passes of the top rule's evidence and the pose give the values of the steps
they chain (bit-identical)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.contrast import (
    _OFFSETS,
    _SHIFTS,
    contrast_profiles,
    outline_rows,
    outlines,
    supported_runs,
)
from stackpick_sim.vision.edges import SOBEL_GAIN, EdgeImage
from stackpick_sim.vision.occlusion import _support_along
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.wall import band_evidences, solution_bands, tan_tilt, wall_evidences


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(11)


def _ellipses(rng: np.random.Generator, n: int, w: float = 80.0, h: float = 60.0
              ) -> list[Ellipse]:
    """Random ellipses over a w x h image, some reaching beyond it."""
    out = []
    for _ in range(n):
        a = rng.uniform(4.0, 30.0)
        out.append(Ellipse.of(rng.uniform(-5, w + 5), rng.uniform(-5, h + 5), a,
                              a * rng.uniform(0.3, 1.0), rng.uniform(-180, 180)))
    return out


def _image(rng: np.random.Generator) -> EdgeImage:
    gx = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    gy = rng.integers(-400, 400, (60, 80)).astype(np.int16)
    return EdgeImage(edges=np.zeros((60, 80), np.uint8), gx=gx, gy=gy, noise=4.0)


def _runs_form(ok: np.ndarray, offsets: np.ndarray, window: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Supported samples per outline, first and last samples of the unsupported runs: the
    array form."""
    return (np.add.reduceat(ok, offsets[:-1], dtype=np.int64),
            (~ok & ok[window[2]]).nonzero()[0], (~ok & ok[window[3]]).nonzero()[0])


def test_contrast_runs_are_the_profile_its_threshold_and_runs(rng: np.random.Generator
                                                                ) -> None:
    image = _image(rng)
    ellipses = _ellipses(rng, 7)
    lines = outlines(ellipses)
    profile = contrast_profiles(lines, image)
    threshold = float(np.median(profile))
    ok = profile >= threshold
    table, sizes, ct, st, _ = outline_rows(ellipses)
    pts, got_ok, supported, firsts, lasts = kernels_pose.contrast_runs(
        table, sizes, ct, st, image.gx, image.gy, _OFFSETS, _SHIFTS, SOBEL_GAIN, threshold)
    assert np.array_equal(pts.T, lines.points)
    assert np.array_equal(got_ok, ok) and 0 < ok.sum() < ok.size
    want = _runs_form(ok, lines.offsets, lines.window)
    for a, b in zip((supported, firsts, lasts), want, strict=True):
        assert np.array_equal(a, b)
    assert firsts.size and lasts.size


def test_supported_runs_read_the_image_threshold(rng: np.random.Generator) -> None:
    image = _image(rng)
    ellipses = _ellipses(rng, 4)
    lines = outlines(ellipses)
    got = supported_runs(outline_rows(ellipses)[:4], image)
    ok = contrast_profiles(lines, image) >= max(image.params.support_min_contrast,
                                                image.params.support_noise_multiple * 4.0)
    assert np.array_equal(got.ok, ok)
    assert np.array_equal(got.offsets, lines.offsets)
    assert np.array_equal(got.counts, lines.counts)


def test_run_ends_of_whole_empty_and_wrapping_outlines(rng: np.random.Generator) -> None:
    counts = np.array([16, 20, 30, 17], np.int64)
    ok = rng.random(int(counts.sum())) < 0.6
    ok[:16] = True  # one outline wholly supported
    ok[16:36] = False  # one wholly unsupported
    ok[36], ok[65] = False, False  # a run wrapping round the third outline's start
    offsets = np.concatenate([[0], np.cumsum(counts)])
    window = np.concatenate([(np.arange(n) + _SHIFTS[:, None]) % n + start
                             for n, start in zip(counts, offsets[:-1], strict=True)], axis=1)
    got = kernels_pose.run_ends(ok, counts)
    for a, b in zip(got, _runs_form(ok, offsets, window), strict=True):
        assert np.array_equal(a, b)


def test_the_support_map_path_reads_the_rounded_samples(rng: np.random.Generator) -> None:
    support = (rng.random((60, 80)) < 0.5).astype(np.uint8)
    ellipses = _ellipses(rng, 5)
    lines = outlines(ellipses)
    pix = np.rint(lines.points).astype(np.int64)
    inside = (pix[:, 0] >= 0) & (pix[:, 0] < 80) & (pix[:, 1] >= 0) & (pix[:, 1] < 60)
    ok = np.zeros(pix.shape[0], bool)
    ok[inside] = support[pix[inside, 1], pix[inside, 0]] > 0
    got = _support_along(outline_rows(ellipses)[:4], support, None)
    assert np.array_equal(got.points, lines.points) and np.array_equal(got.ok, ok)
    for a, b in zip((got.supported, got.firsts, got.lasts),
                    _runs_form(ok, lines.offsets, lines.window), strict=True):
        assert np.array_equal(a, b)


def _shrunk_forms(ellipses: list[Ellipse], margin: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """kernels.interior_counts' (E, 6) forms and row counts, on Python floats."""
    params, sizes = [], []
    for e in ellipses:
        t = math.radians(e.angle_deg)
        c, s = math.cos(t), math.sin(t)
        ia = 1.0 / max(e.a - margin, 1e-6) ** 2
        ib = 1.0 / max(e.b - margin, 1e-6) ** 2
        p, q, r = c * c * ia + s * s * ib, 2.0 * c * s * (ia - ib), s * s * ia + c * c * ib
        half = math.sqrt(p / (p * r - 0.25 * q * q))
        first = math.ceil(e.cy - half)
        params.append((e.cx, e.cy, p, q, r, float(first)))
        sizes.append(max(0, math.floor(e.cy + half) - first + 1))
    return np.array(params).reshape(-1, 6), np.array(sizes, np.int64)


@pytest.mark.parametrize("pixels", [0, 1, 40, 1500, 6000])
def test_interior_counts_of_are_the_shrunk_forms_counts(rng: np.random.Generator,
                                                        pixels: int) -> None:
    uv = np.unique(rng.integers(0, 100, (pixels, 2)), axis=0).reshape(-1, 2)
    width = int(uv[:, 0].max()) + 2 if pixels else 0
    keys = np.sort(uv[:, 1] * width + uv[:, 0]).astype(np.float64)
    margin = TopParams().interior_margin_px
    # Random ones, and ones beyond the keys' columns and rows on every side.
    ellipses = _ellipses(rng, 12, 100.0, 100.0) + [
        Ellipse.of(cx, cy, 20.0, 12.0, 30.0)
        for cx, cy in ((300.0, 50.0), (-40.0, 50.0), (50.0, -30.0), (50.0, 130.0))]
    want = kernels.interior_counts(*_shrunk_forms(ellipses, margin), keys, width)
    got = kernels_pose.interior_counts_of(outline_rows(ellipses)[0], margin, keys, width)
    assert np.array_equal(got, want)
    assert want.sum() > 0 or pixels < 100


@pytest.mark.parametrize("belt", [None, (90.0, 90.0, 95.0)])
def test_wall_hits_are_the_bands_then_their_colour_test(rng: np.random.Generator,
                                                        belt: tuple[float, ...] | None) -> None:
    k = CameraIntrinsics.from_fovy(45.0, 160, 120)
    image = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    image[rng.random((120, 160)) < 0.5] = (200, 90, 40)  # the face's colour at wall brightness
    face = np.array([240.0, 110.0, 50.0])
    params = PoseParams(band_brightness_margin=0.5)
    shares = []
    for e in _ellipses(rng, 5, 160.0, 120.0):
        unit = unit_circle_poses(e, k)
        solutions = [(s.normal_cam, s.centre_cam) for s in unit]
        pu, pv, keep = solution_bands(solutions, e, k, params.wall_depths,
                                      params.wall_margin_px)
        belt_rgb = None if belt is None else np.array(belt)
        want = band_evidences(pu.reshape(2, -1), pv.reshape(2, -1), keep.reshape(2, -1), image,
                              np.stack([face, face]), [tan_tilt(n, c) for n, c in solutions],
                              belt_rgb, params)
        assert wall_evidences(solutions, e, k, image, face, belt_rgb, params) == want
        shares += [w.share for w in want]
    assert 0.0 < max(shares) < 1.0


_COMPILES_AFTER_WARM_UP = r"""
import sys
from pathlib import Path
from numba.core.registry import CPUDispatcher
from stackpick_sim.config.loader import load_scene
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.benchmark.frames import load_frame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.detector import TopObjectDetector
kernels.warm_up()
compiled = {n: k for n, k in vars(kernels_pose).items() if isinstance(k, CPUDispatcher)}
warm = {n: set(k.signatures) for n, k in compiled.items()}
scene = load_scene("paper")
kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
              for t in scene.object_types.values())
folder = Path(sys.argv[1])
for png in sorted(folder.glob("*.png")):
    frame = load_frame(folder, int(png.stem), scene.conveyor.top_z,
                       scene.objects.max_face_height, kinds)
    detector = TopObjectDetector(detector_config(frame))
    detector.detect(frame.image_rgb)
    detector.detect(frame.image_rgb.mean(axis=2).astype("uint8"))
print(sorted(n for n, k in compiled.items() if set(k.signatures) - warm[n]))
"""


def test_warm_up_compiles_every_pass_for_the_types_the_detector_passes() -> None:
    frames = Path(__file__).parent / "data" / "paper_dev_frames"
    out = subprocess.run([sys.executable, "-c", _COMPILES_AFTER_WARM_UP, str(frames)],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout

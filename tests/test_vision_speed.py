"""The detector's speed helpers give what the plain forms give."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels
from stackpick_sim.vision.contrast import outlines
from stackpick_sim.vision.detection import DetectedEllipse
from stackpick_sim.vision.detector import _chromaticities
from stackpick_sim.vision.edges import RING, STAIR_LUTS, colour_gradients, remove_stairs
from stackpick_sim.vision.fitting import ellipse_params, grouped_distances, pair_distances
from stackpick_sim.vision.merging import _repeats
from stackpick_sim.vision.pose import CirclePose, _solutions
from stackpick_sim.vision.wall import _floats

RNG = np.random.default_rng(7)
ELLIPSES = [Ellipse(cx=float(RNG.uniform(0, 200)), cy=float(RNG.uniform(0, 200)),
                    a=float(a), b=float(a * RNG.uniform(0.3, 1.0)),
                    angle_deg=float(RNG.uniform(0, 180)))
            for a in RNG.uniform(3.0, 60.0, 7)]


def test_ellipse_of_is_the_constructor() -> None:
    e = Ellipse.of(1.5, 2.5, 30.0, 20.0, 45.0)
    plain = Ellipse(cx=1.5, cy=2.5, a=30.0, b=20.0, angle_deg=45.0)
    assert e == plain and hash(e) == hash(plain) and repr(e) == repr(plain)
    with pytest.raises(AttributeError):
        e.cx = 3.0  # type: ignore[misc]


def test_detected_ellipse_of_is_the_constructor() -> None:
    e = Ellipse.of(1.5, 2.5, 30.0, 20.0, 45.0)
    fast = DetectedEllipse.of(e, (0, 3), 0.25, 0.75)
    plain = DetectedEllipse(ellipse=e, segments=(0, 3), residual_px=0.25, support=0.75)
    assert fast == plain and repr(fast) == repr(plain)
    with pytest.raises(AttributeError):
        fast.support = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("shift", [-20, -17, -16, -2, -1, 0, 1, 2, 15, 16, 40])
def test_cyclic_index_is_the_modular_one(shift: int) -> None:
    lines = outlines(ELLIPSES)
    starts = lines.offsets[lines.owner]
    counts = lines.counts[lines.owner]
    np.testing.assert_array_equal(lines.cyclic(shift),
                                  starts + (lines.local + shift) % counts)


def test_grouped_distances_are_pair_distances() -> None:
    params = ellipse_params(ELLIPSES)
    counts = RNG.integers(0, 30, len(ELLIPSES))
    which = np.repeat(np.arange(len(ELLIPSES)), counts)
    points = RNG.uniform(-20, 220, (which.size, 2))
    np.testing.assert_array_equal(
        grouped_distances(params, counts, points[:, 0].copy(), points[:, 1].copy()),
        pair_distances(params, points, which, np.arange(which.size)))


def test_floats_of_arrays_and_sequences() -> None:
    assert _floats(np.array([1.0, -2.5, 3.25])) == [1.0, -2.5, 3.25]
    assert _floats(np.array([1.0, 2.0, 3.0], np.float32)) == [1.0, 2.0, 3.0]
    assert _floats((1, 2, 3)) == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("channels", [1, 3])
def test_colour_gradients_take_each_pixels_strongest_channel(channels: int) -> None:
    rng = np.random.default_rng(channels)
    image = rng.integers(0, 256, (23, 31, channels), np.uint8)
    dx = np.stack([cv2.Sobel(image[:, :, c], cv2.CV_16S, 1, 0)
                   for c in range(channels)])
    dy = np.stack([cv2.Sobel(image[:, :, c], cv2.CV_16S, 0, 1)
                   for c in range(channels)])
    best = np.argmax(np.abs(dx.astype(int)) + np.abs(dy.astype(int)), axis=0)  # first of equals
    got_x, got_y = colour_gradients(image[:, :, 0] if channels == 1 else image)
    np.testing.assert_array_equal(got_x, np.take_along_axis(dx, best[None], 0)[0])
    np.testing.assert_array_equal(got_y, np.take_along_axis(dy, best[None], 0)[0])


def _codes(binary: np.ndarray) -> np.ndarray:
    """Each pixel's RING neighbour code, pixel by pixel (0 outside the image)."""
    framed = np.pad(binary, 1)
    h, w = binary.shape
    return sum(framed[1 + r:1 + r + h, 1 + c:1 + c + w].astype(int) << bit
               for bit, (r, c) in enumerate(RING))


def test_remove_stairs_is_two_table_passes() -> None:
    rng = np.random.default_rng(3)
    for density in (0.1, 0.3, 0.6):
        canny = np.where(rng.random((29, 37)) < density, 255, 0).astype(np.uint8)
        b = (canny > 0).astype(np.uint8)
        for lut in STAIR_LUTS:  # each pass reads every code before it removes any pixel
            b = b & (lut[_codes(b)] == 0)
        np.testing.assert_array_equal(remove_stairs(canny), b)
        np.testing.assert_array_equal(remove_stairs(canny > 0), b)


def test_repeats_tells_copies_from_chains_with_new_pixels() -> None:
    arc = np.array([[1, 2], [2, 2], [3, 3], [4, 3]], np.int32)
    chains = (arc, arc[:2], arc.copy(), np.concatenate([arc, [[5, 4]]]), arc[::-1].copy())
    assert _repeats(chains, [2], [0])  # the chain a whole piece was cut from
    assert _repeats(chains, [2, 0], [1, 0])
    assert not _repeats(chains, [2], [1])  # a half piece: the other half is new
    assert not _repeats(chains, [3], [0])  # one more pixel
    assert not _repeats(chains, [4], [0])  # the same pixels in another order


def test_circle_pose_of_is_the_constructor() -> None:
    normal, centre = np.array([0.0, 0.6, 0.8]), np.array([0.1, -0.2, 9.0])
    fast = CirclePose.of(normal, centre)
    plain = CirclePose(normal_cam=normal, centre_cam=centre)
    assert type(fast) is CirclePose and repr(fast) == repr(plain)
    assert fast.normal_cam is normal and fast.centre_cam is centre
    with pytest.raises(AttributeError):
        fast.normal_cam = centre  # type: ignore[misc]


def _on_numpys_eigh(cone: np.ndarray, packed: np.ndarray) -> tuple[np.ndarray, bool]:
    """kernels.circle_solutions of a cone's (16,) row on np.linalg.eigh of the cone."""
    w, v = np.linalg.eigh(cone)
    return kernels.circle_solutions(packed[:6], w, v, packed[6:12], packed[12:])


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e40, 1e99, 1e101])
def test_circle_solutions_are_on_numpys_eigh(scale: float) -> None:
    m = RNG.normal(0.0, 1.0, (3, 3))
    cone = (m + m.T) * scale
    packed = np.concatenate([cone[np.triu_indices(3)], RNG.uniform(1.0, 2.0, 10)])
    moderate = bool(np.all(np.abs(cone) <= 1e100))  # as kernels_pose.cone_of tells it
    got, ok = _solutions(cone, packed, moderate)
    want, want_ok = _on_numpys_eigh(cone, packed)
    np.testing.assert_array_equal(got, want)
    assert ok == want_ok and moderate == (scale < 1e100)


def test_circle_solutions_of_non_finite_entries_are_on_numpys_eigh() -> None:
    cone = np.diag([1.0, float("nan"), 2.0])
    packed = np.concatenate([cone[np.triu_indices(3)], np.ones(10)])
    got, ok = _solutions(cone, packed, False)
    want, want_ok = _on_numpys_eigh(cone, packed)
    np.testing.assert_array_equal(got, want)
    assert ok == want_ok


def test_chromaticities_of_tuples_and_lists_are_alike() -> None:
    colours = ((0.9, 0.3, 0.1), (0.2, 0.2, 0.8))
    got = _chromaticities(colours)
    assert got == _chromaticities([list(c) for c in colours])
    for (r, g, b), chroma in zip(colours, got, strict=True):
        assert chroma == (r / (r + g + b), g / (r + g + b), b / (r + g + b))

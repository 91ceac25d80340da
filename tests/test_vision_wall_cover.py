"""The wall T-junction rule: a whole face over another object's predicted wall is above it."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, normal_from_tilt, project_circle
from stackpick_sim.vision.pose import circle_poses, unit_circle_poses
from stackpick_sim.vision.wall import band_points, solution_band_points, solution_bands
from stackpick_sim.vision.wall_cover import (
    DEFAULT_TOP,
    cover_depths,
    covered_share,
    covered_shares,
    face_bands,
    under_another,
)

K = CameraIntrinsics.from_fovy(45.0, 320, 240)
COVER_MARGIN_PX = DEFAULT_TOP.cover_margin_px
MIN_COVER_SAMPLES = DEFAULT_TOP.cover_min_samples
MIN_COVERED_SHARE = DEFAULT_TOP.cover_min_share
#: A face tilted 35 deg about the camera's x axis: its wall shows on one side.
TILTED = project_circle(np.array([0.0, 0.0, 0.28]), normal_from_tilt(35.0, 0.0), 0.035, K)


def _disc_over_band(solution: int, radius_px: float) -> Ellipse:
    """A frontal disc centred on the middle of TILTED's predicted wall band."""
    sol = circle_poses(TILTED, K, 1.0)[solution]
    centre = band_points(sol.normal_cam, sol.centre_cam, TILTED, K).mean(axis=0)
    return Ellipse(cx=float(centre[0]), cy=float(centre[1]), a=radius_px, b=radius_px,
                   angle_deg=0.0)


def test_face_over_the_tilted_faces_wall_is_above_it() -> None:
    over = _disc_over_band(0, 25.0)
    assert covered_share(TILTED, over, K) >= 0.15
    assert under_another([TILTED, over], K) == [True, False]
    assert under_another([over, TILTED], K) == [False, True]


def test_faces_apart_are_not_under_each_other() -> None:
    far = Ellipse(cx=TILTED.cx + 3 * TILTED.a + 30, cy=TILTED.cy, a=20.0, b=20.0,
                  angle_deg=0.0)
    assert covered_share(TILTED, far, K) == 0.0
    assert under_another([TILTED, far], K) == [False, False]


def test_covered_shares_are_each_bands_share_inside_each_face() -> None:
    """The one-pass (n, n) shares equal Ellipse.inside of each solution's band_points, face
    by face (the same values, not just close)."""
    near = _disc_over_band(0, 25.0)
    faces = [TILTED, near, Ellipse(cx=60.0, cy=50.0, a=30.0, b=18.0, angle_deg=70.0),
             project_circle(np.array([0.03, -0.02, 0.3]), normal_from_tilt(-20.0, 30.0),
                            0.025, K)]
    shares = covered_shares(faces, K)
    for i, face in enumerate(faces):
        bands = [band_points(s.normal_cam, s.centre_cam, face, K, cover_depths())
                 for s in circle_poses(face, K, 1.0)]
        bands = [b for b in bands if b.shape[0] >= MIN_COVER_SAMPLES]
        for j, other in enumerate(faces):
            alone = max((float(np.mean(other.inside(b, COVER_MARGIN_PX))) for b in bands),
                        default=0.0)
            assert shares[i, j] == (0.0 if i == j else alone)
    assert shares[0, 1] >= MIN_COVERED_SHARE


def test_solution_band_point_depths_are_those_of_the_projected_pixels() -> None:
    """solution_band_points' depths follow solution_bands' point order: the points rebuilt
    from them project onto solution_bands' pixels."""
    sols = [(s.normal_cam, s.centre_cam) for s in circle_poses(TILTED, K, 1.0)]
    pu, pv, _ = solution_bands(sols, [TILTED, TILTED], K, cover_depths())
    depth = solution_band_points(sols, cover_depths())[2]
    assert depth.shape == pu.shape
    for k, (normal, centre) in enumerate(sols):
        # Back-project each pixel to its depth: it must land on the solution's wall cylinder
        # (unit radius) at the given depth fraction of the axis.
        ray = np.stack([(pu[k] - K.cx) / K.fx, (pv[k] - K.cy) / K.fy, np.ones_like(pu[k])])
        xyz = ray * depth[k]
        rel = xyz - np.asarray(centre)[:, None]
        along = np.asarray(normal) @ rel
        radial = np.linalg.norm(rel - np.outer(normal, along), axis=0)
        assert np.allclose(radial, 1.0, atol=1e-9)
        assert np.allclose(np.sort(np.unique(np.round(along, 9))), cover_depths())


@pytest.mark.parametrize(("over_radius_m", "under"), [(0.02, True), (0.035, False)])
def test_a_face_covers_a_wall_only_from_in_front(over_radius_m: float, under: bool) -> None:
    """The same image cover, with the covering disc's radius putting it in front of
    TILTED's wall (0.02 m: ~0.23 m deep) or far behind it (0.035 m: ~0.41 m; TILTED lies at
    0.28 m): only a face in front can hide the wall."""
    over = _disc_over_band(0, 25.0)
    radii = {TILTED: 0.035, over: over_radius_m}
    assert under_another([TILTED, over], K) == [True, False]  # the image test alone
    assert under_another([TILTED, over], K, radii.get) == [under, False]
    shares = covered_shares([TILTED, over], K, [0.035, over_radius_m])
    assert (shares[0, 1] >= MIN_COVERED_SHARE) == under
    # An unknown radius leaves the image test as it was.
    assert under_another([TILTED, over], K, {TILTED: 0.035}.get) == [True, False]


def test_face_bands_are_each_faces_solution_bands_in_any_order() -> None:
    other = project_circle(np.array([0.05, 0.02, 0.3]), normal_from_tilt(20.0, 40.0), 0.025, K)
    square = Ellipse(cx=60.0, cy=70.0, a=22.0, b=22.0, angle_deg=0.0)
    faces = [TILTED, other, square]
    cache: dict = {}
    for order, kept in ((faces, None), (faces[::-1], cache), ([other, other, TILTED], cache),
                        ([square, other], cache)):
        pu, pv, keep = face_bands(order, K, kept)
        for i, face in enumerate(order):
            sols = [(s.normal_cam, s.centre_cam) for s in unit_circle_poses(face, K)]
            want = solution_bands(sols, [face, face], K, cover_depths())
            for got, expected in zip((pu, pv, keep), want, strict=True):
                np.testing.assert_array_equal(got[2 * i:2 * i + 2], expected)
    assert len(cache) == 3  # each face's bands computed once

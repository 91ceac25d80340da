"""The wall T-junction rule: a whole face over another object's predicted wall is above it."""

from __future__ import annotations

import numpy as np

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, normal_from_tilt, project_circle
from stackpick_sim.vision.pose import MIN_BAND_SAMPLES, circle_poses
from stackpick_sim.vision.wall import band_points
from stackpick_sim.vision.wall_cover import (
    COVER_DEPTH_FRACTIONS,
    COVER_MARGIN_PX,
    MIN_COVERED_SHARE,
    covered_share,
    covered_shares,
    under_another,
)

K = CameraIntrinsics.from_fovy(45.0, 320, 240)
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
        bands = [band_points(s.normal_cam, s.centre_cam, face, K, COVER_DEPTH_FRACTIONS)
                 for s in circle_poses(face, K, 1.0)]
        bands = [b for b in bands if b.shape[0] >= MIN_BAND_SAMPLES]
        for j, other in enumerate(faces):
            alone = max((float(np.mean(other.inside(b, COVER_MARGIN_PX))) for b in bands),
                        default=0.0)
            assert shares[i, j] == (0.0 if i == j else alone)
    assert shares[0, 1] >= MIN_COVERED_SHARE

"""A synthetic 320x240 frame of two faces, a lower one partly under a top one, shared by the
detector's stage and setting tests."""
from __future__ import annotations

import numpy as np

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.synthetic import draw_ellipses

SHAPE = (240, 320)
K = CameraIntrinsics.from_fovy(45.0, 320, 240)
#: A lower face (semi-minor axis 34 px) partly under a top face (38 px, drawn last).
FACES = [Ellipse(cx=200, cy=110, a=40, b=34, angle_deg=-10),
         Ellipse(cx=150, cy=120, a=45, b=38, angle_deg=20)]


def two_face_image() -> np.ndarray:
    """FACES drawn on SHAPE with noise of std 1.5 grey levels (seeded)."""
    return draw_ellipses(SHAPE, FACES, noise_sigma=1.5, rng=np.random.default_rng(4))

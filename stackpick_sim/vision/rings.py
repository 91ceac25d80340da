"""Ring faces: the face of a roll (tape, a wound reel) round its core's hole.

Failure class: *a ring face failed on its hole*. A roll's face is a ring: its outline shows
whole, but the hole's outline (and, the roll tilted, the core's inner wall seen through the
hole) lies inside it as interior edges. Those are too few for the markings rule (a hole of a
quarter of the face's radius leaves about a third of its perimeter, well below
``marking_min_edge_share``), so the face fails the top rule on interior edges, and a lower
face of another object is taken instead.

What tells a hole from an object lying on the face is where its edges lie. An object resting
on the face is nearer the camera than it, so in the image it is at least the smallest object
kind's radius over the face's kind's radius of the face's size (the markings rule's depth
argument, :mod:`~stackpick_sim.vision.markings`), and it is fitted as an ellipse of its own
that passes the rule and blocks the face. A hole's edges all lie in a small concentric
ellipse: the face's ellipse at ``ring_hole_scale`` of its semi-axes (a roll's core, 25.4 mm
on a 100 mm roll, is a quarter of it; printed artwork and a can end's rings spread over the
whole face and reach its rim). So a whole face that failed on interior edges alone, at least
``ring_hole_share`` of which lie in that ellipse (and in the one the smallest object's size
allows), is judged as a face with markings: the hole, when it is fitted, is its marking, and
the face is a candidate for the top unless a face lies on it. The pick aims at the ring
(:mod:`~stackpick_sim.control.pick_point`), so the reported face is the outer ellipse.

The test reads the edge pixels inside the face (one compiled pass over the edge map's
pixels): no image pass.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import kernels_top


def hole_only(face: Ellipse, edge_points: NDArray[np.float64], margin_px: float,
              hole_scale: float, hole_share: float) -> bool:
    """Whether at least ``hole_share`` of the edge pixels ``edge_points`` ((M, 2) u, v) lying
    more than ``margin_px`` inside ``face`` lie inside its concentric ellipse at
    ``hole_scale`` of its semi-axes (False when none lies inside the face)."""
    # The box, the inside test and the hole test in one compiled pass over the pixels
    # (kernels_top.hole_counts: the same tests as Ellipse.bounds and Ellipse.inside).
    t = math.radians(face.angle_deg)
    inside, in_hole = kernels_top.hole_counts(
        np.ascontiguousarray(edge_points[:, 0], np.float64),
        np.ascontiguousarray(edge_points[:, 1], np.float64), face.bounds(), face.cx, face.cy,
        math.cos(t), math.sin(t),
        (max(face.a - margin_px, 1e-6), max(face.b - margin_px, 1e-6)), (face.a, face.b),
        hole_scale * hole_scale)
    return inside > 0 and in_hole / inside >= hole_share

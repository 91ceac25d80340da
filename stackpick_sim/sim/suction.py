"""Whether the suction cup seals on a face: the vacuum holds only where the lip lies flat.

The cup model (models/suction_cup) pulls with an adhesion actuator, which would lift
whatever the lip touches. A real bellows cup holds only when its lip closes on the surface:

- the lip's disc (radius :func:`lip_radius`, centred where the cup axis meets the face
  plane) lies wholly on sealing surface: inside the face's outline, not over a hole (a tape
  roll's core), and over surface whose height varies by at most ``suction.flatness_tol``
  (a can lid's raised rim against its recessed panel);
- the cup axis is within ``suction.compliance_deg`` of the face normal (the bellows' folds
  take up that much misalignment).

A face is described by its :class:`FaceProfile`: concentric rings of sealing surface, each
at its own height along the face normal. :func:`seal_leak` is pure geometry, evaluated at
the moment the lip first reaches a face (``stackpick_sim.episodes.outcome.seal_leak``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import ObjectTypeCfg, SuctionCfg

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class Ring:
    """A ring of sealing surface on a face: radii from the face centre and height, m."""

    inner: float
    outer: float
    height: float = 0.0
    """Along the face's outward normal, relative to the face plane (a raised rim > 0)."""


@dataclass(frozen=True, kw_only=True)
class FaceProfile:
    """A round face as concentric rings of surface, inner to outer; gaps between are holes."""

    rings: tuple[Ring, ...]

    @property
    def radius(self) -> float:
        """Outer radius of the face, m."""
        return self.rings[-1].outer

    @classmethod
    def disc(cls, radius: float) -> FaceProfile:
        """A flat disc (a plain cylinder's cap)."""
        return cls(rings=(Ring(inner=0.0, outer=radius),))

    def heights_under(self, lo: float, hi: float) -> list[float] | None:
        """Heights of the rings met between radii ``lo`` and ``hi`` (m); None over a hole."""
        covered, found = lo, []
        for ring in self.rings:
            if ring.outer <= covered or ring.inner >= hi:
                continue
            if ring.inner > covered + 1e-9:
                return None  # a gap (hole) between the surface met so far and this ring
            found.append(ring.height)
            covered = ring.outer
            if covered >= hi:
                return found
        return None  # past the outer edge


def face_profile(kind: ObjectTypeCfg) -> FaceProfile:
    """The sealing surface of an object kind's cap (``object_types.*.kind``)."""
    r = kind.radius
    if kind.kind == "tape":
        return FaceProfile(rings=(Ring(inner=kind.hole_radius, outer=r),))
    if kind.kind == "can":
        # A recessed panel inside a raised rim; the rim's top is the face plane.
        panel = r - kind.rim_width
        return FaceProfile(rings=(Ring(inner=0.0, outer=panel, height=-kind.rim_height),
                                  Ring(inner=panel, outer=r)))
    return FaceProfile.disc(r)


def lip_radius(model: mujoco.MjModel, cup_body: int) -> float:
    """Outer radius of the cup's lip (m): the ring of lip spheres plus their radius."""
    reach = [math.hypot(*model.geom_pos[g][:2]) + float(model.geom_size[g][0])
             for g in range(model.ngeom)
             if model.geom_bodyid[g] == cup_body
             and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    if not reach:
        raise ValueError("the cup body has no lip spheres")
    return max(reach)


def seal_leak(cup_pos: FloatArray, cup_axis: FloatArray, face_centre: FloatArray,
              face_normal: FloatArray, profile: FaceProfile, lip: float,
              cfg: SuctionCfg) -> str | None:
    """Why the lip would leak on this face (one line), or None when it seals.

    ``cup_pos``: centre of the lip plane, world m; ``cup_axis``: unit approach direction
    (from the cup towards the part); ``face_centre`` and ``face_normal`` (unit, outward) of
    the face, world; ``lip``: the lip's outer radius, m.
    """
    cos = float(np.clip(-cup_axis @ face_normal, -1.0, 1.0))
    tilt = math.degrees(math.acos(cos))
    if tilt > cfg.compliance_deg:
        return (f"cup axis {tilt:.1f} deg off the face normal (bellows take up "
                f"{cfg.compliance_deg:g} deg)")
    # Where the cup axis meets the face plane: the centre of the lip's footprint.
    hit = cup_pos + cup_axis * (float((face_centre - cup_pos) @ face_normal)
                                / float(cup_axis @ face_normal))
    offset = hit - face_centre
    offset -= face_normal * float(offset @ face_normal)
    d = float(np.linalg.norm(offset))
    heights = profile.heights_under(max(0.0, d - lip), d + lip)
    if heights is None:
        where = "over the face's edge" if d + lip > profile.radius else "over a hole"
        return f"lip {where} (lip centre {1e3 * d:.1f} mm off the face centre)"
    step = max(heights) - min(heights)
    if step > cfg.flatness_tol:
        return (f"lip across a {1e3 * step:.1f} mm step (flatness tolerance "
                f"{1e3 * cfg.flatness_tol:.1f} mm)")
    return None

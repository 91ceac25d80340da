"""Where on a face the cup aims: a point where its lip seals (:mod:`stackpick_sim.sim.suction`).

On a plain disc and on a can's recessed panel that is the face centre, where the lip has
the same margin to every side. On a tape roll's ring face the centre lies over the core
hole, where the lip cannot seal: the cup aims at the middle of the band of distances from
the centre at which the whole lip lies on the ring (the ring's mid-radius when the ring is
wider than the lip's diameter), which leaves equal margin to the hole and to the outer edge.

The controller knows its own cup (the lip's radius, the seal's flatness tolerance) and the
scene's object kinds (``object_types``), but not which kind the tracked face is: it takes
the kinds of the pile whose radius is nearest the tracked face's (the estimator's radius)
and aims where the lip seals on every one of them.

Which side of the ring: up the face's slope, its highest point. A roll's centre of mass
lies below its face, shifted towards the face's high side, so a grip there has the shortest
lever for gravity as the roll is lifted (gripped on the low side of a steep face, a roll
can turn in the cup). A face within a few degrees of level has no slope to speak of: there
the side away from the wrist camera decides (:func:`aim_direction`). The camera rides off
the tool axis; with the aim on its far side the face centre lies between the tool axis and
the camera's line of sight, and the face stays nearer the middle of the image. That side
is taken once, when the approach starts, as a world direction: the aim does not follow the
tool's own turning.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig, SuctionCfg
from stackpick_sim.pipeline import TargetState
from stackpick_sim.sim.suction import FaceProfile, face_profile, seal_leak

FloatArray = NDArray[np.float64]

#: Step of the distances from the face centre at which the seal is tried, m.
OFFSET_STEP = 1e-4
#: World up.
UP: FloatArray = np.array([0.0, 0.0, 1.0])
#: Weight of the side away from the camera against the face's slope (``sin(tilt)``) in the
#: aim's direction: the slope decides from a few degrees of tilt on (sin 5 deg = 0.087).
FLAT_WEIGHT = 0.087
#: Kinds whose radius lies within this of the nearest one to the tracked radius are taken as
#: the tracked face's possible kinds, m (radii of distinct kinds differ by millimetres).
RADIUS_MATCH = 5e-4


def seals_at(profile: FaceProfile, offset: float, lip: float, cfg: SuctionCfg) -> bool:
    """Whether a lip of radius ``lip`` (m) square on the face, its centre ``offset`` m from
    the face centre, seals (:func:`stackpick_sim.sim.suction.seal_leak`)."""
    cup = np.array([offset, 0.0, 0.01])
    return seal_leak(cup, -UP, np.zeros(3), UP, profile, lip, cfg) is None


def aim_offset(profiles: list[FaceProfile], lip: float, cfg: SuctionCfg) -> float:
    """Distance (m) from the face centre at which the lip seals on every one of ``profiles``.

    0 where the centre seals on all; otherwise the middle of the widest band of distances
    that seal on all; 0 when no distance does (the cup cannot seal on every kind: it aims
    at the centre, and a leak is reported at contact).
    """
    if not profiles:
        return 0.0
    radius = min(p.radius for p in profiles)
    offsets = np.arange(0.0, radius + OFFSET_STEP / 2, OFFSET_STEP)
    ok = np.array([all(seals_at(p, float(d), lip, cfg) for p in profiles) for d in offsets])
    if ok[0] or not ok.any():
        return 0.0
    # Runs of sealing distances: starts and ends (exclusive) of the runs of True.
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    starts, ends = edges[::2], edges[1::2]
    widest = int(np.argmax(ends - starts))
    return float(offsets[starts[widest]] + offsets[ends[widest] - 1]) / 2


class PickPoint:
    """The aim of a scene's pick: :func:`aim_offset` for the kinds of the tracked radius."""

    def __init__(self, cfg: SceneConfig, lip: float) -> None:
        names = list(dict.fromkeys(cfg.objects.types))
        self._kinds = [(name, cfg.object_types[name].radius,
                        face_profile(cfg.object_types[name])) for name in names]
        self._lip = lip
        self._suction = cfg.suction
        self._cache: dict[float, float] = {}

    def kinds(self, radius: float | None) -> list[str]:
        """Names of the scene's object kinds (``object_types``) the controller takes a face of
        ``radius`` m to be: those whose radius is nearest it (empty when unknown)."""
        if radius is None or radius <= 0.0 or not self._kinds:
            return []
        nearest = min(abs(r - radius) for _, r, _ in self._kinds)
        return [name for name, r, _ in self._kinds if abs(r - radius) <= nearest + RADIUS_MATCH]

    def offset(self, radius: float | None) -> float:
        """Aim distance from the centre (m) of a face of ``radius`` m (None: unknown, 0)."""
        kinds = self.kinds(radius)
        if not kinds:
            return 0.0
        assert radius is not None
        if radius not in self._cache:
            profiles = [p for name, _, p in self._kinds if name in kinds]
            self._cache[radius] = aim_offset(profiles, self._lip, self._suction)
        return self._cache[radius]


def aim_direction(normal: FloatArray, side: FloatArray) -> FloatArray | None:
    """(3,) unit direction across a face (inward ``normal``, world) to its aim point, or None.

    Up the face: the component of world up in the face plane (length ``sin(tilt)``), plus
    FLAT_WEIGHT times the unit component of ``-side`` in it, which decides on faces within a
    few degrees of level and keeps the direction continuous as the tilt passes zero.
    """
    n = np.asarray(normal, dtype=float) / float(np.linalg.norm(normal))
    up = UP - n * float(UP @ n)
    away = -(np.asarray(side, dtype=float) - n * float(np.asarray(side) @ n))
    norm = float(np.linalg.norm(away))
    direction = up + (FLAT_WEIGHT * away / norm if norm > 1e-9 else 0.0)
    length = float(np.linalg.norm(direction))
    return direction / length if length > 1e-9 else None


def aimed(state: TargetState, offset: float, side: FloatArray) -> TargetState:
    """``state`` with its centre moved ``offset`` m across the face (:func:`aim_direction`
    with ``side``, the camera's side of the tool axis, world)."""
    if offset <= 0.0:
        return state
    direction = aim_direction(state.normal, side)
    if direction is None:
        return state
    return replace(state, centre=state.centre + offset * direction)

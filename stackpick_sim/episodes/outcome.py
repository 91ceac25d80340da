"""Ground-truth checks of an episode: which object is where, held, knocked off, matched.

These read the simulator's state, never the controller's beliefs; only the episode's
bookkeeping and the record use them (the controller sees only detections).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, tilt_angles
from stackpick_sim.sim.cell import Cell, ObjectInfo
from stackpick_sim.sim.ground_truth import FrameTruth, top_face
from stackpick_sim.sim.robot import CUP_BODY, TOOL_SITE
from stackpick_sim.sim.suction import face_profile, lip_radius, seal_leak

FloatArray = NDArray[np.float64]

#: MuJoCo warnings that mean the physics went wrong (MuJoCo resets the state on them).
UNSTABLE_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS,
                     mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_CONTACTFULL,
                     mujoco.mjtWarning.mjWARN_CNSTRFULL)
#: A contact of the cup's lip counts as touching when its distance is below the lip geoms'
#: ``gap`` (the suction cup model's 5 mm adhesion reach), m.
LIP_REACH = 0.005


def lip_geoms(cell: Cell) -> frozenset[int]:
    """Ids of the suction cup's lip spheres (the collision spheres of the cup body)."""
    model = cell.model
    cup = model.body(CUP_BODY).id
    return frozenset(g for g in range(model.ngeom) if model.geom_bodyid[g] == cup
                     and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE)


def touching(cell: Cell, lips: frozenset[int]) -> list[ObjectInfo]:
    """Objects within LIP_REACH of the cup's lip, from the current contact list."""
    by_geom = {o.geom_id: o for o in cell.objects}
    found: dict[str, ObjectInfo] = {}
    data = cell.data
    for c in data.contact[: data.ncon]:
        g0, g1 = int(c.geom[0]), int(c.geom[1])
        if c.dist > LIP_REACH:
            continue
        if g0 in lips and g1 in by_geom:
            found[by_geom[g1].name] = by_geom[g1]
        elif g1 in lips and g0 in by_geom:
            found[by_geom[g0].name] = by_geom[g0]
    return sorted(found.values(), key=lambda o: o.name)


def no_seal(cell: Cell, touched: list[ObjectInfo]) -> str | None:
    """Why the cup's lip leaks on every face it touches (one line), or None once one seals.

    The seal model of :mod:`stackpick_sim.sim.suction` (``suction.seal``; off: always None),
    on the face of each touched object that faces the cup, with the cup's current pose.
    """
    cfg = cell.cfg.suction
    if not cfg.seal or not touched:
        return None
    model, data = cell.model, cell.data
    site = model.site(TOOL_SITE).id
    cup_pos = data.site_xpos[site].copy()
    cup_axis = data.site_xmat[site].reshape(3, 3)[:, 2].copy()
    lip = lip_radius(model, model.body(CUP_BODY).id)
    leaks = []
    for obj in touched:
        centre, normal = top_face(cell, obj, cup_pos)
        profile = face_profile(cell.cfg.object_types[obj.type_name])
        leak = seal_leak(cup_pos, cup_axis, centre, normal, profile, lip, cfg)
        if leak is None:
            return None
        leaks.append(f"{obj.name}: {leak}")
    return "; ".join(leaks)


@dataclass(frozen=True, kw_only=True)
class AimBelief:
    """What the controller believed when the cup reached the face: the record's side of the
    aim (the audit compares it with the truth)."""

    radius: float | None
    """The tracked face's radius, m (None: unknown)."""
    kinds: tuple[str, ...]
    """The object kinds taken for the face (``object_types`` names)."""
    offset: float
    """Distance of the aim point from the tracked face centre, m."""
    point: FloatArray
    """(3,) the aim point, world, m."""


def lip_on_face(cup_pos: FloatArray, cup_axis: FloatArray, centre: FloatArray,
                normal: FloatArray) -> tuple[float, float] | None:
    """(offset, height) m of the lip on a face: the distance from the face ``centre`` (3,)
    at which the cup axis (``cup_axis`` (3,) unit, through ``cup_pos`` (3,), world) meets
    the face plane, and ``cup_pos``'s height above that plane along the outward unit
    ``normal`` (3,); None when the axis runs parallel to the plane."""
    along = float(cup_axis @ normal)
    if abs(along) < 1e-9:
        return None
    height = float((cup_pos - centre) @ normal)
    hit = cup_pos - cup_axis * (height / along)
    offset = hit - centre
    offset -= normal * float(offset @ normal)
    return float(np.linalg.norm(offset)), height


def distance_to_axis(point: FloatArray, cup_pos: FloatArray, cup_axis: FloatArray) -> float:
    """Distance (m) of ``point`` (3,) from the line through ``cup_pos`` along unit
    ``cup_axis`` (3,), world."""
    rel = np.asarray(point, dtype=float) - cup_pos
    return float(np.linalg.norm(rel - cup_axis * float(rel @ cup_axis)))


def unstable(cell: Cell) -> str | None:
    """Why the physics state is unusable (a MuJoCo warning or a non-finite value), or None."""
    data = cell.data
    for w in UNSTABLE_WARNINGS:
        if data.warning[w].number > 0:
            return f"MuJoCo warning {mujoco.mjtWarning(w).name} at t={data.time:.3f} s"
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        return f"non-finite state at t={data.time:.3f} s"
    return None


def axis_turn_deg(cell: Cell, obj: ObjectInfo, start_axis: FloatArray) -> float:
    """Angle (deg) between ``obj``'s cylinder axis now and ``start_axis`` (3,), world frame."""
    axis = cell.data.xmat[obj.body_id].reshape(3, 3)[:, 2]
    cos = float(np.clip(axis @ start_axis, -1.0, 1.0))
    return float(np.degrees(np.arccos(cos)))


def match_object(truth: FrameTruth, pixel: FloatArray) -> str | None:
    """The object whose true face ellipse contains ``pixel`` (nearest centre wins), or None."""
    best: tuple[float, str] | None = None
    for o in truth.objects:
        e = o.ellipse
        if e is None:
            continue
        d = float(np.hypot(pixel[0] - o.face_center_px[0], pixel[1] - o.face_center_px[1]))
        if d <= e.b and (best is None or d < best[0]):
            best = (d, o.name)
    return None if best is None else best[1]


def face_in_view(cell: Cell, obj: ObjectInfo, world_T_cam: FloatArray,
                 k: CameraIntrinsics) -> tuple[tuple[float, float, float, float], FloatArray]:
    """((x px, y px, theta_x deg, theta_y deg), centre world (3,)) of a face, true pose."""
    centre_w, normal_w = top_face(cell, obj, world_T_cam[:3, 3])
    return view_pose(centre_w, -normal_w, world_T_cam, k), centre_w


def view_pose(centre_w: FloatArray, inward_w: FloatArray, world_T_cam: FloatArray,
              k: CameraIntrinsics) -> tuple[float, float, float, float]:
    """The paper's pose (x px, y px, theta_x deg, theta_y deg) of a face seen from a camera."""
    r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
    c = r.T @ (centre_w - p)
    u, v = k.project(c)[0]
    tx, ty = tilt_angles(r.T @ inward_w)
    return float(u), float(v), tx, ty

"""Exact per-frame ground truth, from the simulator's state, not from the image.

For each cylinder: the analytic image ellipse of its top face (``geometry.project_circle``),
the projected face centre (not the ellipse centre under perspective), the face tilt angles
(the paper's theta_x, theta_y), the visible fraction of the face (segmentation rendering), who
rests on whom (contacts) and ``is_top``: nothing rests on it and its face is >= 98% visible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle, tilt_angles
from stackpick_sim.sim.cell import OFF_BELT_DROP, Cell, ObjectInfo

__all__ = ["OFF_BELT_DROP", "TOP_VISIBLE_FRACTION", "FrameTruth", "ObjectTruth", "frame_truth",
           "resting_on", "top_face"]

#: A face at least this visible (and with nothing resting on it) is a top object: the pick
#: target every detector and success rate is measured against.
TOP_VISIBLE_FRACTION = 0.98
#: Visibility is measured on the face ellipse shrunk by this many pixels, so that rasterisation
#: at the outline (half a pixel either way) does not count as occlusion.
VISIBILITY_INSET_PX = 1.0
#: A contact whose normal has at least this upward component means "resting on".
RESTING_NORMAL_Z = 0.3


@dataclass(frozen=True, kw_only=True)
class ObjectTruth:
    """Ground truth of one cylinder in one frame."""

    name: str
    type_name: str
    radius: float
    """m"""
    height: float
    """m"""
    ellipse: Ellipse | None
    """Image of the top-face rim; None if the face reaches behind the camera."""
    face_center_px: tuple[float, float]
    """Projection of the face centre, px (u, v)."""
    face_center_cam: tuple[float, float, float]
    """Face centre in the camera frame, m."""
    face_center_world: tuple[float, float, float]
    """Face centre in the world frame, m."""
    face_normal_cam: tuple[float, float, float]
    """Unit face normal pointing into the object, camera frame."""
    theta_x_deg: float
    theta_y_deg: float
    tilt_deg: float
    """Angle between the cylinder's axis and world vertical, degrees (0 = upright)."""
    visible_fraction: float
    """Share of the top face seen by the camera, [0, 1] (pixels outside the image are unseen)."""
    supports: tuple[str, ...]
    """Names of the objects resting on this one."""
    on_belt: bool
    is_top: bool

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict."""
        return {
            "name": self.name, "type": self.type_name, "radius": self.radius,
            "height": self.height,
            "ellipse": self.ellipse.as_dict() if self.ellipse is not None else None,
            "face_center_px": list(self.face_center_px),
            "face_center_cam": list(self.face_center_cam),
            "face_center_world": list(self.face_center_world),
            "face_normal_cam": list(self.face_normal_cam),
            "theta_x_deg": self.theta_x_deg, "theta_y_deg": self.theta_y_deg,
            "tilt_deg": self.tilt_deg, "visible_fraction": self.visible_fraction,
            "supports": list(self.supports), "on_belt": self.on_belt, "is_top": self.is_top,
        }


@dataclass(frozen=True, kw_only=True)
class FrameTruth:
    """Ground truth of one camera frame."""

    time: float
    """Simulation time, s."""
    world_T_cam: NDArray[np.float64]
    """(4, 4) camera pose in the world, OpenCV camera axes."""
    intrinsics: CameraIntrinsics
    objects: tuple[ObjectTruth, ...]

    @property
    def top_objects(self) -> list[str]:
        """Names of the true top objects."""
        return [o.name for o in self.objects if o.is_top]

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (the schema of ``stackpick render``/``dataset`` JSON files)."""
        k = self.intrinsics
        return {
            "time": self.time,
            "width": k.width, "height": k.height,
            "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
            # Brown-Conrady (k1, k2, p1, p2, k3) of the image; ellipses and pixel positions
            # here are exact in undistorted pixels (cv2.undistortPoints with P = K).
            "distortion": list(k.dist),
            "world_T_cam": self.world_T_cam.tolist(),
            "objects": [o.as_dict() for o in self.objects],
            "top_objects": self.top_objects,
        }


def top_face(cell: Cell, obj: ObjectInfo,
             cam_pos: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(centre, outward unit normal) of the cap of ``obj`` that faces the camera, world frame."""
    data = cell.data
    centre = data.xpos[obj.body_id]
    axis = data.xmat[obj.body_id].reshape(3, 3)[:, 2]
    sign = 1.0 if axis @ (cam_pos - centre) >= 0 else -1.0
    normal = sign * axis
    return centre + normal * (obj.height / 2), normal


def resting_on(cell: Cell) -> dict[int, set[int]]:
    """Map object index -> indices of objects resting on it, from the current contacts."""
    geom_to_obj = {o.geom_id: i for i, o in enumerate(cell.objects)}
    out: dict[int, set[int]] = {i: set() for i in range(len(cell.objects))}
    data = cell.data
    for c in data.contact[: data.ncon]:
        i, j = geom_to_obj.get(int(c.geom[0])), geom_to_obj.get(int(c.geom[1]))
        if i is None or j is None:
            continue
        nz = c.frame[2]  # the contact normal points from geom[0] to geom[1]
        if nz >= RESTING_NORMAL_Z:
            out[i].add(j)
        elif nz <= -RESTING_NORMAL_Z:
            out[j].add(i)
    return out


def _inset(ellipse: Ellipse, px: float) -> Ellipse:
    return Ellipse(cx=ellipse.cx, cy=ellipse.cy, a=max(ellipse.a - px, 0.5),
                   b=max(ellipse.b - px, 0.5), angle_deg=ellipse.angle_deg)


def _visible_fraction(ellipse: Ellipse, obj: ObjectInfo, seg: NDArray[np.int32],
                      hole: Ellipse | None = None) -> float:
    """Share of the face (inside ``ellipse``, outside a tape roll's ``hole``) that the
    segmentation shows as one of ``obj``'s geoms."""
    inner = _inset(ellipse, VISIBILITY_INSET_PX)
    # Count the inset face on a canvas that holds all of it, so off-image pixels count as unseen.
    u0, v0, u1, v1 = inner.bounds()
    pad_u, pad_v = max(0, -math.floor(u0)), max(0, -math.floor(v0))
    h = max(seg.shape[0], math.ceil(v1) + 1) + pad_v
    w = max(seg.shape[1], math.ceil(u1) + 1) + pad_u
    shifted = Ellipse(cx=inner.cx + pad_u, cy=inner.cy + pad_v, a=inner.a, b=inner.b,
                      angle_deg=inner.angle_deg)
    full = shifted.mask((h, w))
    if hole is not None:
        full &= ~Ellipse(cx=hole.cx + pad_u, cy=hole.cy + pad_v, a=hole.a + VISIBILITY_INSET_PX,
                         b=hole.b + VISIBILITY_INSET_PX, angle_deg=hole.angle_deg).mask((h, w))
    total = int(np.count_nonzero(full))
    if total == 0:
        return 0.0
    in_image = full[pad_v:pad_v + seg.shape[0], pad_u:pad_u + seg.shape[1]]
    ids = obj.visual_geom_ids or (obj.geom_id,)
    return float(np.count_nonzero(in_image & np.isin(seg, ids))) / total


def _hole(cell: Cell, obj: ObjectInfo, centre_c: NDArray[np.float64],
          inward_c: NDArray[np.float64]) -> Ellipse | None:
    """Image of a tape roll's core hole on its face (None for other kinds)."""
    kind = cell.cfg.object_types[obj.type_name]
    if kind.kind != "tape":
        return None
    try:
        return project_circle(centre_c, inward_c, kind.hole_radius, cell.intrinsics)
    except ValueError:
        return None


def frame_truth(cell: Cell, segmentation: NDArray[np.int32]) -> FrameTruth:
    """Ground truth of the current state (after mj_forward), with its segmentation image."""
    world_T_cam = cell.world_T_cam()
    r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
    k = cell.intrinsics
    support = resting_on(cell)
    belt = cell.cfg.conveyor
    truths = []
    for i, obj in enumerate(cell.objects):
        centre_w, normal_w = top_face(cell, obj, p_wc)
        centre_c = r_wc.T @ (centre_w - p_wc)
        inward_c = -(r_wc.T @ normal_w)
        try:
            ellipse: Ellipse | None = project_circle(centre_c, inward_c, obj.radius, k)
        except ValueError:
            ellipse = None
        visible = (_visible_fraction(ellipse, obj, segmentation,
                                     _hole(cell, obj, centre_c, inward_c))
                   if ellipse is not None else 0.0)
        on_belt = (not cell.fell_off_belt(obj)
                   and bool(abs(cell.data.xpos[obj.body_id][1]) <= belt.length / 2))
        u, v = k.project(centre_c)[0]
        th_x, th_y = tilt_angles(inward_c)
        tilt = math.degrees(math.acos(min(1.0, abs(float(normal_w[2])))))
        resting = tuple(cell.objects[j].name for j in sorted(support[i]))
        truths.append(ObjectTruth(
            name=obj.name, type_name=obj.type_name, radius=obj.radius, height=obj.height,
            ellipse=ellipse, face_center_px=(float(u), float(v)),
            face_center_cam=tuple(float(x) for x in centre_c),  # type: ignore[arg-type]
            face_center_world=tuple(float(x) for x in centre_w),  # type: ignore[arg-type]
            face_normal_cam=tuple(float(x) for x in inward_c),  # type: ignore[arg-type]
            theta_x_deg=th_x, theta_y_deg=th_y, tilt_deg=tilt, visible_fraction=visible,
            supports=resting, on_belt=on_belt,
            is_top=(not resting) and on_belt and visible >= TOP_VISIBLE_FRACTION))
    return FrameTruth(time=float(cell.data.time), world_T_cam=world_T_cam, intrinsics=k,
                      objects=tuple(truths))

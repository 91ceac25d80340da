"""Motion during the exposure: the cell's state moved along its velocities, and motion blur.

A frame's exposure of ``camera.exposure_s`` is centred on its time stamp. Over a few
milliseconds every body moves at a nearly constant velocity, so the state at an offset
``tau`` from the time stamp is the current ``qpos`` integrated along ``qvel`` for ``tau``
(``mj_integratePos``; the belt's moving skin, a mocap body, moves ``tau`` times the belt's
current surface speed). :func:`subframe_offsets` places the renders of
``blur = "subframes"`` across the exposure; :func:`image_shift` is the pile's image motion
that ``blur = "shift"`` smears one render along.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import cv2
import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.sim.cell import Cell
from stackpick_sim.sim.ground_truth import top_face

#: Shifted copies per pixel of image motion in ``blur = "shift"`` (at least two copies).
SHIFT_COPIES_PER_PX = 3


def subframe_offsets(exposure_s: float, n: int) -> NDArray[np.float64]:
    """``n`` time offsets (s) at the middles of ``n`` equal slices of an exposure centred on 0."""
    return exposure_s * ((np.arange(n) + 0.5) / n - 0.5)


def _refresh(cell: Cell) -> None:
    """Positions, orientations, cameras and lights from ``qpos`` (what rendering reads)."""
    mujoco.mj_kinematics(cell.model, cell.data)
    mujoco.mj_camlight(cell.model, cell.data)


@contextmanager
def moved(cell: Cell) -> Iterator[Callable[[float], None]]:
    """A function that puts the cell's kinematics at an offset ``tau`` s from now; the state
    is restored on exit (positions recomputed from the saved ``qpos``)."""
    model, data = cell.model, cell.data
    qpos0, mocap0 = data.qpos.copy(), data.mocap_pos.copy()
    skin = cell.belt_skin_mocap
    belt_speed = float(model.geom_surfacevel[cell.belt_geom_id, 1])

    def at(tau: float) -> None:
        data.qpos[:] = qpos0
        mujoco.mj_integratePos(model, data.qpos, data.qvel, tau)
        if skin is not None:
            data.mocap_pos[skin] = mocap0[skin]
            data.mocap_pos[skin, 1] += belt_speed * tau
        _refresh(cell)

    try:
        yield at
    finally:
        data.qpos[:] = qpos0
        data.mocap_pos[:] = mocap0
        _refresh(cell)


def image_shift(cell: Cell, exposure_s: float) -> NDArray[np.float64]:
    """(2,) mean image motion (u, v px) across the exposure of the face centres in view."""
    k = cell.intrinsics
    ends = []
    with moved(cell) as at:
        for tau in (-exposure_s / 2, exposure_s / 2):
            at(tau)
            world_T_cam = cell.world_T_cam()
            r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
            centres = np.array([r.T @ (top_face(cell, o, p)[0] - p) for o in cell.objects])
            ends.append(k.project(centres) if len(centres) else np.zeros((0, 2)))
    # Faces in front of the camera and in its view at the exposure's start.
    front = np.array([c[2] > 1e-3 for c in centres]) if len(centres) else np.zeros(0, bool)
    u, v = ends[0][:, 0], ends[0][:, 1]
    seen = front & (u >= 0) & (u <= k.width - 1) & (v >= 0) & (v <= k.height - 1)
    if not seen.any():
        return np.zeros(2)
    return np.asarray((ends[1][seen] - ends[0][seen]).mean(axis=0), dtype=np.float64)


def smear_kernel(shift: NDArray[np.float64]) -> tuple[NDArray[np.float32], tuple[int, int]]:
    """The filter of :func:`smear`: (K, anchor (x, y)), a square kernel whose weights are the
    bilinear taps of every shifted copy, averaged."""
    length = float(np.hypot(*shift))
    n = max(2, math.ceil(length * SHIFT_COPIES_PER_PX) + 1)
    half = math.ceil(max(abs(float(shift[0])), abs(float(shift[1]))) / 2) + 1
    kernel = np.zeros((2 * half + 1, 2 * half + 1), dtype=np.float64)
    for s in np.linspace(-0.5, 0.5, n):
        # A copy translated by d reads the image at (x - d): taps round -d, bilinear weights.
        x, y = -s * shift[0], -s * shift[1]
        x0, y0 = math.floor(x), math.floor(y)
        fx, fy = x - x0, y - y0
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            for dx, wx in ((0, 1.0 - fx), (1, fx)):
                kernel[half + y0 + dy, half + x0 + dx] += wx * wy / n
    return kernel.astype(np.float32), (half, half)


def smear(image: NDArray[np.float32], shift: NDArray[np.float64]) -> NDArray[np.float32]:
    """Mean of copies of ``image`` translated evenly along ``shift`` (px), centred on it
    (bilinear, the border replicated): one filter (:func:`smear_kernel`) over the image."""
    kernel, anchor = smear_kernel(shift)
    out = cv2.filter2D(image, cv2.CV_32F, kernel, anchor=anchor, borderType=cv2.BORDER_REPLICATE)
    return np.asarray(out, dtype=np.float32).reshape(image.shape)

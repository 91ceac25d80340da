"""The suction seal: the lip must lie wholly on flat surface, the cup square enough to the face."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from stackpick_sim.config.scene_config import ObjectTypeCfg, SceneConfig, SuctionCfg
from stackpick_sim.episodes.outcome import lip_geoms, no_seal, touching
from stackpick_sim.sim.cell import Cell, build_cell
from stackpick_sim.sim.robot import TOOL_SITE
from stackpick_sim.sim.suction import FaceProfile, face_profile, seal_leak

CFG = SuctionCfg(compliance_deg=20.0, flatness_tol=0.001)
LIP = 0.015
DOWN = np.array([0.0, 0.0, -1.0])
UP = np.array([0.0, 0.0, 1.0])


def _leak(offset: float, tilt_deg: float = 0.0, profile: FaceProfile | None = None,
          cfg: SuctionCfg = CFG) -> str | None:
    """Leak of a cup 2 mm above a face at the origin, lip centre ``offset`` m along x."""
    a = np.radians(tilt_deg)
    axis = np.array([np.sin(a), 0.0, -np.cos(a)])
    hit = np.array([offset, 0.0, 0.0])
    return seal_leak(hit - 0.002 * axis, axis, np.zeros(3), UP,
                     profile or FaceProfile.disc(0.035), LIP, cfg)


def test_a_centred_square_cup_seals() -> None:
    assert _leak(0.0) is None
    assert _leak(0.019, tilt_deg=15.0) is None  # 15 deg: inside the bellows' 20


def test_a_lip_over_the_edge_leaks() -> None:
    leak = _leak(0.021)  # lip reaches 36 mm out on a 35 mm face
    assert leak is not None and "edge" in leak


def test_a_steep_cup_leaks_and_compliance_is_the_limit() -> None:
    leak = _leak(0.0, tilt_deg=25.0)
    assert leak is not None and "deg off the face normal" in leak
    assert _leak(0.0, tilt_deg=25.0, cfg=replace(CFG, compliance_deg=30.0)) is None


def test_a_tape_roll_seals_only_on_its_ring() -> None:
    tape = face_profile(ObjectTypeCfg(radius=0.05, height=0.03, mass=0.1, kind="tape",
                                      hole_radius=0.012))
    hole = _leak(0.0, profile=tape)
    assert hole is not None and "hole" in hole
    assert _leak(0.031, profile=tape) is None  # 16-46 mm: on the 12-50 mm ring
    assert _leak(0.036, profile=tape) is not None  # over the outer edge


def test_a_can_lid_seals_on_its_panel_not_across_its_rim() -> None:
    can = face_profile(ObjectTypeCfg(radius=0.035, height=0.05, mass=0.2, kind="can",
                                     rim_width=0.004, rim_height=0.002))
    assert _leak(0.015, profile=can) is None  # lip reaches 30 mm: inside the 31 mm panel
    leak = _leak(0.018, profile=can)
    assert leak is not None and "step" in leak
    assert _leak(0.018, profile=can, cfg=replace(CFG, flatness_tol=0.003)) is None


def _cup_over_face(cell: Cell, offset: float, tilt_deg: float) -> None:
    """Put obj0's cap 1 mm below the cup's lip, ``offset`` m off the cup axis, tilted."""
    model, data = cell.model, cell.data
    mujoco.mj_forward(model, data)
    site = model.site(TOOL_SITE).id
    tip, rot = data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()
    axis = rot[:, 2]
    a = np.radians(tilt_deg)
    normal = -(np.cos(a) * axis + np.sin(a) * rot[:, 0])  # outward, towards the cup
    obj = cell.objects[0]
    centre = tip + 0.001 * axis + offset * rot[:, 1] - normal * obj.height / 2
    quat = np.zeros(4)
    # The cylinder's +z along the outward normal: a rotation taking world z to ``normal``.
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, normal), float(z @ normal)
    mujoco.mju_axisAngle2Quat(quat, v / np.linalg.norm(v) if np.linalg.norm(v) > 1e-9 else z,
                              float(np.arctan2(np.linalg.norm(v), c)))
    data.qpos[obj.qpos_adr:obj.qpos_adr + 3] = centre
    data.qpos[obj.qpos_adr + 3:obj.qpos_adr + 7] = quat
    mujoco.mj_forward(model, data)


@pytest.fixture(scope="module")
def cell() -> Cell:
    return build_cell(SceneConfig(), ["small"])  # r = 25 mm: 10 mm of play for a 15 mm lip


@pytest.mark.parametrize(("offset", "tilt", "seals"), [
    (0.0, 0.0, True), (0.006, 10.0, True), (0.013, 0.0, False), (0.0, 30.0, False)])
def test_the_cells_cup_on_a_face(cell: Cell, offset: float, tilt: float, seals: bool) -> None:
    _cup_over_face(cell, offset, tilt)
    touched = touching(cell, lip_geoms(cell))
    assert [o.name for o in touched] == ["obj0"]
    assert (no_seal(cell, touched) is None) == seals


def test_seal_off_lifts_whatever_the_lip_touches(cell: Cell) -> None:
    _cup_over_face(cell, 0.0, 30.0)
    touched = touching(cell, lip_geoms(cell))
    loose = replace(cell, cfg=replace(cell.cfg, suction=SuctionCfg(seal=False)))
    assert touched and no_seal(loose, touched) is None

"""Where the cup aims: the face centre, or a tape roll's ring (off its hole), and the pick."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import ObjectTypeCfg, SuctionCfg
from stackpick_sim.control.pick_point import (
    PickPoint,
    aim_direction,
    aim_offset,
    aimed,
    seals_at,
)
from stackpick_sim.episodes import pick
from stackpick_sim.episodes.episode import run_episode
from stackpick_sim.pipeline import TargetState
from stackpick_sim.sim.stacks import generate_scene
from stackpick_sim.sim.suction import FaceProfile, face_profile

CFG = SuctionCfg()
LIP = 0.015
#: Piles of two or three tape rolls of the realistic scene's kind, the oracle detecting.
TAPES = ['objects.types=["tape"]', "objects.count=[2, 3]", 'episode.detector="oracle"']


def _kind(kind: str, radius: float, **extra: float) -> FaceProfile:
    return face_profile(ObjectTypeCfg(radius=radius, height=0.03, mass=0.1, kind=kind,
                                      **extra))  # type: ignore[arg-type]


def test_discs_and_can_panels_are_aimed_at_their_centre() -> None:
    assert aim_offset([FaceProfile.disc(0.025)], LIP, CFG) == 0.0
    assert aim_offset([_kind("can", 0.03, rim_width=0.0035)], LIP, CFG) == 0.0


def test_a_tape_roll_is_aimed_at_the_middle_of_its_sealing_band() -> None:
    tape = _kind("tape", 0.05, hole_radius=0.0127)
    offset = aim_offset([tape], LIP, CFG)
    # The lip (15 mm) lies on the 12.7-50 mm ring for centres 27.7-35 mm out.
    assert offset == pytest.approx((0.0127 + LIP + 0.05 - LIP) / 2, abs=2e-4)
    assert seals_at(tape, offset, LIP, CFG) and not seals_at(tape, 0.0, LIP, CFG)
    # A disc of the same radius seals there too: one aim serves both kinds.
    assert aim_offset([tape, FaceProfile.disc(0.05)], LIP, CFG) == pytest.approx(offset)


def test_a_ring_narrower_than_the_lip_leaves_the_centre() -> None:
    assert aim_offset([_kind("tape", 0.04, hole_radius=0.0127)], LIP, CFG) == 0.0


def test_the_kind_is_told_by_the_tracked_radius() -> None:
    cfg = load_scene("realistic")
    tape = cfg.object_types["tape"]
    point = PickPoint(cfg, LIP)
    assert point.offset(tape.radius) > tape.hole_radius + LIP - 1e-3
    assert point.offset(cfg.object_types["can"].radius) == 0.0
    assert point.offset(None) == 0.0


def _face(tilt_deg: float) -> TargetState:
    """A face tilted ``tilt_deg`` about y, its high side towards +x."""
    tilt = np.radians(tilt_deg)
    normal = np.array([np.sin(tilt), 0.0, -np.cos(tilt)])  # inward
    return TargetState(centre=np.array([0.4, 0.0, 0.1]), velocity=np.array([0.0, 0.1, 0.0]),
                       normal=normal)


def test_a_tilted_face_is_aimed_up_its_slope_in_its_plane() -> None:
    face = _face(30.0)
    camera_side = np.array([1.0, 0.0, 0.0])  # the slope wins over the camera's side
    moved = aimed(face, 0.03, camera_side)
    step = moved.centre - face.centre
    assert np.linalg.norm(step) == pytest.approx(0.03)
    assert abs(step @ face.normal) < 1e-12  # in the face plane
    assert step[2] == pytest.approx(0.03 * np.sin(np.radians(30.0)))  # the highest point
    assert np.array_equal(moved.normal, face.normal)
    assert np.array_equal(moved.velocity, face.velocity)
    assert aimed(face, 0.0, camera_side) is face


def test_a_level_face_is_aimed_away_from_the_cameras_side() -> None:
    level = aimed(_face(0.0), 0.03, np.array([0.0, 1.0, 0.2]))
    assert np.allclose(level.centre - _face(0.0).centre, [0.0, -0.03, 0.0])
    # The direction turns smoothly from the camera's side to the slope as the tilt grows.
    turns = [aim_direction(_face(t).normal, np.array([0.0, 1.0, 0.0])) for t in (0.5, 5, 20)]
    assert [float(d[1]) for d in turns if d is not None] == sorted(
        float(d[1]) for d in turns if d is not None)
    assert aim_direction(np.array([0.0, 0.0, -1.0]), np.zeros(3)) is None


@pytest.mark.parametrize("seed", [70000, 70001])
def test_a_tape_roll_is_picked_on_its_ring(seed: int) -> None:
    cfg = load_scene("realistic", TAPES)
    rec = run_episode(generate_scene(cfg, seed))
    assert rec.success, f"{rec.failure}: {rec.failure_detail}"
    # The record tells where the lip met the face against what the controller believed.
    tape = cfg.object_types["tape"]
    assert rec.target_kind == "tape" and rec.believed_kinds == ["tape"]
    assert rec.believed_radius_m == pytest.approx(tape.radius)
    assert rec.aim_offset_mm == pytest.approx(1e3 * aim_offset([face_profile(tape)], LIP, CFG),
                                              abs=0.01)
    assert rec.lip_offset_mm is not None and rec.aim_miss_mm is not None
    assert 1e3 * (tape.hole_radius + LIP) < rec.lip_offset_mm < 1e3 * (tape.radius - LIP)
    assert rec.aim_miss_mm < 3.0


def test_a_cup_aimed_at_a_tape_rolls_centre_does_not_seal(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    monkeypatch.setattr(pick, "aimed", lambda state, offset, side: state)
    rec = run_episode(generate_scene(load_scene("realistic", TAPES), 70000))
    assert rec.failure == "missed_grasp" and "over a hole" in rec.failure_detail
    # The record shows the cause: no aim off the centre, the lip landing over the hole.
    assert rec.aim_offset_mm == 0.0 and rec.believed_kinds == ["tape"]
    assert rec.lip_offset_mm is not None and rec.lip_offset_mm < 1e3 * (0.0127 + LIP)


def test_the_kinds_a_radius_is_taken_for() -> None:
    cfg = load_scene("realistic")
    point = PickPoint(cfg, LIP)
    assert point.kinds(0.0251) == ["printed_small"]
    assert point.kinds(0.049) == ["tape"]
    assert point.kinds(None) == [] and point.kinds(0.0) == []

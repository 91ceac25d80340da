"""The pick's record: where the cup met the face against what the controller believed, and
a cup sent to a buried object counted as the wrong object, not as a missed grasp."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stackpick_sim.episodes.audit import buried_target
from stackpick_sim.episodes.outcome import distance_to_axis, lip_on_face
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.schema import record_from_json, record_to_json

UP = np.array([0.0, 0.0, 1.0])


def test_the_lip_on_a_level_face() -> None:
    cup, axis = np.array([0.012, 0.005, 0.107]), -UP
    offset, height = lip_on_face(cup, axis, np.array([0.0, 0.0, 0.1]), UP)  # type: ignore[misc]
    assert offset == pytest.approx(0.013) and height == pytest.approx(0.007)


def test_a_tilted_cup_meets_the_face_where_its_axis_does() -> None:
    axis = np.array([np.sin(0.3), 0.0, -np.cos(0.3)])
    cup = np.array([0.0, 0.0, 0.02])
    lip = lip_on_face(cup, axis, np.zeros(3), UP)
    assert lip is not None and lip[0] == pytest.approx(0.02 * np.tan(0.3))
    assert lip_on_face(cup, np.array([1.0, 0.0, 0.0]), np.zeros(3), UP) is None


def test_distance_to_the_cup_axis() -> None:
    assert distance_to_axis(np.array([0.003, 0.004, -1.0]), np.zeros(3), -UP) == (
        pytest.approx(0.005))


def _failed(target: str | None, top: list[str], reason: str = "missed_grasp") -> EpisodeRecord:
    return EpisodeRecord(seed=1, scene="realistic", detector="ours", tracker_frame="belt",
                         belt_speed=0.1, failure=reason, failed_phase="descend",
                         failure_detail="no seal: obj3: lip over the face's edge",
                         target_object=target, top_objects=top)


def test_a_cup_sent_to_a_buried_object_picked_the_wrong_object() -> None:
    rec = _failed("obj2", ["obj3"])
    buried_target(rec)
    assert rec.failure == "wrong_object" and rec.failed_phase == "descend"
    assert rec.failure_detail.startswith("the track was on obj2, not a true top object")
    assert "no seal: obj3" in rec.failure_detail
    nothing = _failed(None, ["obj3"])
    buried_target(nothing)
    assert nothing.failure == "wrong_object" and "no object" in nothing.failure_detail


@pytest.mark.parametrize(("target", "top", "reason"), [
    ("obj3", ["obj3"], "missed_grasp"),   # a top object missed: the grasp's own failure
    ("obj2", ["obj3"], "lost_track"),     # not a contact
    ("obj2", [], "missed_grasp"),         # no truth of the top objects to judge by
])
def test_other_failures_keep_their_reason(target: str, top: list[str], reason: str) -> None:
    rec = _failed(target, top, reason)
    buried_target(rec)
    assert rec.failure == reason


def test_the_aim_fields_round_trip_and_older_records_read() -> None:
    rec = _failed("obj3", ["obj3"])
    rec.target_kind, rec.believed_kinds, rec.believed_radius_m = "tape", ["tape"], 0.05
    rec.aim_offset_mm, rec.lip_offset_mm, rec.aim_miss_mm, rec.lip_height_mm = (
        31.4, 30.2, 1.3, 7.5)
    back = record_from_json(record_to_json(rec))
    assert back == rec
    old = rec.as_dict()
    for key in ("target_kind", "believed_kinds", "believed_radius_m", "aim_offset_mm",
                "lip_offset_mm", "aim_miss_mm", "lip_height_mm"):
        del old[key]
    old["schema_version"] = 1
    read = record_from_json(json.dumps(old))
    assert isinstance(read, EpisodeRecord) and read.believed_kinds == []
    assert read.lip_offset_mm is None and read.schema_version == 1

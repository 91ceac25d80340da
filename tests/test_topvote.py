"""The top-face vote: what a frame votes for, when a rival outvotes the tracked face, and the
episode's re-target (fabricated observations, no rendering)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.phases import RETARGET_WAIT_FRAMES, PhaseLogic
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.sensing import Candidate, Observation
from stackpick_sim.episodes.topvote import (
    RETARGET_VOTES,
    SAME_FACE_M,
    TopVote,
    belt_position,
    frame_vote,
)
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse

#: The camera 0.3 m above the belt, axes along the world's (the vote needs only a pose).
WORLD_T_CAM = np.eye(4)
WORLD_T_CAM[2, 3] = 0.3
BELT_V = np.array([0.0, 0.1])
#: Camera-frame face centres (m) of two faces, 40 mm apart, and their ellipses (px).
TRACKED_C = np.array([0.0, 0.0, -0.25])
RIVAL_C = np.array([0.04, 0.0, -0.25])
TRACKED_E = Ellipse.of(160.0, 120.0, 30.0, 28.0, 0.0)
RIVAL_E = Ellipse.of(210.0, 120.0, 30.0, 28.0, 0.0)


def _cand(e: Ellipse, centre: np.ndarray, *, top: bool) -> Candidate:
    return Candidate(pixel=np.array([e.cx, e.cy]), normal_cam=np.array([0.0, 0.0, 1.0]),
                     centre_cam=centre, radius=0.03, is_top=top, ellipse=e)


def _obs(t: float, *cands: Candidate) -> Observation:
    """A frame at ``t`` s; the belt has carried every face ``BELT_V * t`` since t = 0."""
    shift = np.array([*(BELT_V * t), 0.0])
    moved = tuple(Candidate(pixel=c.pixel, normal_cam=c.normal_cam,
                            centre_cam=None if c.centre_cam is None else c.centre_cam + shift,
                            radius=c.radius, is_top=c.is_top, ellipse=c.ellipse)
                  for c in cands)
    return Observation(capture_time=t, available_time=t + 0.01, world_T_cam=WORLD_T_CAM,
                       candidates=moved, detection=None, image=None)


def _tracked_top(t: float) -> Observation:
    return _obs(t, _cand(TRACKED_E, TRACKED_C, top=True), _cand(RIVAL_E, RIVAL_C, top=False))


def _rival_top(t: float) -> Observation:
    return _obs(t, _cand(TRACKED_E, TRACKED_C, top=False), _cand(RIVAL_E, RIVAL_C, top=True))


def test_frame_votes() -> None:
    assert frame_vote(_tracked_top(0.0), TRACKED_E) == "tracked"
    assert frame_vote(_rival_top(0.0), TRACKED_E) == "rival"
    # The tracked face not seen: the frame says nothing about it.
    assert frame_vote(_obs(0.0, _cand(RIVAL_E, RIVAL_C, top=True)), TRACKED_E) == "none"
    assert frame_vote(_rival_top(0.0), None) == "none"
    # A top face without a pose cannot be placed on the belt.
    posed = _cand(RIVAL_E, RIVAL_C, top=True)
    bare = Candidate(pixel=posed.pixel, normal_cam=None, centre_cam=None, radius=0.03,
                     is_top=True, ellipse=posed.ellipse)
    assert frame_vote(_obs(0.0, _cand(TRACKED_E, TRACKED_C, top=False), bare),
                      TRACKED_E) == "none"


def test_belt_position_removes_the_belt_travel() -> None:
    top = _rival_top(0.5)
    p = belt_position(top.candidates[1], top, BELT_V)
    np.testing.assert_allclose(p, RIVAL_C[:2], atol=1e-12)


def test_a_single_wrong_first_frame_is_outvoted() -> None:
    vote = TopVote(BELT_V)
    vote.start()  # the first frame named the tracked face: one vote
    for i in range(RETARGET_VOTES - 1):
        vote.add(_rival_top(0.033 * (i + 1)), TRACKED_E)
        assert vote.winner() is None  # not before RETARGET_VOTES
    vote.add(_rival_top(0.033 * RETARGET_VOTES), TRACKED_E)
    winner = vote.winner()
    assert winner is not None and winner.votes == RETARGET_VOTES
    np.testing.assert_allclose(winner.position, RIVAL_C[:2], atol=1e-12)


def test_a_confirmed_track_keeps_its_face() -> None:
    vote = TopVote(BELT_V)
    vote.start()
    for i in range(4):
        vote.add(_tracked_top(0.033 * (i + 1)), TRACKED_E)
    for i in range(5):  # the detector later alternates to another true top: fewer votes
        vote.add(_rival_top(0.2 + 0.033 * i), TRACKED_E)
    assert vote.tracked == 5 and vote.rivals[0].votes == 5
    assert vote.winner() is None


def test_a_confirmed_track_keeps_its_face_through_a_run_of_wrong_frames() -> None:
    # The look view confirms the tracked face once; then the approach's oblique views name
    # a face partly under it, many frames in a row: the pick stays on the confirmed face.
    vote = TopVote(BELT_V)
    vote.start()
    vote.add(_tracked_top(0.033), TRACKED_E)
    for i in range(4 * RETARGET_VOTES):
        vote.add(_rival_top(0.1 + 0.033 * i), TRACKED_E)
    assert vote.rivals[0].votes == 4 * RETARGET_VOTES
    assert vote.winner() is None


def test_rivals_far_apart_are_counted_apart() -> None:
    vote = TopVote(BELT_V)
    vote.start()
    far = RIVAL_C + np.array([2 * SAME_FACE_M, 0.0, 0.0])
    far_e = Ellipse.of(260.0, 120.0, 30.0, 28.0, 0.0)
    for i in range(2):
        vote.add(_rival_top(0.033 * (2 * i + 1)), TRACKED_E)
        vote.add(_obs(0.033 * (2 * i + 2), _cand(TRACKED_E, TRACKED_C, top=False),
                      _cand(far_e, far, top=True)), TRACKED_E)
    assert [r.votes for r in vote.rivals] == [2, 2]
    assert vote.winner() is None


class _Estimator:
    """The estimator as the vote sees it: a fixed prediction; records its resets."""

    def __init__(self) -> None:
        self.resets = 0

    def expected_ellipse(self, obs: Observation) -> Ellipse:
        return TRACKED_E

    def reset(self) -> None:
        self.resets += 1


#: Re-targets the PhaseLogic tests allow (the scenes' default is 1).
MAX_RETARGETS = 2


def _logic(max_retargets: int = MAX_RETARGETS) -> tuple[PhaseLogic, Any]:
    cfg = load_scene("paper", (f"episode.max_retargets={max_retargets}",))
    cell = SimpleNamespace(cfg=cfg, world_T_cam=lambda: WORLD_T_CAM)
    ep = SimpleNamespace(scene=SimpleNamespace(cell=cell), estimator=_Estimator(),
                         sensor=SimpleNamespace(detector=SimpleNamespace(exact=False),
                                                period=1 / cfg.camera.fps),
                         record=EpisodeRecord(seed=0, scene="paper", detector="ours",
                                              tracker_frame="belt", belt_speed=0.1))
    logic = PhaseLogic(ep)  # type: ignore[arg-type]
    logic._vote = TopVote(BELT_V)
    logic._vote.start()
    logic.phase = "approach"
    return logic, ep


def test_outvoted_approach_detects_the_rival_again() -> None:
    logic, ep = _logic()
    for i in range(RETARGET_VOTES):
        logic._count_vote(_rival_top(0.033 * (i + 1)))
    assert logic._retarget_if_outvoted(0.12)
    assert logic.phase == "detect" and ep.estimator.resets == 1
    assert ep.record.retargets == 1
    # The detection frame after the re-target: the old face named top again is passed over
    # while the rival is waited for; the rival named top is taken.
    logic._now = logic.phase_start + 0.04
    assert logic._first_candidate(_tracked_top(0.15)) is None
    rival = logic._first_candidate(_rival_top(0.15))
    assert rival is not None and rival.is_top and rival.ellipse == RIVAL_E
    # Past the wait, the detector's top face is taken whatever it is.
    logic._now = logic.phase_start + (RETARGET_WAIT_FRAMES + 0.5) * ep.sensor.period
    old = logic._first_candidate(_tracked_top(0.3))
    assert old is not None and old.ellipse == TRACKED_E


def test_retargets_are_bounded() -> None:
    logic, ep = _logic()
    for _ in range(MAX_RETARGETS):
        logic.phase = "approach"
        logic._vote.start()
        for i in range(RETARGET_VOTES):
            logic._count_vote(_rival_top(0.033 * (i + 1)))
        assert logic._retarget_if_outvoted(0.2)
    logic.phase = "approach"
    for i in range(RETARGET_VOTES):
        logic._count_vote(_rival_top(0.5 + 0.033 * i))
    assert not logic._retarget_if_outvoted(0.7)
    assert logic.phase == "approach" and ep.record.retargets == MAX_RETARGETS


def test_retargets_are_on_by_default_and_off_on_the_fast_belt() -> None:
    assert load_scene("paper", ()).episode.max_retargets == 1
    assert load_scene("fast_belt", ()).episode.max_retargets == 0


def test_no_retarget_when_the_scene_allows_none() -> None:
    logic, ep = _logic(max_retargets=0)
    for i in range(RETARGET_VOTES + 1):
        logic._count_vote(_rival_top(0.033 * (i + 1)))
    assert logic._vote.winner() is None  # frames are not even counted
    assert not logic._retarget_if_outvoted(0.2)
    assert logic.phase == "approach" and ep.record.retargets == 0


def test_max_retargets_is_validated() -> None:
    with pytest.raises(ConfigError, match=r"episode\.max_retargets"):
        load_scene("paper", ("episode.max_retargets=-1",))

"""The top-face vote: what a frame votes for, when a rival outvotes the tracked face, and the
episode's re-target (fabricated observations, no rendering)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
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
    Disc,
    TopVote,
    VoteRules,
    belt_position,
    frame_vote,
    lies_over,
)
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.pipeline import TargetState

#: The camera 0.3 m above the belt, axes along the world's (the vote needs only a pose).
WORLD_T_CAM = np.eye(4)
WORLD_T_CAM[2, 3] = 0.3
BELT_V = np.array([0.0, 0.1])
#: Camera-frame face centres (m) of two faces, 40 mm apart, and their ellipses (px).
TRACKED_C = np.array([0.0, 0.0, -0.25])
RIVAL_C = np.array([0.04, 0.0, -0.25])
TRACKED_E = Ellipse.of(160.0, 120.0, 30.0, 28.0, 0.0)
RIVAL_E = Ellipse.of(210.0, 120.0, 30.0, 28.0, 0.0)
#: The paper scene's vote settings.
RULES = VoteRules(size_tolerance=0.25, over_height=0.010)
#: The tracked face's height, world z, m (the camera 0.3 m up, the faces 0.25 m below it).
TRACKED_Z = 0.05


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
    assert frame_vote(_tracked_top(0.0), TRACKED_E, RULES.size_tolerance) == "tracked"
    assert frame_vote(_rival_top(0.0), TRACKED_E, RULES.size_tolerance) == "rival"
    # The tracked face not seen: the frame says nothing about it.
    assert frame_vote(_obs(0.0, _cand(RIVAL_E, RIVAL_C, top=True)), TRACKED_E,
                      RULES.size_tolerance) == "none"
    assert frame_vote(_rival_top(0.0), None, RULES.size_tolerance) == "none"
    # A top face without a pose cannot be placed on the belt.
    posed = _cand(RIVAL_E, RIVAL_C, top=True)
    bare = Candidate(pixel=posed.pixel, normal_cam=None, centre_cam=None, radius=0.03,
                     is_top=True, ellipse=posed.ellipse)
    assert frame_vote(_obs(0.0, _cand(TRACKED_E, TRACKED_C, top=False), bare),
                      TRACKED_E, RULES.size_tolerance) == "none"


#: A smaller face lying on the tracked one: its centre inside the tracked face's ellipse, at
#: 0.6 of its size, 30 mm above it (nearer the camera).
ON_C = np.array([0.005, 0.0, -0.22])
ON_E = Ellipse.of(166.0, 120.0, 18.0, 17.0, 0.0)


def _on_top(t: float) -> Observation:
    return _obs(t, _cand(TRACKED_E, TRACKED_C, top=False), _cand(ON_E, ON_C, top=True))


def test_a_smaller_face_on_the_tracked_one_is_a_rival() -> None:
    assert frame_vote(_on_top(0.0), TRACKED_E, RULES.size_tolerance) == "rival"
    # Its centre lies inside the tracked face's ellipse: only the size tells it apart.
    assert frame_vote(_on_top(0.0), TRACKED_E, 1.0) == "tracked"
    # The tracked face's own fit, a little larger than predicted, is the tracked face.
    larger = Ellipse.of(161.0, 120.0, 33.0, 31.0, 0.0)
    assert frame_vote(_obs(0.0, _cand(larger, TRACKED_C, top=True)), TRACKED_E,
                      RULES.size_tolerance) == "tracked"


#: The tracked face as a disc in the camera's frame (radius 30 mm, level).
TRACKED_DISC = Disc(centre=TRACKED_C, normal=np.array([0.0, 0.0, 1.0]), radius=0.03)


def _confirmed_then(rival: Callable[[float], Observation], rival_frames: int,
                    tracked_frames: int = 2) -> TopVote:
    """A vote whose tracked face was confirmed ``tracked_frames`` times, then outvoted by
    ``rival_frames`` frames of ``rival``."""
    vote = TopVote(BELT_V, RULES)
    vote.start()
    for i in range(tracked_frames):
        vote.add(_tracked_top(0.033 * (i + 1)), TRACKED_E, TRACKED_DISC)
    for i in range(rival_frames):
        t = 0.2 + 0.033 * i
        moved = TRACKED_C + np.array([*(BELT_V * t), 0.0])
        vote.add(rival(t), TRACKED_E, replace(TRACKED_DISC, centre=moved))
    return vote


def test_a_disc_lies_over_another_where_they_overlap() -> None:
    level = np.array([0.0, 0.0, 1.0])
    tracked = Disc(centre=np.array([0.0, 0.0, 0.25]), normal=level, radius=0.03)
    near = Disc(centre=np.array([0.04, 0.0, 0.24]), normal=level, radius=0.03)
    assert lies_over(near, tracked) and not lies_over(tracked, near)
    beside = Disc(centre=np.array([0.08, 0.0, 0.24]), normal=level, radius=0.03)
    assert not lies_over(beside, tracked)  # no line of sight meets both
    # A tracked face tilted up towards the other one: where they overlap it is the nearer,
    # though the other face's centre lies nearer the camera than its own.
    tilted = replace(tracked, normal=np.array([0.6, 0.0, 0.8]))
    assert not lies_over(near, tilted) and lies_over(tilted, near)


def test_a_face_above_outvotes_a_confirmed_track() -> None:
    vote = _confirmed_then(_on_top, 3)  # 3 votes for the track (first detection + 2)
    assert vote.winner(TRACKED_Z) is None  # as many votes, not more
    vote.add(_on_top(0.4), TRACKED_E)
    winner = vote.winner(TRACKED_Z)
    assert winner is not None and winner.votes == 4
    np.testing.assert_allclose(winner.height, TRACKED_Z + 0.03, atol=1e-12)
    np.testing.assert_allclose(winner.position, ON_C[:2], atol=1e-12)
    # The same votes for a face no higher than the tracked one (a lower face named top
    # by oblique views, or another true top beside it) keep the pick.
    assert vote.winner(TRACKED_Z + 0.03 - RULES.over_height + 1e-4) is None
    assert vote.winner(None) is None


def test_a_higher_face_that_does_not_lie_over_the_track_does_not_outvote_it() -> None:
    vote = TopVote(BELT_V, RULES)
    vote.start()
    vote.add(_tracked_top(0.033), TRACKED_E, TRACKED_DISC)
    for i in range(6):  # no tracked face known in the camera's frame: never over it
        vote.add(_on_top(0.1 + 0.033 * i), TRACKED_E, None)
    assert vote.rivals[0].votes == 6 and vote.rivals[0].over == 0
    assert vote.winner(TRACKED_Z) is None


def test_a_face_beside_at_the_same_height_does_not_outvote_a_confirmed_track() -> None:
    vote = _confirmed_then(_rival_top, 10)
    assert vote.rivals[0].votes == 10 and vote.tracked == 3
    assert vote.winner(TRACKED_Z) is None
    higher = RIVAL_C + np.array([0.0, 0.0, 0.02])
    above = _confirmed_then(lambda t: _obs(t, _cand(TRACKED_E, TRACKED_C, top=False),
                                           _cand(RIVAL_E, higher, top=True)), 10)
    assert above.winner(TRACKED_Z) is not None


def test_belt_position_removes_the_belt_travel() -> None:
    top = _rival_top(0.5)
    p = belt_position(top.candidates[1], top, BELT_V)
    np.testing.assert_allclose(p, RIVAL_C[:2], atol=1e-12)


def test_a_single_wrong_first_frame_is_outvoted() -> None:
    vote = TopVote(BELT_V, RULES)
    vote.start()  # the first frame named the tracked face: one vote
    for i in range(RETARGET_VOTES - 1):
        vote.add(_rival_top(0.033 * (i + 1)), TRACKED_E)
        assert vote.winner(TRACKED_Z) is None  # not before RETARGET_VOTES
    vote.add(_rival_top(0.033 * RETARGET_VOTES), TRACKED_E)
    winner = vote.winner(TRACKED_Z)
    assert winner is not None and winner.votes == RETARGET_VOTES
    np.testing.assert_allclose(winner.position, RIVAL_C[:2], atol=1e-12)


def test_a_confirmed_track_keeps_its_face() -> None:
    vote = TopVote(BELT_V, RULES)
    vote.start()
    for i in range(4):
        vote.add(_tracked_top(0.033 * (i + 1)), TRACKED_E)
    for i in range(5):  # the detector later alternates to another true top: fewer votes
        vote.add(_rival_top(0.2 + 0.033 * i), TRACKED_E)
    assert vote.tracked == 5 and vote.rivals[0].votes == 5
    assert vote.winner(TRACKED_Z) is None


def test_a_confirmed_track_keeps_its_face_through_a_run_of_wrong_frames() -> None:
    # The look view confirms the tracked face once; then the approach's oblique views name
    # a face partly under it, many frames in a row: the pick stays on the confirmed face.
    vote = TopVote(BELT_V, RULES)
    vote.start()
    vote.add(_tracked_top(0.033), TRACKED_E)
    for i in range(4 * RETARGET_VOTES):
        vote.add(_rival_top(0.1 + 0.033 * i), TRACKED_E)
    assert vote.rivals[0].votes == 4 * RETARGET_VOTES
    assert vote.winner(TRACKED_Z) is None


def test_rivals_far_apart_are_counted_apart() -> None:
    vote = TopVote(BELT_V, RULES)
    vote.start()
    far = RIVAL_C + np.array([2 * SAME_FACE_M, 0.0, 0.0])
    far_e = Ellipse.of(260.0, 120.0, 30.0, 28.0, 0.0)
    for i in range(2):
        vote.add(_rival_top(0.033 * (2 * i + 1)), TRACKED_E)
        vote.add(_obs(0.033 * (2 * i + 2), _cand(TRACKED_E, TRACKED_C, top=False),
                      _cand(far_e, far, top=True)), TRACKED_E)
    assert [r.votes for r in vote.rivals] == [2, 2]
    assert vote.winner(TRACKED_Z) is None


class _Estimator:
    """The estimator as the vote sees it: a fixed prediction; records its resets."""

    face_z = TRACKED_Z
    initialised = True
    radius = TRACKED_DISC.radius

    def __init__(self) -> None:
        self.resets = 0

    def expected_ellipse(self, obs: Observation) -> Ellipse:
        return TRACKED_E

    def state(self, t: float, world_T_cam: np.ndarray) -> TargetState:
        """The tracked face, carried by the belt (world frame)."""
        centre = WORLD_T_CAM[:3, :3] @ TRACKED_C + WORLD_T_CAM[:3, 3] + [*BELT_V * t, 0.0]
        return TargetState(centre=centre, velocity=np.array([*BELT_V, 0.0]),
                           normal=np.array([0.0, 0.0, 1.0]))

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
    logic._vote = TopVote(BELT_V, RULES)
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


def test_a_confirmed_approach_detects_the_face_above_again() -> None:
    logic, ep = _logic()
    for i in range(2):
        logic._count_vote(_tracked_top(0.033 * (i + 1)))
    for i in range(3):
        logic._count_vote(_on_top(0.1 + 0.033 * i))
    assert not logic._retarget_if_outvoted(0.2)  # 3 votes against the track's 3
    logic._count_vote(_on_top(0.2))
    assert logic._retarget_if_outvoted(0.23)
    assert logic.phase == "detect" and ep.record.retargets == 1
    logic._now = logic.phase_start + 0.04
    assert logic._first_candidate(_tracked_top(0.27)) is None
    above = logic._first_candidate(_on_top(0.27))
    assert above is not None and above.ellipse == ON_E


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
    assert logic._vote.winner(TRACKED_Z) is None  # frames are not even counted
    assert not logic._retarget_if_outvoted(0.2)
    assert logic.phase == "approach" and ep.record.retargets == 0


def test_max_retargets_is_validated() -> None:
    with pytest.raises(ConfigError, match=r"episode\.max_retargets"):
        load_scene("paper", ("episode.max_retargets=-1",))


def test_vote_settings_come_from_the_scene_and_are_validated() -> None:
    cfg = load_scene("paper", ("episode.vote_size_tolerance=0.4",
                               "episode.retarget_over_height=0.02"))
    logic, _ = _logic()
    assert logic._vote.rules == RULES  # the fixture's; a PhaseLogic reads the scene's:
    ep = SimpleNamespace(scene=SimpleNamespace(cell=SimpleNamespace(cfg=cfg)))
    rules = PhaseLogic(ep)._vote.rules  # type: ignore[arg-type]
    assert rules == VoteRules(size_tolerance=0.4, over_height=0.02)
    with pytest.raises(ConfigError, match=r"episode\.vote_size_tolerance"):
        load_scene("paper", ("episode.vote_size_tolerance=0",))
    with pytest.raises(ConfigError, match=r"episode\.retarget_over_height"):
        load_scene("paper", ("episode.retarget_over_height=-0.01",))

"""The phase machine's logic: what each phase commands and when it hands over or fails.

See :mod:`stackpick_sim.episodes.episode` for the loop that drives it. Phase durations are
logged in sim time; the record is filled in as the phases pass.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING

import numpy as np

from stackpick_sim.episodes.audit import DETECTION_PHASES
from stackpick_sim.episodes.pick import ArmPhases, Command
from stackpick_sim.episodes.record import ERROR_REASON, FAILURES, PHASES
from stackpick_sim.episodes.sensing import Candidate, Observation, ellipse_inside
from stackpick_sim.episodes.target import EDGE_MARGIN_PX
from stackpick_sim.episodes.topvote import Disc, Rival, TopVote, VoteRules, posed_top
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.geometry import Ellipse, project_circle
from stackpick_sim.pipeline import Hints

if TYPE_CHECKING:
    from stackpick_sim.episodes.episode import Episode

#: Longest time without a fused detection while the face should be in view, s (track,
#: approach, servo; the descent may go blind).
MAX_BLIND_S = 0.4
#: A first detection that no later frame confirms (associates within the start gate) for
#: this many frame periods is dropped and the top object detected again, at most
#: MAX_REDETECTIONS times. Three frames: latency and one missed frame are normal.
UNCONFIRMED_FRAMES = 3.5
MAX_REDETECTIONS = 2
#: The track phase hands over as soon as the filter is initialised once this many frame
#: periods have passed without a fused detection.
TRACK_FADING_FRAMES = 1.5
#: Phases whose frames vote on the top face (:mod:`stackpick_sim.episodes.topvote`): the arm
#: is not yet committed to the face. A rival face that outvotes the tracked one is taken
#: instead, at most ``episode.max_retargets`` times (0: never); the detection after a
#: re-target waits up to RETARGET_WAIT_FRAMES frame periods for the detector to name the
#: rival top again (three frames: latency and one missed frame), then takes whatever it
#: names top.
VOTING_PHASES = ("track", "approach", "servo")
RETARGET_WAIT_FRAMES = 3.5


class PhaseLogic(ArmPhases):
    """Per-tick decisions of one episode."""

    def __init__(self, episode: Episode) -> None:
        self.ep = episode
        self.phase = PHASES[0]
        self.phase_start = 0.0
        self.failure: str | None = None
        self.done = False
        self._detection_frames: set[float] = set()
        """Capture times of the frames taken while looking for the top (the track starts
        only from those: frames of an abandoned track are not a new detection)."""
        self._target: Candidate | None = None
        self._hint_depth: float | None = None
        self._hint_normal: np.ndarray | None = None
        self._settled = 0
        self._standoff = episode.scene.cell.cfg.episode.standoff
        self._lift_from: np.ndarray | None = None
        self._lift_base = np.zeros(3)
        self._grasped: list[str] = []
        self._cycle_end: float | None = None
        self._tilt_share = 1.0
        self._face_share = 1.0
        self._planned_normal = np.array([0.0, 0.0, -1.0])
        self._pick_point = None
        """Set when the approach starts (:meth:`_take_aim_side`)."""
        self._aim_side = np.zeros(3)
        self._sight = np.array([0.0, 0.0, -1.0])
        """Line of sight from the camera to the face when the descent began, world (3,) m
        (:func:`~stackpick_sim.episodes.pick.sight_shift`)."""
        self._below = 0.0
        self._search_from = 0.0
        """How far down the line of sight the grasp holds the face, m."""
        self._redetections = 0
        cfg = episode.scene.cell.cfg
        self._vote = TopVote(np.array([0.0, cfg.conveyor.speed]), VoteRules(
            size_tolerance=cfg.episode.vote_size_tolerance,
            over_height=cfg.episode.retarget_over_height))
        self._retargets = 0
        self._wanted: Rival | None = None
        """The face a re-target detects again (topvote), or None."""
        self._at_floor = 0.0
        self._floor = 0.0
        self._last_lateral = 0.0
        self._now = 0.0

    # -- bookkeeping ---------------------------------------------------------------------
    def _enter(self, phase: str, t: float) -> None:
        # Summed: the detect and track phases run again after an unconfirmed detection.
        spent = self.ep.record.phases.get(self.phase, 0.0) + (t - self.phase_start)
        self.ep.record.phases[self.phase] = round(spent, 6)
        self.phase, self.phase_start = phase, t

    def fail(self, reason: str, detail: str) -> None:
        """End the episode with ``reason`` (one of FAILURES, or ERROR_REASON)."""
        if reason not in (*FAILURES, ERROR_REASON):
            raise EpisodeError(f"unknown failure reason {reason!r}; known: "
                               f"{', '.join((*FAILURES, ERROR_REASON))}")
        if self.failure is None:
            self.failure = reason
            self.ep.record.failure = reason
            self.ep.record.failure_detail = detail
            self.ep.record.failed_phase = self.phase

    def finish(self) -> None:
        """Close the last phase's log and judge the outcome."""
        rec = self.ep.record
        rec.phases[self.phase] = round(rec.phases.get(self.phase, 0.0)
                                       + (self._now - self.phase_start), 6)
        rec.cycle_time_s = self._cycle_end
        self.ep.audit.on_finish(self.done, self._grasped)

    def before_capture(self, t: float) -> None:
        """Decide whether the frame is worth processing and what the detector is told."""
        self.ep.sensor.process = self._frame_needed()
        looking = self.phase in DETECTION_PHASES
        if looking:
            self._detection_frames.add(t)
        self.ep.sensor.hints = Hints(
            expected_depth_m=self._hint_depth, reference_normal_cam=self._hint_normal,
            expected_ellipse=None if looking else self._predicted_ellipse(),
            target=None if looking else self._target)
        self.ep.audit.on_capture(t, self.phase)

    def _frame_needed(self) -> bool:
        """Whether the controller can use a frame captured now (else it is not processed).

        Until the descent, always. During the descent only while the tracked face is
        predicted wholly in the image (the tracker drops faces cut by the border); after
        the grasp, never: lift and verify are blind.
        """
        if self.phase in ("grasp", "lift", "verify"):
            return False
        if self.phase != "descend":
            return True
        e = self._predicted_ellipse()
        return e is not None and ellipse_inside(e, self.ep.scene.cell.intrinsics, EDGE_MARGIN_PX)

    def _predicted_ellipse(self) -> Ellipse | None:
        """The tracked face's ellipse as the camera sees it now (None before tracking)."""
        ep = self.ep
        if not ep.estimator.initialised:
            return None
        cell = ep.scene.cell
        world_T_cam = ep.arm.eih.world_T_cam(cell.data)
        state = ep.estimator.state(self._now, world_T_cam)
        r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
        try:
            return project_circle(r.T @ (state.centre - p), r.T @ state.normal,
                                  ep.estimator.radius or 0.0, cell.intrinsics)
        except ValueError:
            return None

    # -- the machine -----------------------------------------------------------------------
    def tick(self, t: float, dt: float, observations: list[Observation]) -> Command:
        """Advance the phase machine at sim time ``t`` s; returns the servo errors if servoing.

        A generator: a phase that moves the arm yields its :class:`ControlGoal` and takes
        back the joint rates to apply, or None for the controller's (see
        :meth:`~stackpick_sim.episodes.pick.ArmPhases._command`)."""
        self._now = t
        cfg = self.ep.scene.cell.cfg.episode
        if self.phase not in ("look", "detect"):
            for obs in observations:
                self._count_vote(obs)
                self.ep.estimator.offer(obs)
        if t - self.phase_start > getattr(cfg, f"timeout_{self.phase}") + 1e-9:
            self._time_out(t)
            return None
        if self._retarget_if_outvoted(t):
            return None
        handler = getattr(self, f"_{self.phase}")
        result = handler(t, dt, observations)
        if isinstance(result, Generator):
            result = yield from result
        self._update_sensor_hints()
        return result

    def _time_out(self, t: float) -> None:
        if self.phase == "detect":
            self.fail("no_detection", f"no top object detected in {t - self.phase_start:.2f} s")
        elif self.ep.arm.at_limit():
            self.fail("joint_limit", f"{self.phase} timed out with a joint at its limit")
        elif self.phase == "servo":
            self.fail("servo_diverged", "the servo did not converge in time")
        else:
            self.fail("timeout", f"{self.phase} took longer than its time-out")

    def _look(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        if self.ep.sensor.frames > 0:
            self._enter("detect", t)

    def _detect(self, t: float, dt: float, observations: list[Observation]) -> None:
        self.ep.arm.hold()
        for obs in observations:
            if obs.capture_time not in self._detection_frames:
                continue
            cand = self._first_candidate(obs)
            if cand is None:
                continue
            self._start(obs, cand)
            self._enter("track", t)
            return

    def _first_candidate(self, obs: Observation) -> Candidate | None:
        """The detector's posed top face of ``obs``; after a re-target, only the rival's
        (until RETARGET_WAIT_FRAMES frame periods have passed)."""
        ep = self.ep
        top = posed_top(obs)
        if top is None or self._wanted is None:
            return top
        waited = self._now - self.phase_start
        if (self._vote.is_face(top, obs, self._wanted)
                or waited > RETARGET_WAIT_FRAMES * ep.sensor.period):
            return top
        return None

    def _count_vote(self, obs: Observation) -> None:
        """Count ``obs``'s vote on the top face while the arm is not committed to it (only
        when re-targets are allowed: ``episode.max_retargets`` > 0, the detector is not
        exact and the estimator predicts the tracked face's ellipse)."""
        expected = getattr(self.ep.estimator, "expected_ellipse", None)  # optional
        if (self.phase in VOTING_PHASES and not self.ep.sensor.detector.exact
                and self.ep.scene.cell.cfg.episode.max_retargets > 0 and obs.candidates
                and expected is not None):
            self._vote.add(obs, expected(obs), self._tracked_disc(obs))

    def _tracked_disc(self, obs: Observation) -> Disc | None:
        """The tracked face at ``obs``'s capture, in its camera's frame (None before the
        filter is set or the radius known)."""
        est = self.ep.estimator
        if not est.initialised or not est.radius:
            return None
        state = est.state(obs.capture_time, obs.world_T_cam)
        r, p = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        return Disc(centre=r.T @ (state.centre - p), normal=r.T @ state.normal,
                    radius=float(est.radius))

    def _retarget_if_outvoted(self, t: float) -> bool:
        """Detect again, arm still, if a rival face outvoted the tracked one; True if so.

        The frames' votes say the first detection named a face the detector since sees as
        not the top (see :mod:`stackpick_sim.episodes.topvote`); the detection after this
        takes the rival's face if the detector names it top within RETARGET_WAIT_FRAMES.
        """
        if (self.phase not in VOTING_PHASES
                or self._retargets >= self.ep.scene.cell.cfg.episode.max_retargets):
            return False
        winner = self._vote.winner(self.ep.estimator.face_z if self.ep.estimator.initialised
                                   else None)
        if winner is None:
            return False
        self._retargets += 1
        self.ep.record.retargets = self._retargets
        self._wanted = winner
        self.ep.estimator.reset()
        self._enter("detect", t)
        return True

    def _start(self, obs: Observation, cand: Candidate) -> None:
        self.ep.audit.on_start(obs.capture_time, cand)
        self.ep.estimator.start(obs, cand)
        self._target = cand
        self._vote.start()
        self._wanted = None

    def _update_sensor_hints(self) -> None:
        """The tracked face's depth and normal in the camera now (kept once a track is
        set, for the next frames' detector)."""
        ep = self.ep
        if not ep.estimator.initialised:
            return
        world_T_cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        state = ep.estimator.state(self._now, world_T_cam)
        r, p = world_T_cam[:3, :3], world_T_cam[:3, 3]
        self._hint_depth = float((r.T @ (state.centre - p))[2])
        self._hint_normal = r.T @ state.normal

    def _check_track(self, t: float) -> bool:
        est = self.ep.estimator
        if self.ep.arm.at_limit() and self.phase in ("approach", "servo"):
            # A joint stopped at its range end leaves the goal (and often the face) out of
            # reach: report the cause, not the symptom.
            self.fail("joint_limit", "a joint reached its range end before the servo goal")
            return False
        if est.lost:
            self.fail("lost_track", "too many detections in a row outside the tracking gate")
            return False
        if est.last_fused_time is not None and t - est.last_fused_time > MAX_BLIND_S:
            self.fail("lost_track", f"no detection fused for {t - est.last_fused_time:.2f} s")
            return False
        return True

    def _track(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        est = self.ep.estimator
        if not self._check_track(t):
            return
        if (not est.initialised and est.last_fused_time is not None
                and t - est.last_fused_time > UNCONFIRMED_FRAMES * self.ep.sensor.period
                and self._redetections < MAX_REDETECTIONS):
            # No later frame confirmed the first detection near where the belt carries it: a
            # false top (a fragment of outlines, a lower face); detect again, arm still.
            self._redetections += 1
            self.ep.record.redetections = self._redetections
            est.reset()
            self._enter("detect", t)
            return
        # Go early when the face has stopped being seen (it is leaving the still look view
        # across the border): two detections already give its position and velocity.
        fading = (est.last_fused_time is not None
                  and t - est.last_fused_time > TRACK_FADING_FRAMES * self.ep.sensor.period)
        if est.initialised and (est.fused >= self.ep.scene.cell.cfg.episode.track_frames
                                or fading):
            self._take_aim_side()
            self._plan_reach(t)
            self._enter("approach", t)

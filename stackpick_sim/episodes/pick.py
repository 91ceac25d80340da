"""The arm's phases of a pick: approach, servo, descend, grasp, lift, verify.

A mixin of :class:`stackpick_sim.episodes.phases.PhaseLogic` (which holds the state and the
look/detect/track phases). The tool approaches along a *commanded* axis: the face normal,
or, where the arm cannot reach that at the servo standoff, a share of its tilt that grows
during the descent to the full normal, or to the share the arm can take where the face will
be at the grasp (:mod:`stackpick_sim.control.reach`). The descent is
blind (the face leaves the view) and pauses while the tool is off the face's axis; past the
heights the track measured it searches on, down the line of sight, for a face read at the
wrong scale (:func:`larger_kind_drop`, :func:`sight_shift`); the lift
turns the tool upright as it rises and pulls it ``episode.lift_retreat`` towards the robot's
base (a grasp at the edge of the reach, on a fast belt, cannot rise straight up).
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.control.pick_point import RADIUS_MATCH, PickPoint, aimed
from stackpick_sim.control.reach import (
    GRASP_JOINT_MARGIN,
    GRASP_SELF_CLEARANCE,
    ReachChecker,
    descent_tilt_share,
    tilted_axis,
    tool_pose_on_axis,
)
from stackpick_sim.episodes.arm import ServoErrors, approach_pose, pose_error
from stackpick_sim.episodes.outcome import AimBelief, no_seal, touching
from stackpick_sim.episodes.sensing import Observation
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.pipeline import ControlGoal, TargetState
from stackpick_sim.sim.cell import ObjectInfo
from stackpick_sim.sim.robot import CUP_BODY
from stackpick_sim.sim.suction import lip_radius

if TYPE_CHECKING:
    from stackpick_sim.episodes.episode import Episode

FloatArray = NDArray[np.float64]
#: A phase that commands the arm: yields its goals (see :meth:`ArmPhases._command`),
#: returns the servo errors (or None).
Command = Generator[ControlGoal, FloatArray | None, ServoErrors | None]

#: The approach hands over to the servo within this distance (m) and angle (deg) of its goal.
APPROACH_DONE = (0.01, 5.0)
#: The servo must meet its tolerances on this many consecutive ticks.
SERVO_SETTLE_TICKS = 3
#: The reach check looks at the face this far ahead of the approach's start, s: about the
#: approach and servo time (median 0.45 s on paper scenes), when the descent begins.
REACH_LEAD_S = 0.5
#: The reach is planned again when the tracked face normal has turned this far since the
#: plan, deg (the NORMAL_AGREEMENT_DEG of the normal's consensus).
REPLAN_TURN_DEG = 10.0
#: The descent ends in a miss once the tool is within this of its deepest command, m, or
#: has been commanded there this long, s (the arm lags the command by up to ~60 ms at
#: 0.35 m/s on paper scenes).
DESCENT_ARRIVED = 0.001
DESCENT_WAIT = 0.15
#: ... the wait counting only while the tool is within this of the command, m (it lags a
#: straight descent by ~1 mm; placeholder with margin).
DESCENT_SETTLED = 0.003
#: The descent pauses while the face centre is farther than ``DESCENT_HOLD_LATERAL +
#: DESCENT_HOLD_SLOPE * standoff`` (m) from the tool axis: twice the servo's lateral
#: tolerance at the face, well inside the cup lip's 11 mm radius; farther up the servo has
#: time to take out more (12.5 mm at the 0.19 m standoff). Placeholders.
DESCENT_HOLD_LATERAL = 0.003
DESCENT_HOLD_SLOPE = 0.05
#: The tool's turn trails the commanded axis: while the descent turns it (~45 deg/s on a
#: face tilted ~40 deg that the arm cannot meet square-on at the servo standoff) by 5-6 deg,
#: closing over ~0.2 s once the command stops turning. The commanded turn therefore ends
#: this long (s, at the descent speed) before the face, so that the cup meets the face near
#: the planned angle and not past the bellows' compliance.
AXIS_LAG_S = 0.25
#: The tool keeps pressing this far (m) past where it touched while the suction takes hold.
GRASP_PRELOAD = 0.002
#: Body whose origin lies on the robot's vertical J1 axis (the lift retreats towards it).
BASE_AXIS_BODY = "j1_link"


def floor_time(at_floor: float, depth_error: float, standoff: float, floor: float,
               dt: float) -> float:
    """Time (s) the descent's command has rested at its ``floor`` m with the tool near it.

    ``at_floor`` s so far, plus ``dt`` s when the commanded ``standoff`` m is at the floor
    and the tool is within DESCENT_SETTLED of it (``depth_error`` m short, see
    :func:`descent_missed`).
    """
    if standoff <= floor and depth_error < DESCENT_SETTLED:
        return at_floor + dt
    return at_floor


def larger_kind_drop(radius: float | None, radii: list[float], depth: float) -> float:
    """How much farther (m) a face read as ``radius`` m at ``depth`` m from the camera lies
    were it of the next larger of the pile's kinds (``radii``, m); 0 when none is larger.

    A monocular pose is known up to scale: an outline of the same size in the image is a
    face of radius ``R`` at depth ``d`` or one of radius ``R'`` at ``d R' / R``. A face
    taken for a smaller kind than it is (a can's 30 mm lid for a 25 mm printed lid) is
    farther than the track believes, so lower: the cup reaches the believed height above it.
    """
    if radius is None or radius <= 0.0:
        return 0.0
    larger = [r for r in radii if r > radius + RADIUS_MATCH]
    return max(0.0, depth) * (min(larger) / radius - 1.0) if larger else 0.0


def sight_shift(sight: FloatArray, drop: float) -> FloatArray:
    """(3,) offset, world m, ``drop`` m down the line of sight ``sight`` (3,: from the camera
    to the face, world; any length).

    A monocular pose is known up to scale along its line of sight: a face read too high
    (too near: an outline that takes in its wall, a kind mistaken for a smaller one) lies
    farther along the same line. Below the predicted face the descent's goal slides down
    the line of sight of the views that placed it (carried on with the face by the belt),
    not the tool's own axis, which leaves that line by the camera's offset.
    """
    ray = np.asarray(sight, dtype=float)
    if drop <= 0.0 or ray[2] > -1e-6:
        return np.zeros(3)
    return np.asarray(ray * (drop / -ray[2]))


def descent_floor(overtravel: float, face_z: float, lowest_face_z: float, tallest: float,
                  previous: float = 0.0, scale_drop: float = 0.0) -> float:
    """Deepest standoff (m, negative: past the predicted face) a descent is commanded to.

    ``overtravel`` m past the predicted face (at height ``face_z``, world z, m), and further
    by as much as the track's lowest monocular height ``lowest_face_z`` m lies below it, or
    by ``scale_drop`` m (:func:`larger_kind_drop`) if more, by at most ``tallest`` m (the
    tallest object kind: lower down is another layer of the pile); never above
    ``previous``, the floor of an earlier tick (m). A monocular height errs one way, too
    high (see :attr:`~stackpick_sim.episodes.target.TargetEstimator.lowest_face_z`), so a
    face not met by then is missed; a face met above the floor ends the descent at contact.
    """
    below = min(max(face_z - lowest_face_z, scale_drop, 0.0), tallest)
    return min(previous, -overtravel - below)


def descent_missed(depth_error: float, standoff: float, floor: float,
                   at_floor: float) -> bool:
    """Whether a descent has passed the predicted face without contact.

    ``depth_error`` m: the tool's distance short of its commanded ``standoff`` m (positive:
    above it); ``floor`` m: the deepest command (:func:`descent_floor`); ``at_floor`` s: how
    long the command has rested at the floor with the tool within DESCENT_SETTLED of it. The arm
    follows the commanded descent some millimetres late: a miss is the tool itself past the
    predicted face, or the tool resting near the floor for DESCENT_WAIT. A tool still far
    above (the wrist swinging through its J5 = 0 singularity leaves the tool 10-20 mm
    behind the command) is waited for, up to the phase's time-out.
    """
    return depth_error + standoff <= floor + DESCENT_ARRIVED or at_floor > DESCENT_WAIT


def lift_position(start: NDArray[np.float64], base: NDArray[np.float64], rise: float,
                  lift_height: float, retreat: float) -> NDArray[np.float64]:
    """(3,) tool position ``rise`` m into a lift from ``start`` (3,), world frame, m.

    Straight up, and towards the robot's vertical axis through ``base`` (3,; only its x, y
    count) by ``retreat`` m over the whole ``lift_height``: in proportion to the rise, so the
    tool leaves the belt upwards and the arm pulls in as it rises.
    """
    out = np.asarray(start, dtype=float) + np.array([0.0, 0.0, rise])
    inward = np.asarray(base, dtype=float)[:2] - out[:2]
    dist = float(np.linalg.norm(inward))
    if retreat > 0.0 and dist > 1e-9 and lift_height > 0.0:
        out[:2] += inward / dist * min(retreat * rise / lift_height, dist)
    return out


class ArmPhases:
    """Approach to verify; the attributes below are PhaseLogic's (set in its __init__)."""

    ep: Episode
    phase_start: float
    done: bool
    _standoff: float
    _tilt_share: float
    _face_share: float
    _planned_normal: NDArray[np.float64]
    _at_floor: float
    _floor: float
    _last_lateral: float
    _settled: int
    _lift_from: NDArray[np.float64] | None
    _lift_base: NDArray[np.float64]
    _grasped: list[str]
    _cycle_end: float | None
    _pick_point: PickPoint | None
    _aim_side: NDArray[np.float64]
    _sight: NDArray[np.float64]
    _below: float
    _search_from: float
    phase: str

    def fail(self, reason: str, detail: str) -> None:
        raise NotImplementedError

    def _enter(self, phase: str, t: float) -> None:
        raise NotImplementedError

    def _check_track(self, t: float) -> bool:
        raise NotImplementedError

    def _aim(self, state: TargetState) -> TargetState:
        """The tracked face ``state`` with its centre moved to the point the cup aims at
        (:mod:`stackpick_sim.control.pick_point`: a tape roll's ring, not its hole)."""
        if self._pick_point is None:
            return state
        return aimed(state, self._pick_point.offset(self.ep.estimator.radius), self._aim_side)

    def _belief(self, state: TargetState) -> AimBelief:
        """What the controller believes of the tracked face ``state`` and its aim (record):
        past the track's heights, the aim point taken down the line of sight."""
        radius = self.ep.estimator.radius
        point = self._pick_point
        aim = self._aim(state).centre
        below = max(0.0, self._search_from - self._standoff)
        return AimBelief(radius=radius, kinds=tuple(point.kinds(radius) if point else ()),
                         offset=float(np.linalg.norm(aim - state.centre)),
                         point=aim + sight_shift(self._sight, below))

    def _take_aim_side(self) -> None:
        """The aim's rules for this cell's cup, and the camera's side of the tool axis now,
        world (3,): on a level face the aim goes to the other side."""
        ep = self.ep
        model = ep.scene.cell.model
        self._pick_point = PickPoint(ep.scene.cell.cfg,
                                     lip_radius(model, model.body(CUP_BODY).id))
        tool = ep.arm.command_world_T_tool()
        axis, away = tool[:3, 2], ep.arm.eih.world_T_cam(ep.scene.cell.data)[:3, 3] - tool[:3, 3]
        self._aim_side = away - axis * float(away @ axis)

    def _plan_reach(self, t: float) -> None:
        """Share of the face tilt the tool takes at the servo standoff (control/reach.py)."""
        ep = self.ep
        cell = ep.scene.cell
        state = self._aim(ep.estimator.state(t + REACH_LEAD_S, ep.arm.eih.world_T_cam(cell.data)))
        checker = ReachChecker(cell.model)
        share, margin, clearance = checker.tilt_share(
            ep.arm.full_qpos(), state.centre, state.normal, self._standoff,
            ep.arm.command_world_T_tool())
        cfg = cell.cfg.episode
        # Where the face will be when the cup meets it (the descent's nominal duration on).
        lead = REACH_LEAD_S + cfg.standoff / max(cfg.descend_speed, 1e-6)
        grasp = self._aim(ep.estimator.state(t + lead, ep.arm.eih.world_T_cam(cell.data)))
        self._face_share = max(share, checker.tilt_share(
            ep.arm.full_qpos(), grasp.centre, grasp.normal, 0.0, ep.arm.command_world_T_tool(),
            margin=GRASP_JOINT_MARGIN, clearance=GRASP_SELF_CLEARANCE)[0])
        ep.record.grasp_tilt_share = self._face_share
        self._planned_normal = state.normal
        self._tilt_share = share
        ep.record.servo_tilt_share = share
        if math.isfinite(margin):
            ep.record.servo_joint_margin_rad = round(margin, 4)
            ep.record.servo_self_clearance_m = round(clearance, 4)

    def _replan_if_turned(self, t: float) -> None:
        """Plan the reach again once the tracked normal has turned (the consensus of views
        settled on the other solution of the pose's ambiguity)."""
        ep = self.ep
        n = ep.estimator.state(t, ep.arm.eih.world_T_cam(ep.scene.cell.data)).normal
        if float(n @ self._planned_normal) < math.cos(math.radians(REPLAN_TURN_DEG)):
            self._plan_reach(t)

    def _commanded(self, state: TargetState, standoff: float) -> TargetState:
        """The face's aim point (:meth:`_aim`) with the face normal replaced by the tool
        axis commanded at ``standoff`` m."""
        state = self._aim(state)
        if self._tilt_share >= 1.0 and self._face_share >= 1.0:
            return state
        cfg = self.ep.scene.cell.cfg.episode
        share = descent_tilt_share(self._tilt_share, standoff, cfg.standoff, self._face_share,
                                   turned_at=cfg.descend_speed * AXIS_LAG_S)
        return replace(state, normal=tilted_axis(state.normal, share))

    def _approach(self, t: float, dt: float, obs: list[Observation]) -> Command:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        if not self._check_track(t):
            return None
        self._replan_if_turned(t)
        lead = 1.0 / cfg.approach_gain
        now_T_tool = ep.arm.command_world_T_tool()
        cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        target = self._commanded(ep.estimator.state(t, cam), cfg.standoff)
        goal = ControlGoal(phase="approach", target=target,
                           lead=self._commanded(ep.estimator.state(t + lead, cam), cfg.standoff),
                           standoff=cfg.standoff, standoff_rate=0.0, dt=dt)
        ep.arm.apply((yield from self._command(goal)), dt)
        here = approach_pose(target, cfg.standoff, now_T_tool)
        pos, ang = pose_error(ep.arm.eih.world_T_ee(ep.scene.cell.data), here)
        if pos < APPROACH_DONE[0] and ang < APPROACH_DONE[1]:
            self._enter("servo", t)
        return None

    def _servo_step(self, t: float, dt: float, standoff: float, rate: float,
                    below: float = 0.0, below_rate: float = 0.0
                    ) -> Generator[ControlGoal, FloatArray | None, ServoErrors]:
        """One servo tick to ``standoff`` m from the face (changing at ``rate`` m/s), the face
        taken ``below`` m lower on the line of sight (:func:`sight_shift`; growing at
        ``below_rate`` m/s)."""
        ep = self.ep
        cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
        target = self._commanded(ep.estimator.state(t, cam), standoff)
        if below > 0.0:
            shift = sight_shift(self._sight, below)
            target = replace(target, centre=target.centre + shift,
                             velocity=target.velocity + shift / below * below_rate)
        qdot = yield from self._command(ControlGoal(phase=self.phase, target=target, lead=None,
                                                    standoff=standoff, standoff_rate=rate,
                                                    dt=dt))
        err = ep.arm.servo_errors(target, standoff)
        ep.arm.apply(qdot, dt)
        return err

    def _command(self, goal: ControlGoal
                 ) -> Generator[ControlGoal, FloatArray | None, FloatArray]:
        """(6,) joint rates for ``goal``: the goal is yielded to the episode's driver, which
        answers with an external policy's action, or None for the controller's command."""
        ep = self.ep
        action = yield goal
        qdot = np.asarray(ep.controller.command(goal, ep.arm) if action is None else action,
                          dtype=float)
        if qdot.shape != (6,) or not np.all(np.isfinite(qdot)):
            raise EpisodeError(f"the {goal.phase} command must be 6 finite joint rates (rad/s); "
                               f"got {np.round(qdot, 4).tolist()}")
        return qdot

    def _servo(self, t: float, dt: float, obs: list[Observation]) -> Command:
        cfg = self.ep.scene.cell.cfg.episode
        if not self._check_track(t):
            return None
        self._replan_if_turned(t)
        err = yield from self._servo_step(t, dt, cfg.standoff, 0.0)
        ok = (err.lateral < cfg.servo_lateral_tol and abs(err.depth) < cfg.servo_depth_tol
              and err.tilt_deg < cfg.servo_tilt_tol_deg)
        self._settled = self._settled + 1 if ok else 0
        if self._settled >= SERVO_SETTLE_TICKS:
            self._standoff = cfg.standoff
            cam = self.ep.arm.eih.world_T_cam(self.ep.scene.cell.data)
            self._sight = self._commanded(self.ep.estimator.state(t, cam), 0.0).centre - cam[:3, 3]
            self._enter("descend", t)
        return err

    def _descend(self, t: float, dt: float, obs: list[Observation]) -> Command:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        touched = touching(ep.scene.cell, ep.lips)
        if touched:
            return (yield from self._contact(t, dt, touched))
        floor = self._descent_floor(cfg.overtravel)
        # The descent waits while the tool is off the face's axis (e.g. the wrist swinging
        # through its J5 = 0 singularity): going on would bring the cup down beside the face.
        aligned = self._last_lateral < DESCENT_HOLD_LATERAL + DESCENT_HOLD_SLOPE * self._standoff
        speed = cfg.descend_speed if aligned and self._standoff > floor else 0.0
        self._standoff = max(self._standoff - speed * dt, floor)
        # Past the heights the track measured the goal goes on down the line of sight.
        below = max(0.0, self._search_from - self._standoff)
        err = yield from self._servo_step(t, dt, self._standoff + below,
                                          0.0 if below > 0.0 else -speed, below,
                                          speed if below > 0.0 else 0.0)
        self._last_lateral = err.lateral
        self._at_floor = floor_time(self._at_floor, err.depth, self._standoff, floor, dt)
        if descent_missed(err.depth, self._standoff, floor, self._at_floor):
            cam = ep.arm.eih.world_T_cam(ep.scene.cell.data)
            ep.audit.on_lip(self._belief(ep.estimator.state(t, cam)))
            self.fail("missed_grasp", "the descent passed the predicted face without contact")
            return None
        return err

    def _contact(self, t: float, dt: float, touched: list[ObjectInfo]) -> Command:
        """The lip reached ``touched``: a leak ends the pick, a seal starts the grasp."""
        ep = self.ep
        cell = ep.scene.cell
        state = ep.estimator.state(t, ep.arm.eih.world_T_cam(cell.data))
        ep.audit.on_contact(state, self._belief(state))
        leak = no_seal(cell, touched)
        if leak is not None:  # the vacuum leaks: no lift (sim/suction.py)
            self.fail("missed_grasp", f"no seal: {leak}")
            return None
        cell.data.ctrl[cell.suction_actuator_id] = 1.0
        # Pressed on past the predicted face (above it: to it); met further down the line
        # of sight, past the contact.
        self._below = max(0.0, self._search_from - self._standoff)
        pressed = (self._standoff + self._below if self._below > 0.0
                   else max(self._standoff, 0.0))
        self._standoff = pressed - GRASP_PRELOAD
        self._enter("grasp", t)
        return (yield from self._servo_step(t, dt, self._standoff, 0.0, self._below))

    def _descent_floor(self, overtravel: float) -> float:
        """This tick's :func:`descent_floor` (m), remembered for the next: the deepest of the
        ticks', the first one's camera the farthest from the face. Also the floor the
        track's heights alone set (``_search_from``): below it the descent searches for a
        face read at the wrong scale, down the line of sight (:func:`sight_shift`)."""
        ep = self.ep
        est = ep.estimator
        cfg = ep.scene.cell.cfg
        tallest = max(t.height for t in cfg.object_types.values())
        radii = [cfg.object_types[name].radius for name in cfg.objects.types]
        depth = float(ep.arm.eih.world_T_cam(ep.scene.cell.data)[2, 3]) - est.face_z
        self._search_from = descent_floor(overtravel, est.face_z, est.lowest_face_z, tallest,
                                          self._search_from)
        self._floor = descent_floor(overtravel, est.face_z, est.lowest_face_z, tallest,
                                    min(self._floor, self._search_from),
                                    larger_kind_drop(est.radius, radii, depth))
        return self._floor

    def _grasp(self, t: float, dt: float, obs: list[Observation]) -> Command:
        cfg = self.ep.scene.cell.cfg.episode
        err = yield from self._servo_step(t, dt, self._standoff, 0.0, self._below)
        if t - self.phase_start >= cfg.grasp_dwell:
            self._grasped = [o.name for o in touching(self.ep.scene.cell, self.ep.lips)]
            self._lift_from = self.ep.arm.command_world_T_tool()
            cell = self.ep.scene.cell
            self._lift_base = cell.data.xpos[cell.model.body(BASE_AXIS_BODY).id].copy()
            self._enter("lift", t)
        return err

    def _lift(self, t: float, dt: float, obs: list[Observation]) -> None:
        ep = self.ep
        cfg = ep.scene.cell.cfg.episode
        assert self._lift_from is not None
        rise = min(cfg.lift_speed * (t - self.phase_start), cfg.lift_height)
        # Straight up, the tool turning upright on the way: a tool tilted with a face that
        # faces away from the robot would otherwise fold the wrist into itself as the arm
        # reaches up (J4 link against J6 link, control/reach.py).
        axis = tilted_axis(self._lift_from[:3, 2], 1.0 - rise / cfg.lift_height)
        goal = tool_pose_on_axis(lift_position(self._lift_from[:3, 3], self._lift_base, rise,
                                               cfg.lift_height, cfg.lift_retreat),
                                 axis, 0.0, self._lift_from)
        ep.arm.apply(ep.arm.pose_rate(goal, cfg.approach_gain * 2, dt), dt)
        tool_z = ep.arm.eih.world_T_ee(ep.scene.cell.data)[2, 3]
        if tool_z >= self._lift_from[2, 3] + cfg.lift_height - 0.003:
            self._cycle_end = t
            self._enter("verify", t)

    def _verify(self, t: float, dt: float, obs: list[Observation]) -> None:
        self.ep.arm.hold()
        if t - self.phase_start >= self.ep.scene.cell.cfg.episode.verify_time:
            self.done = True

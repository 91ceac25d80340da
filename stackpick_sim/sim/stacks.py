"""Seeded piles of overlapping cylinders: physical placement, settling, rejection sampling.

The seed draws the pile's size and kinds once; then, attempt after attempt from the same
generator, cylinders are set down one by one onto the belt or onto the pile (near a previous
cylinder, preferably one whose face overlaps nothing yet, nearly upright) and simulated, with
a temporary viscous damping and MuJoCo's sleeping, until they rest; a drop that leaves a
cylinder off the belt or tilted too far is undone and redrawn. A pile is accepted when, the
damping and sleeping removed, it stays put, every cylinder rests on the belt or on others, no
axis is tilted past ``objects.max_tilt_deg``, no face lies higher than
``objects.max_face_height`` above the belt, every top face lies inside the look-pose image and
overlaps at least one other object's silhouette there, and it rides the running belt, speed
noise included, for as long as a pick takes without collapsing (checked from a saved state,
then restored).
Same config and seed give the same settled state, bit for bit.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import SceneGenerationError
from stackpick_sim.geometry import plane_basis, project_circle
from stackpick_sim.sim import randomize
from stackpick_sim.sim.cell import PARK_SPACING, PARK_X, Cell, build_cell
from stackpick_sim.sim.conveyor import Conveyor
from stackpick_sim.sim.ground_truth import top_face

#: While being placed, an object counts as resting when its speed is below this, m/s ...
REST_LINEAR_SPEED = 0.002
#: ... and its angular speed below this, rad/s. (Damped, a tipping cylinder turns slowly: a
#: looser bound declares it at rest mid-tip; soft-contact jitter of a resting pile is about
#: this size, so such drops run to ``sim.settle_time`` and the undamped check decides.)
REST_ANGULAR_SPEED = 0.05
#: Shortest simulated time after a drop before rest is checked, s (it must at least land).
MIN_DROP_TIME = 0.1
#: Rest is checked every this many steps.
REST_CHECK_STEPS = 10
#: Gap left between a dropped object's lowest point and the pile's highest point, m.
DROP_CLEARANCE = 0.005
#: Drop distance from the previous object's centre, as a range of fractions of the sum of radii:
#: from well on top of it to leaning against its rim.
NEIGHBOUR_DISTANCE = (0.4, 1.0)
#: A drop is abandoned as soon as any placed object tilts past ``objects.max_tilt_deg``: it
#: would only be rejected after settling. Damped, a tipping cylinder does not right itself:
#: of the drops whose object passed 45 deg on the way, 97 % ended past it (measured on 30
#: paper scenes); the few that would have come back are redrawn like the rest.
#: Tries at dropping one object before the whole pile is started again: a drop that leaves
#: any object off the belt or tilted too far is undone (state restored) and redrawn.
DROP_TRIES = 8
#: Largest tilt of a cylinder as it is released, degrees. Objects are dropped nearly upright:
#: the tilt of a pile comes from landing on a neighbour's rim; a tilted release tips them
#: onto their side, where they roll off the belt.
RELEASE_TILT_DEG = 5.0
#: A face must overlap another silhouette by this share of its area to count as "in a stack".
MIN_OVERLAP_FRACTION = 0.02
#: The problem of a face that overlaps no other object's silhouette (see MIN_OVERLAP_FRACTION).
OVERLAPS_NOTHING = "overlaps no other object"
#: Top faces must lie this far inside the image border, px.
IMAGE_MARGIN_PX = 2.0
#: Points per rim when rasterising silhouettes.
RIM_POINTS = 48
#: Time constants of the temporary viscous damping on the objects while they are placed, s.
#: Placement is gentle (a hand setting objects down, not a free fall), so cylinders come to
#: rest where they land instead of tumbling onto their side and rolling off the belt; the
#: damping is removed before the stability check, so accepted piles are true equilibria.
PLACEMENT_DAMPING_TAU = (0.05, 0.02)
#: Undamped time a placed pile must then stay at rest, s ...
STABILITY_CHECK_TIME = 0.3
#: ... moving no object by more than this, m, ...
STABILITY_MAX_DRIFT = 0.001
#: ... nor turning its axis by more than this, degrees. (Instantaneous velocities are not
#: used here: soft contacts keep a resting pile jittering at a few cm/s of angular speed
#: without it going anywhere.)
STABILITY_MAX_TURN_DEG = 1.0
#: A valid pile must also ride the running belt this long, s (an episode's pick comes about
#: 1.5 s after its first image), with the configured speed noise (``conveyor.speed_jitter``;
#: its steps jolt the pile: marginal piles that ride a steady belt collapse under them) ...
RUNNING_CHECK_TIME = 1.6
#: ... drawn from the seed-sequence stream ``[seed, RUNNING_CHECK_STREAM]`` (the episode's
#: belt uses another stream: a pile must ride a noisy belt, not one particular noise), ...
RUNNING_CHECK_STREAM = 4
#: ... moving no object by more than this relative to the belt, m, ...
RUNNING_MAX_DRIFT = 0.003
#: ... nor turning it by more than this, degrees. Stacked cylinders creep ~1.2 mm/s over
#: their neighbours on a moving belt (soft-contact slip), which this allows; marginal piles
#: collapse within a second (centimetres), which it does not.
RUNNING_MAX_TURN_DEG = 3.0


@dataclass(kw_only=True)
class Scene:
    """A settled pile in its cell, ready to render or to run an episode on."""

    cell: Cell
    seed: int
    attempts: int
    """Attempts it took (1 = the first pile was valid)."""
    rejections: dict[str, int]
    """Why the rejected attempts were rejected: reason -> count."""
    drop_retries: dict[str, int]
    """Single drops undone and redrawn within the attempts (see DROP_TRIES): reason -> count."""
    build_wall_s: float
    """Wall time spent building and settling, s."""


def _object_top_z(cell: Cell, i: int) -> float:
    obj = cell.objects[i]
    axis_z = abs(cell.data.xmat[obj.body_id][8])
    return float(cell.data.xpos[obj.body_id][2] + axis_z * obj.height / 2
                 + math.sqrt(max(0.0, 1 - axis_z**2)) * obj.radius)


def _park_all(cell: Cell) -> None:
    model, data = cell.model, cell.data
    mujoco.mj_resetData(model, data)
    cell.set_belt_speed(0.0)
    cell.set_arm(cell.look_q)
    for i, obj in enumerate(cell.objects):
        data.qpos[obj.qpos_adr:obj.qpos_adr + 7] = [PARK_X, PARK_SPACING * i, obj.height / 2,
                                                    1, 0, 0, 0]
    mujoco.mj_forward(model, data)


def _at_rest(cell: Cell, upto: int) -> bool:
    for obj in cell.objects[:upto]:
        v = cell.data.qvel[obj.dof_adr:obj.dof_adr + 6]
        if np.linalg.norm(v[:3]) > REST_LINEAR_SPEED or np.linalg.norm(v[3:]) > REST_ANGULAR_SPEED:
            return False
    return True


def _drop(cell: Cell, i: int, centre: NDArray[np.float64], rng: np.random.Generator) -> None:
    """Drop object ``i`` above the pile near a previous object and simulate until all rest."""
    cfg = cell.cfg.objects
    obj = cell.objects[i]
    data = cell.data
    if i == 0:
        r = 0.5 * cfg.pile_radius * math.sqrt(rng.uniform())
        phi = rng.uniform(0, 2 * math.pi)
        xy = centre + r * np.array([math.cos(phi), math.sin(phi)])
    else:
        # Near an object whose face overlaps no other object yet, if there is one: a pile is
        # only valid when every face is in a stack, and a drop near any object at random
        # leaves one standing alone in about half the piles.
        alone = [j for j, p in _face_problems(cell, i).items() if p.endswith(OVERLAPS_NOTHING)]
        candidates = alone or list(range(i))
        other = cell.objects[candidates[int(rng.integers(len(candidates)))]]
        d = rng.uniform(*NEIGHBOUR_DISTANCE) * (obj.radius + other.radius)
        phi = rng.uniform(0, 2 * math.pi)
        xy = data.xpos[other.body_id][:2] + d * np.array([math.cos(phi), math.sin(phi)])
        off = xy - centre
        if np.linalg.norm(off) > cfg.pile_radius:  # keep the pile together
            xy = centre + off * cfg.pile_radius / np.linalg.norm(off)
    tilt = rng.uniform(0, math.radians(RELEASE_TILT_DEG))
    heading = rng.uniform(0, 2 * math.pi)
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, np.array([math.cos(heading), math.sin(heading), 0.0]), tilt)
    half_extent = math.cos(tilt) * obj.height / 2 + math.sin(tilt) * obj.radius
    # Drop just above what lies under the new object's footprint: a drop from the top of the
    # whole pile would hit hard and scatter it.
    reach = obj.radius + half_extent
    floor = max([cell.cfg.conveyor.top_z] + [
        _object_top_z(cell, k) for k in range(i)
        if np.linalg.norm(data.xpos[cell.objects[k].body_id][:2] - xy)
        < reach + math.hypot(cell.objects[k].radius, cell.objects[k].height / 2)])
    data.qpos[obj.qpos_adr:obj.qpos_adr + 7] = [*xy, floor + DROP_CLEARANCE + half_extent, *quat]
    data.qvel[obj.dof_adr:obj.dof_adr + 6] = 0.0
    _teleported(cell)
    model = cell.model
    min_steps = math.ceil(MIN_DROP_TIME / model.opt.timestep)
    max_steps = math.ceil(cell.cfg.sim.settle_time / model.opt.timestep)
    give_up_cos = math.cos(math.radians(cfg.max_tilt_deg))
    placed = [o.body_id for o in cell.objects[:i + 1]]
    for step in range(1, max_steps + 1):
        mujoco.mj_step(model, data)
        if step % REST_CHECK_STEPS:
            continue
        if np.any(np.abs(data.xmat[placed, 8]) < give_up_cos):
            break  # an object tipped past the limit: the caller redraws this drop
        if step >= min_steps and _at_rest(cell, i + 1):
            break


def _silhouette_masks(cell: Cell, world_T_cam: NDArray[np.float64],
                      upto: int) -> list[NDArray[np.uint8]]:
    """Analytic image silhouette of each of the first ``upto`` cylinders: the hull of its two
    projected rims."""
    k = cell.intrinsics
    r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
    t = np.linspace(0, 2 * math.pi, RIM_POINTS, endpoint=False)
    masks = []
    for obj in cell.objects[:upto]:
        centre = cell.data.xpos[obj.body_id]
        axis = cell.data.xmat[obj.body_id].reshape(3, 3)[:, 2]
        u, v = plane_basis(axis)
        ring = obj.radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), v))
        pts = np.concatenate([centre + s * axis * obj.height / 2 + ring for s in (-1.0, 1.0)])
        px = k.project((pts - p_wc) @ r_wc)
        hull = cv2.convexHull(np.round(px * 16).astype(np.int32))
        mask = np.zeros((k.height, k.width), np.uint8)
        cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=4)
        masks.append(mask)
    return masks


def _placement_problem(cell: Cell, upto: int) -> str | None:
    """Why the objects placed so far are not a valid partial pile (off belt, too tilted)."""
    for obj in cell.objects[:upto]:
        if cell.fell_off_belt(obj):
            return f"{obj.name} fell off the belt"
        axis_z = abs(cell.data.xmat[obj.body_id][8])
        if math.degrees(math.acos(min(1.0, axis_z))) > cell.cfg.objects.max_tilt_deg:
            return f"{obj.name} tilted past objects.max_tilt_deg"
    return None


def _face_problems(cell: Cell, upto: int) -> dict[int, str]:
    """Objects among the first ``upto`` whose top face is not in front of the look-pose
    camera, lies above ``objects.max_face_height``, leaves the image or overlaps no other
    object's silhouette there: index -> problem (the first that applies)."""
    world_T_cam = cell.world_T_cam()
    r_wc, p_wc = world_T_cam[:3, :3], world_T_cam[:3, 3]
    k = cell.intrinsics
    silhouettes = _silhouette_masks(cell, world_T_cam, upto)
    coverage = np.sum(silhouettes, axis=0, dtype=np.uint8)  # silhouettes covering each pixel
    problems = {}
    for i, obj in enumerate(cell.objects[:upto]):
        centre, normal = top_face(cell, obj, p_wc)
        try:
            face = project_circle(r_wc.T @ (centre - p_wc), -(r_wc.T @ normal), obj.radius, k)
        except ValueError:
            problems[i] = f"{obj.name} is not in front of the camera"
            continue
        if centre[2] - cell.cfg.conveyor.top_z > cell.cfg.objects.max_face_height:
            problems[i] = f"{obj.name}'s face is above objects.max_face_height"
            continue
        u0, v0, u1, v1 = face.bounds()
        if (u0 < IMAGE_MARGIN_PX or v0 < IMAGE_MARGIN_PX or u1 > k.width - 1 - IMAGE_MARGIN_PX
                or v1 > k.height - 1 - IMAGE_MARGIN_PX):
            problems[i] = f"{obj.name}'s face leaves the image"
            continue
        others = coverage > silhouettes[i]  # covered by some other object's silhouette
        if np.count_nonzero(face.mask((k.height, k.width)) & others) \
                < MIN_OVERLAP_FRACTION * face.area:
            problems[i] = f"{obj.name} {OVERLAPS_NOTHING}"
    return problems


def pile_problem(cell: Cell) -> str | None:
    """Why the current pile is not valid, or None if it is (see the module docstring)."""
    problem = _placement_problem(cell, len(cell.objects))
    if problem is not None:
        return problem
    problems = _face_problems(cell, len(cell.objects))
    return problems[min(problems)] if problems else None


_SLEEP = int(mujoco.mjtEnableBit.mjENBL_SLEEP)


def _set_placement_mode(cell: Cell, on: bool) -> None:
    """Switch the placement aids on or off: a viscous damping on the objects, and MuJoCo's
    sleeping (objects at rest, parked ones included, are not simulated until something touches
    them: a drop then costs the steps of the objects it moves, not of the whole pile). Both
    are off for the stability checks and the episode, which see the true, awake physics."""
    model = cell.model
    tau_lin, tau_ang = PLACEMENT_DAMPING_TAU
    for obj in cell.objects:
        dofs = slice(obj.dof_adr, obj.dof_adr + 6)
        if on:
            mass = model.body_mass[obj.body_id]
            inertia = model.body_inertia[obj.body_id]
            model.dof_damping[dofs] = np.concatenate([np.full(3, mass / tau_lin),
                                                      inertia / tau_ang])
        else:
            model.dof_damping[dofs] = 0.0
    _set_sleep(cell, on)


def _set_sleep(cell: Cell, on: bool) -> None:
    """Allow sleeping or not; switching it off wakes every object (at the next forward)."""
    if on:
        cell.model.opt.enableflags |= _SLEEP
    else:
        cell.model.opt.enableflags &= ~_SLEEP
    mujoco.mj_forward(cell.model, cell.data)


def _teleported(cell: Cell) -> None:
    """After writing object poses directly: wake all objects and recompute the kinematics (a
    sleeping object's pose is not updated from qpos)."""
    if cell.model.opt.enableflags & _SLEEP:
        _set_sleep(cell, False)
        _set_sleep(cell, True)
    else:
        mujoco.mj_forward(cell.model, cell.data)


def _stays_put(cell: Cell, belt: Conveyor | None = None,
               duration: float = STABILITY_CHECK_TIME, max_drift: float = STABILITY_MAX_DRIFT,
               max_turn_deg: float = STABILITY_MAX_TURN_DEG) -> bool:
    """Simulate undamped for ``duration`` (s), the belt at rest or driven by ``belt`` (its
    speed noise redrawn as in an episode) with the objects riding it; True if no object
    drifted (relative to the belt, m) or turned (deg) past the bounds."""
    ids = [o.body_id for o in cell.objects]
    pos0, axis0 = cell.data.xpos[ids].copy(), cell.data.xmat[ids][:, 6:9].copy()
    carried = 0.0  # belt travel, m along world +y
    if belt is not None:
        belt.start()
    dt = cell.model.opt.timestep
    for _ in range(math.ceil(duration / dt)):
        mujoco.mj_step(cell.model, cell.data)
        if belt is not None:
            carried += belt.speed * dt
            belt.update()
    if belt is not None:
        belt.stop()
    drift = np.linalg.norm(cell.data.xpos[ids] - pos0 - [0.0, carried, 0.0], axis=1)
    cos_turn = np.clip(np.sum(cell.data.xmat[ids][:, 6:9] * axis0, axis=1), -1.0, 1.0)
    return bool(np.all(drift <= max_drift)
                and np.all(np.degrees(np.arccos(cos_turn)) <= max_turn_deg))


def _stable_on_running_belt(cell: Cell, rng: np.random.Generator) -> bool:
    """Whether the pile also stays put on the running belt, its speed noise drawn from
    ``rng``; the cell's state is restored afterwards (the pile is delivered at rest, under the
    camera)."""
    data = cell.data
    saved = [data.qpos.copy(), data.qvel.copy(), data.act.copy(), data.qacc_warmstart.copy()]
    time_saved = data.time
    belt = cell.cfg.conveyor
    # Ride at most until the leading object nears the belt's end (a short belt, a fast belt).
    lead = max(data.xpos[o.body_id][1] + o.radius + o.height for o in cell.objects)
    duration = min(RUNNING_CHECK_TIME, (belt.length / 2 - lead) / belt.speed)
    try:
        return _stays_put(cell, Conveyor(cell, rng), duration, RUNNING_MAX_DRIFT,
                          RUNNING_MAX_TURN_DEG)
    finally:
        data.time = time_saved
        for dst, src in zip((data.qpos, data.qvel, data.act, data.qacc_warmstart), saved,
                            strict=True):
            dst[:] = src
        mujoco.mj_forward(cell.model, data)


def _reason(problem: str) -> str:
    """A problem without the object's name, for counting."""
    return problem.split(" ", 1)[1] if problem.startswith("obj") else problem


def settle_pile(cell: Cell, rng: np.random.Generator,
                retries: Counter[str] | None = None) -> str | None:
    """Reset the cell and place a fresh pile drawn from ``rng``; None if it came to rest.

    Otherwise the reason it could not be placed. The pile may still be invalid in other ways
    (check ``pile_problem``).
    """
    _park_all(cell)
    jitter = cell.cfg.objects.centre_jitter
    centre = cell.look_point[:2] + jitter * rng.standard_normal(2)
    model, data = cell.model, cell.data
    _set_placement_mode(cell, True)
    try:
        for i in range(len(cell.objects)):
            saved = (data.time, data.qpos.copy(), data.qvel.copy())
            for _ in range(DROP_TRIES):
                _drop(cell, i, centre, rng)
                problem = _placement_problem(cell, i + 1)
                if problem is None:
                    break
                if retries is not None:
                    retries[_reason(problem)] += 1
                data.time, data.qpos[:], data.qvel[:] = saved[0], saved[1], saved[2]
                _teleported(cell)
            else:
                return problem
    finally:
        _set_placement_mode(cell, False)
    face_problems = _face_problems(cell, len(cell.objects))  # cheap: before the physics check
    if face_problems:
        return face_problems[min(face_problems)]
    if not _stays_put(cell):
        return "not at rest"
    mujoco.mj_forward(model, data)
    return None


def generate_scene(cfg: SceneConfig, seed: int) -> Scene:
    """The settled scene of ``cfg`` and ``seed`` (deterministic), or SceneGenerationError."""
    start = time.perf_counter()
    cfg = randomize.draw(cfg, seed)  # the scene's own draw of any [randomize] keys
    rng = np.random.default_rng(seed)
    lo, hi = cfg.objects.count
    count = int(rng.integers(lo, hi + 1))
    kinds = [cfg.objects.types[int(k)] for k in rng.integers(len(cfg.objects.types), size=count)]
    cell = build_cell(cfg, kinds, seed)
    problems: Counter[str] = Counter()
    retries: Counter[str] = Counter()
    belt_rng = np.random.default_rng([seed, RUNNING_CHECK_STREAM])
    for attempt in range(1, cfg.sim.max_attempts + 1):
        problem = settle_pile(cell, rng, retries) or pile_problem(cell)
        if (problem is None and cfg.conveyor.speed > 0
                and not _stable_on_running_belt(cell, belt_rng)):
            problem = "collapses on the running belt"
        if problem is None:
            return Scene(cell=cell, seed=seed, attempts=attempt, rejections=dict(problems),
                         drop_retries=dict(retries), build_wall_s=time.perf_counter() - start)
        problems[_reason(problem)] += 1
    worst = ", ".join(f"{n}x {r}" for r, n in problems.most_common())
    raise SceneGenerationError(
        f"seed {seed}: no valid pile of {count} objects in {cfg.sim.max_attempts} attempts "
        f"({worst}); try fewer objects (objects.count), a larger objects.max_tilt_deg or "
        f"objects.pile_radius, or more sim.max_attempts")

"""One pick as a phase machine: look, detect, track, approach, servo, descend, grasp, lift,
verify (the issue's phases, :data:`~stackpick_sim.episodes.record.PHASES`).

Time runs in control ticks of ``episode.control_period`` (physics at ``sim.timestep``
between them). At every tick: kinematics are brought up to date, a frame is captured if
one is due, detections whose latency has passed are fused into the tracker, the current
phase computes the arm's joint rates, and the physics advances. Every phase has a
time-out; any failure ends the episode with a reason from
:data:`~stackpick_sim.episodes.record.FAILURES`. Physics trouble (a MuJoCo warning or a
non-finite state) ends it as ``unstable_sim``, never as an exception.

Random streams (``np.random.default_rng([seed, k])``): the pile uses ``seed`` alone, its
running-belt check ``k = 4`` (``stacks.RUNNING_CHECK_STREAM``) and the look snapshot
``k = 1``; here the camera noise is ``k = CAMERA_STREAM`` and the belt speed noise
``k = BELT_STREAM``. The scene's own draws: the belt's wear marks ``k = 6``
(``cell.BELT_TEXTURE_STREAM``), randomised keys ``k = 7`` (``randomize.RANDOMIZE_STREAM``),
clutter ``k = 8`` (``cell.CLUTTER_STREAM``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from stackpick_sim.control import ControlError
from stackpick_sim.episodes.arm import ArmController, ServoErrors
from stackpick_sim.episodes.hypotheses import RadiusHypotheses
from stackpick_sim.episodes.outcome import lip_geoms, unstable
from stackpick_sim.episodes.phases import PhaseLogic
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.sensing import Observation, Sensor
from stackpick_sim.exceptions import EstimationError, StackpickError
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.conveyor import Conveyor
from stackpick_sim.sim.stacks import Scene

#: Seed-sequence stream of the camera's pixel noise and light jitter.
CAMERA_STREAM = 2
#: Seed-sequence stream of the belt speed noise.
BELT_STREAM = 3


@dataclass(kw_only=True)
class TickInfo:
    """What a hook sees at each control tick (read-only by convention)."""

    time: float
    phase: str
    observations: list[Observation]
    servo: ServoErrors | None
    episode: Episode


@dataclass(kw_only=True)
class EpisodeHooks:
    """Optional callbacks: ``on_tick`` after each tick's control, before the physics."""

    on_tick: Callable[[TickInfo], None] | None = None
    keep_images: bool = False
    """Render and keep every camera frame (replay), whatever the detector."""


@dataclass(kw_only=True)
class Episode:
    """The live state of one episode (what :class:`PhaseLogic` and hooks work on)."""

    scene: Scene
    record: EpisodeRecord
    sensor: Sensor
    arm: ArmController
    estimator: RadiusHypotheses
    conveyor: Conveyor
    camera: WristCamera | None
    lips: frozenset[int]
    wall: dict[str, float] = field(default_factory=dict)


def make_estimator(scene: Scene) -> RadiusHypotheses:
    """The tracker: one radius hypothesis per object kind for ``ours``, the truth for the oracle."""
    cfg = scene.cell.cfg
    oracle = cfg.episode.detector == "oracle"
    radii = sorted({t.radius for t in cfg.object_types.values()}, reverse=True)
    return RadiusHypotheses(cfg, scene.cell.intrinsics, oracle=oracle,
                            radii=(0.0,) if oracle else tuple(radii))


def run_episode(scene: Scene, hooks: EpisodeHooks | None = None) -> EpisodeRecord:
    """Run one pick on a settled scene (the scene's cell is changed); never raises on physics.

    The scene's config (``scene.cell.cfg``) supplies everything, its ``episode`` section
    the detector, tracker frame, phase settings and time-outs.
    """
    hooks = hooks or EpisodeHooks()
    wall0 = time.perf_counter()
    cell = scene.cell
    cfg = cell.cfg
    ep_cfg = cfg.episode
    record = EpisodeRecord(seed=scene.seed, scene=cfg.name, detector=ep_cfg.detector,
                           tracker_frame=ep_cfg.tracker_frame, belt_speed=cfg.conveyor.speed,
                           scene_build_wall_s=scene.build_wall_s)
    camera = WristCamera(cell)
    sensor = Sensor(cell, camera, np.random.default_rng([scene.seed, CAMERA_STREAM]),
                    detector=ep_cfg.detector, keep_images=hooks.keep_images)
    conveyor = Conveyor(cell, np.random.default_rng([scene.seed, BELT_STREAM]))
    episode = Episode(scene=scene, record=record, sensor=sensor, arm=ArmController(cell),
                      estimator=make_estimator(scene),
                      conveyor=conveyor, camera=camera, lips=lip_geoms(cell),
                      wall={"physics": 0.0, "control": 0.0, "truth": 0.0})
    model, data = cell.model, cell.data
    substeps = max(1, round(ep_cfg.control_period / model.opt.timestep))
    dt = substeps * model.opt.timestep
    data.warning.number[:] = 0  # warnings of the pile's settling are not this episode's
    data.time = 0.0  # episode time: the first image is taken at t = 0
    logic = PhaseLogic(episode)
    conveyor.start()
    try:
        while logic.failure is None and not logic.done:
            t0 = time.perf_counter()
            mujoco.mj_forward(model, data)
            episode.wall["physics"] += time.perf_counter() - t0
            problem = unstable(cell)
            if problem is not None:
                logic.fail("unstable_sim", problem)
                break
            t = float(data.time)
            if sensor.due(t):
                logic.before_capture(t)
                sensor.capture(t, episode.arm.eih.world_T_cam(data))
            observations = sensor.ready(t)
            t0 = time.perf_counter()
            servo = None
            try:
                servo = logic.tick(t, dt, observations)
            except ControlError as exc:
                logic.fail("joint_limit" if episode.arm.at_limit() else "servo_diverged",
                           f"control: {exc}")
            except EstimationError as exc:
                logic.fail("lost_track", f"estimation: {exc}")
            episode.wall["control"] += time.perf_counter() - t0
            if hooks.on_tick is not None:
                hooks.on_tick(TickInfo(time=t, phase=logic.phase, observations=observations,
                                       servo=servo, episode=episode))
            if logic.failure is not None or logic.done:
                break
            t0 = time.perf_counter()
            for _ in range(substeps):
                conveyor.update()
                mujoco.mj_step(model, data)
            episode.wall["physics"] += time.perf_counter() - t0
    except StackpickError as exc:  # a bug or bad input deeper down: still a record, not a crash
        logic.fail("unstable_sim", f"{type(exc).__name__}: {exc}")
    finally:
        camera.close()
    logic.finish()
    record.frames = sensor.frames
    record.frames_processed = sensor.processed
    record.measurements_fused = episode.estimator.fused
    record.sim_time_s = float(data.time)
    record.wall_s = time.perf_counter() - wall0
    breakdown = dict(episode.wall)
    breakdown.update(sensor.wall)
    record.wall_breakdown_s = {k: round(v, 6) for k, v in breakdown.items()}
    if not math.isfinite(record.sim_time_s):
        record.sim_time_s = -1.0
    return record

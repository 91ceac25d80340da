"""One pick as a phase machine: look, detect, track, approach, servo, descend, grasp, lift,
verify (the phases of :data:`~stackpick_sim.episodes.record.PHASES`).

Time runs in control ticks of ``episode.control_period`` (physics at ``sim.timestep``
between them). At every tick: kinematics are brought up to date, a frame is captured if
one is due, detections whose latency has passed are fused into the tracker, the current
phase computes the arm's joint rates, and the physics advances. Every phase has a
time-out; any failure ends the episode with a reason from
:data:`~stackpick_sim.episodes.record.FAILURES`. Physics trouble (a MuJoCo warning or a
non-finite state) ends it as ``unstable_sim``, never as an exception; an unexpected
exception (a bug in a plug-in stage or in this package) ends it as ``error``, its traceback
kept in :attr:`EpisodeRun.traceback`.

:class:`EpisodeRun` is the episode as an object: ``reset(seed)`` (or ``start(scene)``), then
``step()`` once per control tick until it returns False, then ``finish()`` for the record.
:func:`run_episode` is that loop; the batch runner, replays and the Gymnasium environment
share it. The detector, estimator and controller are the scene's ``episode.detector``,
``episode.estimator`` and ``episode.controller`` (:mod:`stackpick_sim.registry`).

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
import traceback
from collections.abc import Callable, Generator
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.control import ControlError
from stackpick_sim.episodes.arm import ArmController, ServoErrors
from stackpick_sim.episodes.audit import Audit, CellTruth
from stackpick_sim.episodes.outcome import lip_geoms, unstable
from stackpick_sim.episodes.phases import PhaseLogic
from stackpick_sim.episodes.record import ERROR_REASON, EpisodeRecord
from stackpick_sim.episodes.sensing import Observation, Sensor
from stackpick_sim.exceptions import EstimationError
from stackpick_sim.pipeline import ControlGoal, Controller, Detector, Estimator
from stackpick_sim.registry import TRUTH_STAGES, load, version_of
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.conveyor import Conveyor
from stackpick_sim.sim.stacks import Scene, generate_scene

FloatArray = NDArray[np.float64]

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
    estimator: Estimator
    controller: Controller
    conveyor: Conveyor
    camera: WristCamera | None
    lips: frozenset[int]
    wall: dict[str, float] = field(default_factory=dict)
    audit: Audit = field(init=False)


def estimator_name(cfg: SceneConfig) -> str:
    """The episode's estimator: ``episode.estimator``, or ``episode.tracker_frame``'s."""
    return cfg.episode.estimator or cfg.episode.tracker_frame


def make_detector(cfg: SceneConfig, truth: CellTruth) -> Detector:
    """The scene's ``episode.detector``; only a built-in that needs it gets ``truth``."""
    name = cfg.episode.detector
    factory = load("detector", name)
    detector = factory(cfg, truth) if ("detector", name) in TRUTH_STAGES else factory(cfg)
    for attr, default in (("needs_image", True), ("exact", False)):
        if not hasattr(detector, attr):
            setattr(detector, attr, default)
    return detector


def stage_versions(stages: dict[str, object]) -> dict[str, str]:
    """Version of each stage that declares one (``version`` or its module's
    ``__version__``)."""
    out = {}
    for kind, stage in stages.items():
        version = version_of(stage)
        if version is not None:
            out[kind] = version
    return out


class EpisodeRun:
    """One episode, steppable: :meth:`reset` or :meth:`start`, :meth:`step`, :meth:`finish`."""

    def __init__(self, cfg: SceneConfig, hooks: EpisodeHooks | None = None) -> None:
        self.cfg = cfg
        self.hooks = hooks or EpisodeHooks()
        self.traceback = ""
        """The traceback of the exception that ended the episode as ``error``, or empty."""

    def reset(self, seed: int) -> Episode:
        """Build and settle the pile of ``seed`` (as ``stackpick run`` does) and start on it."""
        return self.start(generate_scene(self.cfg, seed))

    def start(self, scene: Scene) -> Episode:
        """Set the episode up on a settled ``scene`` (its cell is changed by the steps)."""
        self._wall0 = time.perf_counter()
        cell = scene.cell
        cfg = self.cfg = cell.cfg
        ep_cfg = cfg.episode
        camera = WristCamera(cell)
        truth = CellTruth(cell, camera)
        detector = make_detector(cfg, truth)
        estimator = load("estimator", estimator_name(cfg))(
            cfg, cell.intrinsics, bool(getattr(detector, "exact", False)))
        controller = load("controller", ep_cfg.controller)(cfg)
        record = EpisodeRecord(
            seed=scene.seed, scene=cfg.name, detector=ep_cfg.detector,
            estimator=estimator_name(cfg), controller=ep_cfg.controller,
            stage_versions=stage_versions({"detector": detector, "estimator": estimator,
                                           "controller": controller}),
            tracker_frame=getattr(estimator, "frame", ep_cfg.tracker_frame),
            belt_speed=cfg.conveyor.speed, scene_build_wall_s=scene.build_wall_s)
        sensor = Sensor(cell, camera, np.random.default_rng([scene.seed, CAMERA_STREAM]),
                        detector=detector, keep_images=self.hooks.keep_images)
        conveyor = Conveyor(cell, np.random.default_rng([scene.seed, BELT_STREAM]))
        ep = Episode(scene=scene, record=record, sensor=sensor, arm=ArmController(cell),
                     estimator=estimator, controller=controller, conveyor=conveyor,
                     camera=camera, lips=lip_geoms(cell),
                     wall={"physics": 0.0, "control": 0.0, "truth": 0.0})
        ep.audit = Audit(ep, truth)
        self.episode = ep
        model, data = cell.model, cell.data
        self._substeps = max(1, round(ep_cfg.control_period / model.opt.timestep))
        self.dt = self._substeps * model.opt.timestep
        data.warning.number[:] = 0  # warnings of the pile's settling are not this episode's
        data.time = 0.0  # episode time: the first image is taken at t = 0
        self.logic = PhaseLogic(ep)
        self._closed = False
        conveyor.start()
        return ep

    @property
    def over(self) -> bool:
        """Whether the episode has ended (failed or verified)."""
        return self.logic.failure is not None or self.logic.done

    def step(self) -> bool:
        """One control tick (sense, decide, act, physics) with the episode's own controller;
        False once the episode is over."""
        ticks = self.ticks()
        try:
            while True:
                ticks.send(None)
        except StopIteration as stop:
            return bool(stop.value)

    def ticks(self) -> Generator[ControlGoal, FloatArray | None, bool]:
        """One control tick as a generator: it yields each :class:`ControlGoal` the arm is to
        follow and takes back (6,) joint rates (rad/s) for it, or None for the controller's
        command (an external policy drives the arm this way). Returns whether the episode
        goes on."""
        if self.over:
            return False
        try:
            yield from self._tick()
        except Exception as exc:  # a bug in a stage or here: an ``error`` record, not a crash
            self.traceback = traceback.format_exc()
            self.logic.fail(ERROR_REASON, f"{type(exc).__name__}: {exc}")
        if self.over:
            self._close_camera()
        return not self.over

    def _tick(self) -> Generator[ControlGoal, FloatArray | None, None]:
        ep, logic = self.episode, self.logic
        cell = ep.scene.cell
        model, data = cell.model, cell.data
        t0 = time.perf_counter()
        mujoco.mj_forward(model, data)
        ep.wall["physics"] += time.perf_counter() - t0
        problem = unstable(cell)
        if problem is not None:
            logic.fail("unstable_sim", problem)
            return
        t = float(data.time)
        if ep.sensor.due(t):
            logic.before_capture(t)
            ep.sensor.capture(t, ep.arm.eih.world_T_cam(data))
        observations = ep.sensor.ready(t)
        t0 = time.perf_counter()
        servo = None
        try:
            servo = yield from logic.tick(t, self.dt, observations)
        except ControlError as exc:  # the servo law or the joint-limit QP had no solution
            logic.fail("joint_limit" if ep.arm.at_limit() else "servo_diverged",
                       f"control: {exc}")
        except EstimationError as exc:  # the track's geometry became impossible
            logic.fail("lost_track", f"estimation: {exc}")
        ep.wall["control"] += time.perf_counter() - t0
        if self.hooks.on_tick is not None:
            self.hooks.on_tick(TickInfo(time=t, phase=logic.phase, observations=observations,
                                        servo=servo, episode=ep))
        if self.over:
            return
        t0 = time.perf_counter()
        for _ in range(self._substeps):
            ep.conveyor.update()
            mujoco.mj_step(model, data)
        ep.wall["physics"] += time.perf_counter() - t0

    def _close_camera(self) -> None:
        if not self._closed and self.episode.camera is not None:
            self.episode.camera.close()
        self._closed = True

    def finish(self) -> EpisodeRecord:
        """Judge the outcome and complete the record (call once, after the last step)."""
        self._close_camera()
        ep = self.episode
        try:
            self.logic.finish()
        except Exception as exc:
            self.traceback = traceback.format_exc()
            ep.record.failure, ep.record.success = ERROR_REASON, False
            ep.record.failure_detail = f"judging the outcome: {type(exc).__name__}: {exc}"
        record = ep.record
        data = ep.scene.cell.data
        record.frames = ep.sensor.frames
        record.frames_processed = ep.sensor.processed
        record.measurements_fused = ep.estimator.fused
        record.sim_time_s = float(data.time)
        record.wall_s = time.perf_counter() - self._wall0
        breakdown = dict(ep.wall)
        breakdown.update(ep.sensor.wall)
        record.wall_breakdown_s = {k: round(v, 6) for k, v in breakdown.items()}
        if not math.isfinite(record.sim_time_s):
            record.sim_time_s = -1.0
        return record


def run_episode(scene: Scene, hooks: EpisodeHooks | None = None) -> EpisodeRecord:
    """Run one pick on a settled scene (the scene's cell is changed); never raises on physics
    or on an exception inside the episode (the record says ``error``).

    The scene's config (``scene.cell.cfg``) supplies everything, its ``episode`` section
    the stages, phase settings and time-outs.
    """
    run = EpisodeRun(scene.cell.cfg, hooks)
    run.start(scene)
    while run.step():
        pass
    return run.finish()

"""Frozen scene configuration: one ``SceneConfig`` nests every section of a ``scenes/*.toml``.

Units: metres, seconds, kilograms, degrees where the name says ``_deg``. World frame: z up,
the belt runs along +y with its centre line at ``x = conveyor.x``; the arm's base is at the
origin. Every section validates itself in ``__post_init__`` and raises
:class:`~stackpick_sim.exceptions.ConfigError` naming the dotted key.
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field
from typing import Literal

from stackpick_sim.exceptions import ConfigError

#: A pile larger than this cannot be placed so that every face overlaps another object
#: within the camera's view; rejection sampling would only spin.
MAX_OBJECTS = 10
#: The highest face must stay this far below the camera at the look pose, m (the camera's
#: near clipping and a face that still fits the image).
MIN_FACE_CLEARANCE = 0.1


def _require(ok: bool, key: str, value: object, allowed: str) -> None:
    if not ok:
        raise ConfigError(f"{key} = {value!r} is out of range; allowed: {allowed}")


def _positive(key: str, value: float) -> None:
    _require(math.isfinite(value) and value > 0, key, value, "a finite number > 0")


def _non_negative(key: str, value: float) -> None:
    _require(math.isfinite(value) and value >= 0, key, value, "a finite number >= 0")


@dataclass(frozen=True, kw_only=True)
class ConveyorCfg:
    """The belt: a static box whose surface moves (MuJoCo ``surfacevel``)."""

    speed: float = 0.1
    """Nominal belt speed, m/s along world +y."""
    speed_jitter: float = 0.0
    """Std of the belt speed noise (the paper's n(k)), m/s, redrawn every ``jitter_period``."""
    jitter_period: float = 0.1
    """Seconds between redraws of the speed noise."""
    x: float = 0.40
    """Belt centre line, world x, m (the VS-060 reaches tool-down picks to about 0.56 m)."""
    top_z: float = 0.10
    """Height of the belt surface, m."""
    width: float = 0.30
    """Belt width along x, m."""
    length: float = 1.40
    """Belt length along y, m, centred on y = 0; objects past its ends are out of the cell."""
    friction: float = 1.0
    """Sliding friction of the belt surface (it carries objects by friction)."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.speed) and 0 <= self.speed <= 1.0, "conveyor.speed",
                 self.speed, "0 to 1.0 m/s")
        _non_negative("conveyor.speed_jitter", self.speed_jitter)
        _positive("conveyor.jitter_period", self.jitter_period)
        for key in ("width", "length", "friction"):
            _positive(f"conveyor.{key}", getattr(self, key))
        _require(math.isfinite(self.top_z) and 0.02 <= self.top_z <= 0.5, "conveyor.top_z",
                 self.top_z, "0.02 to 0.5 m")
        _require(math.isfinite(self.x) and 0.3 <= self.x <= 0.6, "conveyor.x", self.x,
                 "0.3 to 0.6 m (the arm's pick zone)")


@dataclass(frozen=True, kw_only=True)
class ObjectTypeCfg:
    """One kind of cylinder (the paper used two)."""

    radius: float
    """m"""
    height: float
    """m"""
    mass: float
    """kg"""
    rgba: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    """Colour, components in [0, 1]."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.radius) and 0.01 <= self.radius <= 0.06,
                 "object_types.*.radius", self.radius, "0.01 to 0.06 m")
        _require(math.isfinite(self.height) and 0.01 <= self.height <= 0.15,
                 "object_types.*.height", self.height, "0.01 to 0.15 m")
        _require(math.isfinite(self.mass) and 0.01 <= self.mass <= 0.6,
                 "object_types.*.mass", self.mass, "0.01 to 0.6 kg (what the suction cup holds)")
        _require(all(0.0 <= c <= 1.0 for c in self.rgba), "object_types.*.rgba", self.rgba,
                 "four components in [0, 1]")


def _default_types() -> dict[str, ObjectTypeCfg]:
    return {
        "large": ObjectTypeCfg(radius=0.035, height=0.03, mass=0.15, rgba=(0.85, 0.6, 0.25, 1.0)),
        "small": ObjectTypeCfg(radius=0.025, height=0.025, mass=0.08, rgba=(0.3, 0.6, 0.85, 1.0)),
    }


@dataclass(frozen=True, kw_only=True)
class ObjectsCfg:
    """How piles are made."""

    count: tuple[int, int] = (3, 5)
    """[min, max] number of cylinders per scene, both inclusive."""
    types: tuple[str, ...] = ("large", "small")
    """Names of ``object_types`` to draw from, uniformly."""
    max_tilt_deg: float = 45.0
    """Largest allowed tilt of a settled cylinder's axis from vertical, degrees."""
    pile_radius: float = 0.05
    """Horizontal spread of drop points around the pile centre, m."""
    centre_jitter: float = 0.02
    """Std of the pile centre's offset from the look point, m."""
    max_face_height: float = 0.15
    """Highest a top face's centre may lie above the belt, m: a pile with a higher face is
    redrawn, and the detectors look for faces between this height and the belt (see
    :func:`stackpick_sim.geometry.face_depth_range`)."""

    def __post_init__(self) -> None:
        lo, hi = self.count
        _require(1 <= lo <= hi, "objects.count", list(self.count),
                 "[min, max] with 1 <= min <= max")
        _require(hi <= MAX_OBJECTS, "objects.count", list(self.count),
                 f"at most {MAX_OBJECTS} objects (more cannot be placed in one camera view)")
        _require(len(self.types) >= 1, "objects.types", list(self.types), "at least one type name")
        _require(math.isfinite(self.max_tilt_deg) and 0 < self.max_tilt_deg <= 80,
                 "objects.max_tilt_deg", self.max_tilt_deg, "0 < tilt <= 80 degrees")
        _require(math.isfinite(self.pile_radius) and 0 <= self.pile_radius <= 0.1,
                 "objects.pile_radius", self.pile_radius, "0 to 0.1 m")
        _require(math.isfinite(self.centre_jitter) and 0 <= self.centre_jitter <= 0.05,
                 "objects.centre_jitter", self.centre_jitter, "0 to 0.05 m")
        _require(math.isfinite(self.max_face_height) and 0.01 <= self.max_face_height <= 0.5,
                 "objects.max_face_height", self.max_face_height, "0.01 to 0.5 m")


@dataclass(frozen=True, kw_only=True)
class CameraCfg:
    """The wrist camera."""

    width: int = 320
    """px (the paper's camera: 320x240)"""
    height: int = 240
    """px"""
    fovy_deg: float = 45.0
    """Vertical field of view, degrees."""
    look_height: float = 0.30
    """Camera height above the belt surface at the look pose, m."""
    noise_std: float = 0.0
    """Std of additive Gaussian pixel noise, grey levels (0-255 scale)."""
    fps: float = 30.0
    """Frame rate, Hz."""
    shadows: bool = False
    """Render shadows (several times slower on a CPU renderer; the ring light casts few)."""
    latency_s: float = 0.010
    """Delay from a frame's capture to its detection being usable, s. Measured: the vision
    pipeline's median ``timings_ms["total"]`` on 320x240 paper-scene frames was 8-9 ms on the
    project's 2-core machine (benchmarks/bench_episodes.py, 2025), rounded up to 10 ms.
    Modelled as this constant, never the wall clock, so episodes are deterministic."""

    def __post_init__(self) -> None:
        _require(16 <= self.width <= 4096, "camera.width", self.width, "16 to 4096 px")
        _require(16 <= self.height <= 4096, "camera.height", self.height, "16 to 4096 px")
        _require(math.isfinite(self.fovy_deg) and 10 <= self.fovy_deg <= 120, "camera.fovy_deg",
                 self.fovy_deg, "10 to 120 degrees")
        _require(math.isfinite(self.look_height) and 0.15 <= self.look_height <= 0.6,
                 "camera.look_height", self.look_height, "0.15 to 0.6 m")
        _require(math.isfinite(self.noise_std) and 0 <= self.noise_std <= 50,
                 "camera.noise_std", self.noise_std, "0 to 50 grey levels")
        _require(math.isfinite(self.fps) and 1 <= self.fps <= 240, "camera.fps", self.fps,
                 "1 to 240 Hz")
        _require(math.isfinite(self.latency_s) and 0 <= self.latency_s <= 1.0,
                 "camera.latency_s", self.latency_s, "0 to 1 s")


@dataclass(frozen=True, kw_only=True)
class LightsCfg:
    """The paper's ring light (Fig. 3a): lights around the camera, each with its own intensity."""

    intensity: float = 1.0
    """One factor scaling all ring lights; 1.0 nominal."""
    ring: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    """Relative intensity of each ring light; their number is the length of this list."""
    ring_radius: float = 0.045
    """Radius of the ring around the optical axis, m."""
    ambient: float = 0.15
    """Ambient light of the room, [0, 1]."""
    jitter: float = 0.0
    """Relative std of a per-frame random scaling of each ring light (illumination jitter)."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.intensity) and 0 <= self.intensity <= 5, "lights.intensity",
                 self.intensity, "0 to 5")
        _require(1 <= len(self.ring) <= 16 and all(0 <= v <= 5 for v in self.ring), "lights.ring",
                 list(self.ring), "1 to 16 intensities, each 0 to 5")
        _require(math.isfinite(self.ring_radius) and 0.01 <= self.ring_radius <= 0.2,
                 "lights.ring_radius", self.ring_radius, "0.01 to 0.2 m")
        _require(0 <= self.ambient <= 1, "lights.ambient", self.ambient, "0 to 1")
        _require(math.isfinite(self.jitter) and 0 <= self.jitter <= 0.5, "lights.jitter",
                 self.jitter, "0 to 0.5")


@dataclass(frozen=True, kw_only=True)
class SimCfg:
    """Physics settings."""

    timestep: float = 0.002
    """s"""
    settle_time: float = 1.5
    """Longest time one dropped object is simulated to come to rest, s."""
    max_attempts: int = 200
    """Rejection-sampling budget per scene."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.timestep) and 1e-4 <= self.timestep <= 0.01, "sim.timestep",
                 self.timestep, "1e-4 to 0.01 s")
        _require(math.isfinite(self.settle_time) and 0.2 <= self.settle_time <= 10,
                 "sim.settle_time", self.settle_time, "0.2 to 10 s")
        _require(1 <= self.max_attempts <= 10_000, "sim.max_attempts", self.max_attempts,
                 "1 to 10000")


#: Built-in detectors an episode can use (stackpick_sim/registry.py; plug-ins by name too).
DETECTORS: tuple[str, ...] = ("ours", "oracle", "rht", "findellipses")
#: Frames the Kalman tracker can estimate in (stackpick_sim.estimation.kalman).
TrackerFrame = Literal["belt", "image"]
TRACKER_FRAMES: tuple[str, ...] = typing.get_args(TrackerFrame)


@dataclass(frozen=True, kw_only=True)
class EpisodeCfg:
    """One pick: phase settings and time-outs (stackpick_sim/episodes/).

    Defaults are placeholders chosen in simulation for the paper cell, not identified on
    hardware; each is what the name says, in SI units.
    """

    detector: str = "ours"
    """``ours`` (the vision pipeline), ``oracle`` (ground-truth top object and pose), ``rht``
    or ``findellipses`` (baseline ellipse detectors with our top rule and pose), or a
    plug-in: ``module:attr`` or an entry point of ``stackpick_sim.detectors``."""
    estimator: str = ""
    """``belt`` or ``image`` (the Kalman tracker in that frame) or a plug-in (``module:attr``,
    entry point of ``stackpick_sim.estimators``); empty: ``tracker_frame``'s."""
    controller: str = "ibvs"
    """``ibvs`` (differential-IK approach, image-based visual servo) or a plug-in
    (``module:attr``, entry point of ``stackpick_sim.controllers``)."""
    tracker_frame: TrackerFrame = "belt"
    """Kalman state frame: ``belt`` (back-projected, metres) or ``image`` (paper, pixels)."""
    control_period: float = 0.01
    """Period of the arm controller (servo law, mink), s; a multiple of ``sim.timestep``."""
    track_frames: int = 3
    """Detections fused before the approach starts (two initialise the filter)."""
    max_retargets: int = 0
    """Times an episode may drop its tracked face for one that later frames voted top
    (stackpick_sim/episodes/topvote.py); 0: never. Off by default: on unseen seeds nearly
    every re-target moved between two true top faces, and on the 0.3 m/s belt the pause
    cost picks (README, "Which face is picked")."""
    standoff: float = 0.19
    """Distance tool tip to face centre along the face normal at the end of approach and
    servo, m: the largest face (r = 35 mm) must stay wholly in the 240 px tall image, whose
    centre is 60 mm off the tool axis on the camera mount (at 0.19 m it clears the top edge
    by ~10 px)."""
    approach_gain: float = 8.0
    """Gain of the approach's mink FrameTask differential IK, 1/s."""
    servo_lateral_tol: float = 0.0015
    """Servo converged: face centre within this of the tool axis, m ..."""
    servo_depth_tol: float = 0.003
    """... standoff within this, m ..."""
    servo_tilt_tol_deg: float = 1.5
    """... tool axis within this angle of the face normal, degrees."""
    descend_speed: float = 0.35
    """Speed of the descent along the approach axis, m/s."""
    overtravel: float = 0.006
    """How far past the predicted face the descent goes before calling a miss, m (further
    by as much as the track's lowest monocular face height lies below the predicted one, at
    most the tallest object's height: :func:`stackpick_sim.episodes.pick.descent_floor`)."""
    grasp_dwell: float = 0.06
    """Time the suction is on before lifting, s."""
    lift_height: float = 0.10
    """Lift of the tool after the grasp, straight up, m."""
    lift_speed: float = 0.4
    """Lift speed, m/s."""
    lift_retreat: float = 0.0
    """Horizontal travel of the tool towards the robot's base (the J1 axis) during the lift,
    m, in proportion to the rise: a grasp near the edge of the workspace (a fast belt carries
    the face far out) cannot rise straight up with the arm stretched."""
    verify_time: float = 0.15
    """Time the lifted object must stay held, s."""
    timeout_look: float = 0.2
    timeout_detect: float = 0.4
    timeout_track: float = 0.5
    timeout_approach: float = 1.2
    timeout_servo: float = 1.0
    timeout_descend: float = 1.0
    timeout_grasp: float = 0.3
    timeout_lift: float = 0.8
    timeout_verify: float = 0.5
    """Longest sim time of each phase, s; past it the episode fails with ``timeout``."""

    def __post_init__(self) -> None:
        from stackpick_sim.registry import known

        for kind in ("detector", "estimator", "controller"):
            name = getattr(self, kind)
            if kind == "estimator" and name == "":
                continue  # tracker_frame's
            _require(isinstance(name, str) and (":" in name or name in known(kind)),
                     f"episode.{kind}", name, f"{', '.join(known(kind))} or module:attr")
        _require(self.tracker_frame in TRACKER_FRAMES, "episode.tracker_frame",
                 self.tracker_frame, ", ".join(TRACKER_FRAMES))
        _require(math.isfinite(self.control_period) and 1e-3 <= self.control_period <= 0.1,
                 "episode.control_period", self.control_period, "0.001 to 0.1 s")
        _require(0 <= self.max_retargets <= 3, "episode.max_retargets", self.max_retargets,
                 "an integer 0-3")
        _require(2 <= self.track_frames <= 30, "episode.track_frames", self.track_frames,
                 "2 to 30 frames")
        for key in ("standoff", "approach_gain", "servo_lateral_tol", "servo_depth_tol",
                    "servo_tilt_tol_deg", "descend_speed", "overtravel", "lift_height",
                    "lift_speed"):
            _positive(f"episode.{key}", getattr(self, key))
        for key in ("grasp_dwell", "verify_time"):
            _non_negative(f"episode.{key}", getattr(self, key))
        _require(math.isfinite(self.lift_retreat) and 0 <= self.lift_retreat <= 0.3,
                 "episode.lift_retreat", self.lift_retreat, "0 to 0.3 m")
        for key in ("look", "detect", "track", "approach", "servo", "descend", "grasp", "lift",
                    "verify"):
            _non_negative(f"episode.timeout_{key}", getattr(self, f"timeout_{key}"))


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """A whole scene: what ``scenes/<name>.toml`` describes."""

    name: str = "paper"
    description: str = ""
    conveyor: ConveyorCfg = field(default_factory=ConveyorCfg)
    objects: ObjectsCfg = field(default_factory=ObjectsCfg)
    object_types: dict[str, ObjectTypeCfg] = field(default_factory=_default_types)
    camera: CameraCfg = field(default_factory=CameraCfg)
    lights: LightsCfg = field(default_factory=LightsCfg)
    sim: SimCfg = field(default_factory=SimCfg)
    episode: EpisodeCfg = field(default_factory=EpisodeCfg)

    def __post_init__(self) -> None:
        unknown = [t for t in self.objects.types if t not in self.object_types]
        if unknown:
            raise ConfigError(f"objects.types names unknown type(s) {unknown}; "
                              f"defined in object_types: {sorted(self.object_types)}")
        widest = max(2 * self.object_types[t].radius for t in self.objects.types)
        _require(widest < self.conveyor.width / 2, "conveyor.width", self.conveyor.width,
                 f"more than twice the widest object's diameter ({widest:.3f} m)")
        lowest = min(self.object_types[t].height for t in self.objects.types)
        top = self.camera.look_height - MIN_FACE_CLEARANCE
        _require(lowest < self.objects.max_face_height <= top,
                 "objects.max_face_height", self.objects.max_face_height,
                 f"above the lowest object's height ({lowest:.3f} m) and at least "
                 f"{MIN_FACE_CLEARANCE} m below camera.look_height ({self.camera.look_height} m)")

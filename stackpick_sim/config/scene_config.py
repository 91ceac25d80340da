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

from stackpick_sim.config.vision_params import (
    SKIPPABLE_STAGES,
    OutlineTrackingParams,
    StageSections,
)
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


def _within(key: str, value: float, lo: float, hi: float, unit: str) -> None:
    """ConfigError unless ``lo <= value <= hi`` (and finite), naming the range with its unit."""
    _require(math.isfinite(value) and lo <= value <= hi, key, value,
             f"{lo:g} to {hi:g} {unit}".rstrip())


@dataclass(frozen=True, kw_only=True)
class ConveyorCfg:
    """The belt: a static box whose surface moves (MuJoCo ``surfacevel``)."""

    speed: float = 0.1
    """Nominal belt speed, m/s along world +y; 0 to 1.0 m/s."""
    speed_jitter: float = 0.0
    """Std of the belt speed noise (the paper's n(k)), m/s, redrawn every ``jitter_period``;
    0 to 0.1 m/s (a tenth of the fastest belt: a drive holds its speed to a few per cent)."""
    jitter_period: float = 0.1
    """Seconds between redraws of the speed noise; 0.001 to 10 s (from a drive controller's
    1 ms tick to a slow drift)."""
    x: float = 0.40
    """Belt centre line, world x, m; 0.3 to 0.6 m (the VS-060 reaches tool-down picks to
    about 0.56 m)."""
    top_z: float = 0.10
    """Height of the belt surface, m; 0.02 to 0.5 m."""
    width: float = 0.30
    """Belt width along x, m; 0.05 to 2 m (conveyor belts are made from a few cm to 2 m
    wide; it must also exceed four times the widest object's radius, see SceneConfig)."""
    length: float = 1.40
    """Belt length along y, m, centred on y = 0; objects past its ends are out of the cell;
    0.2 to 10 m (from about a pile's length to a long line section)."""
    friction: float = 1.0
    """Sliding friction of the belt surface (it carries objects by friction); 0.05 to 5
    (from a slick PTFE belt to a grippy rubber one; above that MuJoCo's contact sticks the
    same)."""
    texture: bool = False
    """Draw the belt as worn rubber (grain, lengthwise wear streaks, scuffs; seeded by the
    scene seed) moving with the belt surface, instead of one flat dark colour."""
    clutter: int = 0
    """Loose items (boxes, tins) lying beside the belt, just past its side rails: seeded by the
    scene seed, visual only (they never touch the pile); 0: none, at most 12. The look view
    (0.25 m across the belt) sees them on belts narrower than about 0.2 m."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.speed) and 0 <= self.speed <= 1.0, "conveyor.speed",
                 self.speed, "0 to 1.0 m/s")
        _within("conveyor.speed_jitter", self.speed_jitter, 0.0, 0.1, "m/s")
        _within("conveyor.jitter_period", self.jitter_period, 0.001, 10.0, "s")
        _within("conveyor.width", self.width, 0.05, 2.0, "m")
        _within("conveyor.length", self.length, 0.2, 10.0, "m")
        _within("conveyor.friction", self.friction, 0.05, 5.0, "")
        _require(0 <= self.clutter <= 12, "conveyor.clutter", self.clutter, "0 to 12 items")
        _within("conveyor.top_z", self.top_z, 0.02, 0.5, "m")
        _within("conveyor.x", self.x, 0.3, 0.6, "m (the arm's pick zone)")


#: Kinds of object (``object_types.*.kind``): what their caps look like and how a cup seals.
ObjectKind = Literal["cylinder", "can", "printed", "tape"]
OBJECT_KINDS: tuple[str, ...] = typing.get_args(ObjectKind)


@dataclass(frozen=True, kw_only=True)
class ObjectTypeCfg:
    """One kind of cylinder (the paper used two)."""

    radius: float
    """m; 0.01 to 0.06"""
    height: float
    """m; 0.01 to 0.15"""
    mass: float
    """kg; 0.01 to 0.6 (what the suction cup holds)"""
    rgba: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    """Colour, components in [0, 1] (a printed lid's background, a can's body and lid)."""
    kind: ObjectKind = "cylinder"
    """``cylinder`` (one flat colour), ``can`` (a metal lid: raised rim round a recessed
    panel, specular), ``printed`` (a lid printed with text and a logo, seeded) or ``tape``
    (a roll: a ring face round a core hole)."""
    hole_radius: float = 0.0
    """Radius of a tape roll's core hole, m (``kind = "tape"`` only; 0 < hole < radius)."""
    rim_width: float = 0.004
    """Width of a can lid's raised rim, m (``kind = "can"``)."""
    rim_height: float = 0.002
    """Height of a can lid's rim above its panel, m (``kind = "can"``)."""
    specular: float = 0.15
    """Specular reflectance of the surface, [0, 1] (MuJoCo material): matte plastic 0.15, no
    blinding highlight; tinplate about 0.8."""
    shininess: float = 0.3
    """Shininess (tightness of the highlight), [0, 1] (MuJoCo material): plastic 0.3,
    tinplate about 0.8."""
    print_seed: int = 0
    """Seed of a printed lid's artwork (word, logo, stripe colour), ``kind = "printed"``."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.radius) and 0.01 <= self.radius <= 0.06,
                 "object_types.*.radius", self.radius, "0.01 to 0.06 m")
        _require(math.isfinite(self.height) and 0.01 <= self.height <= 0.15,
                 "object_types.*.height", self.height, "0.01 to 0.15 m")
        _require(math.isfinite(self.mass) and 0.01 <= self.mass <= 0.6,
                 "object_types.*.mass", self.mass, "0.01 to 0.6 kg (what the suction cup holds)")
        _require(all(0.0 <= c <= 1.0 for c in self.rgba), "object_types.*.rgba", self.rgba,
                 "four components in [0, 1]")
        _require(self.kind in OBJECT_KINDS, "object_types.*.kind", self.kind,
                 ", ".join(OBJECT_KINDS))
        if self.kind == "tape":
            _require(math.isfinite(self.hole_radius) and 0.005 <= self.hole_radius
                     <= self.radius - 0.005, "object_types.*.hole_radius", self.hole_radius,
                     "0.005 m to radius - 0.005 m")
        _require(math.isfinite(self.rim_width) and 0.001 <= self.rim_width <= self.radius / 3,
                 "object_types.*.rim_width", self.rim_width, "0.001 m to radius / 3")
        _require(math.isfinite(self.rim_height) and 0 <= self.rim_height <= 0.01,
                 "object_types.*.rim_height", self.rim_height, "0 to 0.01 m")
        for key in ("specular", "shininess"):
            value = getattr(self, key)
            _require(math.isfinite(value) and 0 <= value <= 1, f"object_types.*.{key}", value,
                     "0 to 1")


def _default_types() -> dict[str, ObjectTypeCfg]:
    return {
        "large": ObjectTypeCfg(radius=0.035, height=0.03, mass=0.15, rgba=(0.85, 0.6, 0.25, 1.0)),
        "small": ObjectTypeCfg(radius=0.025, height=0.025, mass=0.08, rgba=(0.3, 0.6, 0.85, 1.0)),
    }


@dataclass(frozen=True, kw_only=True)
class ObjectsCfg:
    """How piles are made."""

    count: tuple[int, int] = (3, 5)
    """[min, max] number of cylinders per scene, both inclusive; 1 <= min <= max <= 10."""
    types: tuple[str, ...] = ("large", "small")
    """Names of ``object_types`` to draw from, uniformly."""
    max_tilt_deg: float = 45.0
    """Largest allowed tilt of a settled cylinder's axis from vertical, degrees; above 0, at
    most 80."""
    pile_radius: float = 0.05
    """Horizontal spread of drop points around the pile centre, m; 0 to 0.1 m."""
    centre_jitter: float = 0.02
    """Std of the pile centre's offset from the look point, m; 0 to 0.05 m."""
    max_face_height: float = 0.15
    """Highest a top face's centre may lie above the belt, m: a pile with a higher face is
    redrawn, and the detectors look for faces between this height and the belt (see
    :func:`stackpick_sim.geometry.face_depth_range`); 0.01 to 0.5 m, above the lowest
    object's height and at least MIN_FACE_CLEARANCE below ``camera.look_height``."""

    def __post_init__(self) -> None:
        lo, hi = self.count
        _require(1 <= lo <= hi, "objects.count", list(self.count),
                 "[min, max] with 1 <= min <= max")
        _require(hi <= MAX_OBJECTS, "objects.count", list(self.count),
                 f"at most {MAX_OBJECTS} objects (more cannot be placed in one camera view)")
        _require(len(self.types) >= 1, "objects.types", list(self.types), "at least one type name")
        _require(math.isfinite(self.max_tilt_deg) and 0 < self.max_tilt_deg <= 80,
                 "objects.max_tilt_deg", self.max_tilt_deg, "0 < tilt <= 80 degrees")
        _within("objects.pile_radius", self.pile_radius, 0, 0.1, "m")
        _within("objects.centre_jitter", self.centre_jitter, 0, 0.05, "m")
        _within("objects.max_face_height", self.max_face_height, 0.01, 0.5, "m")


#: How motion blur is rendered (``camera.blur``).
BlurMode = Literal["subframes", "shift"]
BLUR_MODES: tuple[str, ...] = typing.get_args(BlurMode)


@dataclass(frozen=True, kw_only=True)
class CameraCfg:
    """The wrist camera."""

    width: int = 320
    """px (the paper's camera: 320x240); 16 to 4096"""
    height: int = 240
    """px; 16 to 4096"""
    fovy_deg: float = 45.0
    """Vertical field of view, degrees; 10 to 120."""
    look_height: float = 0.30
    """Camera height above the belt surface at the look pose, m; 0.15 to 0.6 m."""
    noise_std: float = 0.0
    """Std of additive Gaussian pixel noise, grey levels (0-255 scale); 0 to 50."""
    fps: float = 30.0
    """Frame rate, Hz; 1 to 240."""
    shadows: bool = False
    """Render shadows (several times slower on a CPU renderer; the ring light casts few)."""
    latency_s: float = 0.010
    """Delay from a frame's capture to its detection being usable, s. Measured: the vision
    pipeline's median ``timings_ms["total"]`` on 320x240 paper-scene frames was 8-9 ms on the
    project's 2-core machine (benchmarks/bench_episodes.py), rounded up to 10 ms.
    Modelled as this constant, never the wall clock, so episodes are deterministic. 0 to
    1 s."""

    exposure_s: float = 0.0
    """Exposure time, s (industrial cameras: 0.1-10 ms); 0: an instantaneous image. The
    exposure is centred on the frame's time stamp: the ground truth is the state at its
    middle. Motion during it blurs the image (``blur``)."""
    blur: BlurMode = "subframes"
    """How motion blur is rendered when ``exposure_s > 0``: ``subframes`` averages
    ``blur_subframes`` renders with the belt, the objects and the arm moved along their
    velocities across the exposure (faithful, one render each); ``shift`` averages shifted
    copies of one render along the pile's image motion (one render; benchmarks/bench_camera.py
    measures its error against ``subframes``)."""
    blur_subframes: int = 8
    """Renders averaged across the exposure with ``blur = "subframes"``."""
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    """Brown-Conrady lens distortion (k1, k2, p1, p2, k3), OpenCV's model and order, applied
    to the rendered pinhole image; all 0: none. Machine-vision lenses of 4-8 mm on small
    sensors: k1 about -0.05 to -0.3 (barrel)."""
    full_well: float = 0.0
    """Electrons that fill a pixel (saturation at grey 255 and gain 1); > 0 turns on the
    sensor model: photon (Poisson) noise, read noise, gain and 8-bit quantisation (Foi et al.
    2008, "Practical Poissonian-Gaussian noise modeling"). Typical 5000-20000 e-. 0: off."""
    read_noise: float = 0.0
    """Read noise, electrons rms (typical 2-10 e-); with ``full_well > 0``."""
    gain: float = 1.0
    """Analogue gain: grey levels per electron relative to gain 1 (fewer electrons make the
    same grey level, so relatively more photon noise); with ``full_well > 0``."""
    vignetting: float = 0.0
    """Relative brightness lost at the image corners (cos^4-like radial fall-off, quadratic
    in the radius), [0, 0.8]; 0: none."""
    jpeg_quality: int = 0
    """JPEG-compress every frame at this quality (1-100, OpenCV's scale); 0: no JPEG."""

    def __post_init__(self) -> None:
        _require(16 <= self.width <= 4096, "camera.width", self.width, "16 to 4096 px")
        _require(16 <= self.height <= 4096, "camera.height", self.height, "16 to 4096 px")
        _within("camera.fovy_deg", self.fovy_deg, 10, 120, "degrees")
        _within("camera.look_height", self.look_height, 0.15, 0.6, "m")
        _within("camera.noise_std", self.noise_std, 0, 50, "grey levels")
        _within("camera.fps", self.fps, 1, 240, "Hz")
        _within("camera.latency_s", self.latency_s, 0, 1.0, "s")
        _within("camera.exposure_s", self.exposure_s, 0, 0.05, "s")
        _require(self.blur in BLUR_MODES, "camera.blur", self.blur, ", ".join(BLUR_MODES))
        _require(2 <= self.blur_subframes <= 64, "camera.blur_subframes",
                 self.blur_subframes, "2 to 64")
        _require(all(math.isfinite(c) and abs(c) <= 1.0 for c in self.distortion),
                 "camera.distortion", list(self.distortion), "five coefficients in [-1, 1]")
        _require(self.full_well == 0 or (math.isfinite(self.full_well)
                                         and 100 <= self.full_well <= 1e6),
                 "camera.full_well", self.full_well, "0 (off) or 100 to 1e6 electrons")
        _within("camera.read_noise", self.read_noise, 0, 100, "electrons")
        _within("camera.gain", self.gain, 1, 64, "")
        _within("camera.vignetting", self.vignetting, 0, 0.8, "")
        _require(0 <= self.jpeg_quality <= 100, "camera.jpeg_quality", self.jpeg_quality,
                 "0 (off) or 1 to 100")

    @property
    def distorted(self) -> bool:
        """Whether the lens distorts (any coefficient non-zero)."""
        return any(c != 0.0 for c in self.distortion)


@dataclass(frozen=True, kw_only=True)
class LightsCfg:
    """The paper's ring light (Fig. 3a): lights around the camera, each with its own intensity."""

    intensity: float = 1.0
    """One factor scaling all ring lights; 1.0 nominal; 0 to 5."""
    ring: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    """Relative intensity of each ring light; their number is the length of this list; 1 to
    16 lights, each 0 to 5."""
    ring_radius: float = 0.045
    """Radius of the ring around the optical axis, m; 0.01 to 0.2 m."""
    ambient: float = 0.15
    """Ambient light of the room, 0 to 1."""
    jitter: float = 0.0
    """Relative std of a per-frame random scaling of each ring light (illumination jitter);
    0 to 0.5."""
    shadow_lamps: int = 0
    """How many ring lamps cast shadows when ``camera.shadows`` is on (the first ones); 0:
    all of them."""
    shadow_map_px: int = 1024
    """Side of each casting lamp's shadow map, px (cost grows with it and with the lamps)."""

    def __post_init__(self) -> None:
        _within("lights.intensity", self.intensity, 0, 5, "")
        _require(1 <= len(self.ring) <= 16 and all(0 <= v <= 5 for v in self.ring), "lights.ring",
                 list(self.ring), "1 to 16 intensities, each 0 to 5")
        _within("lights.ring_radius", self.ring_radius, 0.01, 0.2, "m")
        _require(0 <= self.ambient <= 1, "lights.ambient", self.ambient, "0 to 1")
        _within("lights.jitter", self.jitter, 0, 0.5, "")
        _require(0 <= self.shadow_lamps <= len(self.ring), "lights.shadow_lamps",
                 self.shadow_lamps, f"0 (all) to {len(self.ring)} (the ring's lamps)")
        _require(64 <= self.shadow_map_px <= 8192, "lights.shadow_map_px", self.shadow_map_px,
                 "64 to 8192 px")


@dataclass(frozen=True, kw_only=True)
class SuctionCfg:
    """When the suction cup seals on a face (stackpick_sim/sim/suction.py)."""

    seal: bool = True
    """Model the seal: a pick holds only where the cup's lip lies wholly on flat sealing
    surface of the face, with the cup axis within ``compliance_deg`` of its normal; off, the
    cup lifts whatever its lip touches."""
    compliance_deg: float = 20.0
    """Largest angle between the cup axis and the face normal that the bellows take up,
    degrees (bellows cups of 1.5-2.5 folds: about 15-30 deg in Schmalz's and Piab's
    catalogues; flat cups a few degrees)."""
    flatness_tol: float = 0.001
    """Largest height difference of the surface under the lip that still seals, m (a lip
    across a can's raised rim leaks)."""

    def __post_init__(self) -> None:
        _within("suction.compliance_deg", self.compliance_deg, 0, 45, "degrees")
        _within("suction.flatness_tol", self.flatness_tol, 0, 0.01, "m")


@dataclass(frozen=True, kw_only=True)
class SimCfg:
    """Physics settings."""

    timestep: float = 0.002
    """s; 1e-4 to 0.01"""
    settle_time: float = 1.5
    """Longest time one dropped object is simulated to come to rest, s; 0.2 to 10 s."""
    max_attempts: int = 200
    """Rejection-sampling budget per scene; 1 to 10000."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.timestep) and 1e-4 <= self.timestep <= 0.01, "sim.timestep",
                 self.timestep, "1e-4 to 0.01 s")
        _within("sim.settle_time", self.settle_time, 0.2, 10, "s")
        _require(1 <= self.max_attempts <= 10_000, "sim.max_attempts", self.max_attempts,
                 "1 to 10000")


@dataclass(frozen=True, kw_only=True)
class VisionCfg(StageSections):
    """The detector's settings: bounds on its work (stackpick_sim/vision/limits.py: caps that
    keep the cost of any image fixed; deterministic, so seeded runs stay reproducible; the
    defaults lie well above a pile frame's counts and change nothing on the project's
    scenes), the marking test, and one table per stage (``[vision.roi]``, ``[vision.edges]``,
    ``[vision.segments]``, ``[vision.fits]``, ``[vision.merging]``, ``[vision.refine]``,
    ``[vision.gate]``, ``[vision.complete]``, ``[vision.inner_face]``,
    ``[vision.lean]``, ``[vision.under_wall]``, ``[vision.whole_refit]``, ``[vision.top]``,
    ``[vision.markings]``,
    ``[vision.report]``, ``[vision.pose]``, ``[vision.ellipses]``:
    stackpick_sim/config/vision_params.py)."""

    max_pixels: int = 640 * 480
    """Images with more pixels are detected on a copy downscaled by the smallest integer
    factor within this, px; ellipses and pose are mapped back to the full image."""
    max_chains: int = 200
    """Connected edge pieces linked into chains, and chains kept, longest first (a pile's
    region of interest has at most ~25 chains)."""
    max_fits: int = 64
    """Segment fits passed to the merge, longest arcs first (its cost grows with their
    square)."""
    max_ellipses: int = 48
    """Merged ellipses passed to the refit and the top rule, best-supported first."""
    max_arcs: int = 24
    """Arcs the top rule's last-resort arc pairs are drawn from, longest first (24 arcs are
    276 pairs)."""
    max_refits: int = 8
    """Ellipses the top rule's contrast retry refits, best-supported first."""
    marking_depth_ratio: float = 1.0
    """The top rule's test for a marking or relief inside a face (printed artwork, a can
    end's groove): an ellipse lying inside a face whose outline shows whole is a marking, not
    an object resting on the face, when its depth read from its size and its kind's radius is
    at least this multiple of the face's (1: not nearer than the face; an object resting on
    it is nearer by about its height). Ratio."""
    marking_min_edge_share: float = 0.75
    """The same test judges only faces with at least this many interior edge pixels per
    pixel of their perimeter: markings across a face (a word, a stripe, a can end's rings)
    leave about its perimeter or more, a stray edge entering a plain face a fraction of it
    (0.06-0.63 on rendered paper-scene frames, 0.8-3 on realistic-scene faces with
    markings). Ratio."""
    time_budget_ms: float = 0.0
    """Wall-clock budget of one detection, ms; 0: none. When it runs out the detection is a
    miss naming the stage. Depends on the machine's load: results under a budget are not
    reproducible, so it is for real-time use, not for seeded runs."""
    skip_stages: tuple[str, ...] = ()
    """Detector stages skipped, by name: any of ``roi`` (search the whole frame), ``refine``
    (keep the merged fits unrefined), ``gate`` (no size gate); the others are required
    (docs/detector.md)."""

    def __post_init__(self) -> None:
        _require(set(self.skip_stages) <= set(SKIPPABLE_STAGES), "vision.skip_stages",
                 list(self.skip_stages), f"names of {', '.join(SKIPPABLE_STAGES)}")
        _require(MIN_VISION_PIXELS <= self.max_pixels <= 4096 * 4096, "vision.max_pixels",
                 self.max_pixels, f"{MIN_VISION_PIXELS} to {4096 * 4096} px")
        for key in ("max_chains", "max_fits", "max_ellipses", "max_arcs", "max_refits"):
            value = getattr(self, key)
            _require(1 <= value <= 100_000, f"vision.{key}", value, "1 to 100000")
        _require(0.5 <= self.marking_depth_ratio <= 2.0, "vision.marking_depth_ratio",
                 self.marking_depth_ratio, "0.5 to 2")
        _require(0.0 <= self.marking_min_edge_share <= 10.0, "vision.marking_min_edge_share",
                 self.marking_min_edge_share, "0 to 10")
        _require(math.isfinite(self.time_budget_ms) and self.time_budget_ms >= 0,
                 "vision.time_budget_ms", self.time_budget_ms, "0 (none) or a number > 0 ms")


#: The fewest pixels vision.max_pixels may allow: a 64x48 image.
MIN_VISION_PIXELS = 64 * 48


#: Built-in detectors an episode can use (stackpick_sim/registry.py; plug-ins by name too).
DETECTORS: tuple[str, ...] = ("ours", "oracle", "rht", "findellipses")
#: Frames the Kalman tracker can estimate in (stackpick_sim.estimation.kalman).
TrackerFrame = Literal["belt", "image"]
TRACKER_FRAMES: tuple[str, ...] = typing.get_args(TrackerFrame)


#: Allowed (min, max, unit) of EpisodeCfg's numeric settings; the reasons are in the fields'
#: docstrings.
EPISODE_RANGES: dict[str, tuple[float, float, str]] = {
    "standoff": (0.05, 0.5, "m"),
    "approach_gain": (0.1, 100.0, "1/s"),
    "servo_lateral_tol": (1e-4, 0.02, "m"),
    "servo_depth_tol": (1e-4, 0.05, "m"),
    "servo_tilt_tol_deg": (0.01, 30.0, "degrees"),
    "descend_speed": (0.01, 2.0, "m/s"),
    "overtravel": (1e-4, 0.1, "m"),
    "face_height_agreement": (1e-4, 0.02, "m"),
    "normal_vote_height_tol": (1e-4, 0.1, "m"),
    "tracked_depth_margin": (0.01, 0.9, "[0, 1]"),
    "kind_follow_time": (0.0, 2.0, "s"),
    "belt_velocity_std": (1e-4, 0.5, "m/s"),
    "belt_velocity_time": (0.0, 5.0, "s"),
    "belt_velocity_evidence": (0.1, 100.0, "(nats)"),
    "vote_size_tolerance": (0.01, 1.0, "[0, 1]"),
    "retarget_over_height": (0.0, 0.1, "m"),
    "grasp_dwell": (0.0, 2.0, "s"),
    "lift_height": (0.005, 0.5, "m"),
    "lift_speed": (0.01, 2.0, "m/s"),
    "verify_time": (0.0, 5.0, "s"),
}
#: Longest allowed time-out of one episode phase, s (see EpisodeCfg.timeout_look).
MAX_PHASE_TIMEOUT_S = 10.0


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
    """Period of the arm controller (servo law, mink), s; a multiple of ``sim.timestep``;
    0.001 to 0.1 s."""
    track_frames: int = 3
    """Detections fused before the approach starts (two initialise the filter); 2 to 30."""
    max_retargets: int = 1
    """Times an episode may drop its tracked face for one that later frames voted top
    (stackpick_sim/episodes/topvote.py): a first detection that named a face lying under
    another is outvoted by the frames after it. 0: never (the arm stops for the new
    detection: on a fast belt the pause can cost the pick). 0 to 3."""
    vote_size_tolerance: float = 0.25
    """A frame's top face is the tracked face only if its ellipse's centre lies inside the
    tracked face's predicted ellipse and its semi-major axis is within this share of the
    predicted one's, [0, 1] (stackpick_sim/episodes/topvote.py): a smaller face lying on
    the tracked one (a 25-35 mm lid on a 50 mm tape roll, 30-50 % smaller in the image) has
    its centre inside too. The tracked face's own fits differ from the prediction by a few
    per cent, and by the ratio of two kinds' radii (17-20 %) while the track holds the wrong
    kind. 0.01 to 1."""
    retarget_over_height: float = 0.010
    """A rival face that later frames name top more often than the tracked face (and in at
    least three frames), lying over it along the camera's lines of sight, takes the pick if
    it lies at least this high above the tracked face, m
    (stackpick_sim/episodes/topvote.py): the tracked face lies under it. A face resting on
    the tracked object lies about its own object's height above it (the realistic scene's
    kinds are 25-30 mm tall; the detector's poses put such faces 30-45 mm above), while
    a lower face, which lies a whole object's height below the tracked one, reads at most
    ~20 mm too high (a fit that takes in its side wall). 0 to 0.1 m."""
    standoff: float = 0.19
    """Distance tool tip to face centre along the face normal at the end of approach and
    servo, m: the largest face (r = 35 mm) must stay wholly in the 240 px tall image, whose
    centre is 60 mm off the tool axis on the camera mount (at 0.19 m it clears the top edge
    by ~10 px). 0.05 to 0.5 m (a wrist camera focuses from a few cm; beyond 0.5 m the arm
    cannot hold the tool above a face on the belt)."""
    approach_gain: float = 8.0
    """Gain of the approach's mink FrameTask differential IK, 1/s; 0.1 to 100 1/s (below,
    an approach takes tens of seconds; above, a 10 ms control step overshoots)."""
    servo_lateral_tol: float = 0.0015
    """Servo converged: face centre within this of the tool axis, m (0.1 mm, under a pixel at
    the standoff, to 20 mm, beyond which a suction cup misses the smallest face) ..."""
    servo_depth_tol: float = 0.003
    """... standoff within this, m (0.1 to 50 mm: the descent absorbs the rest) ..."""
    servo_tilt_tol_deg: float = 1.5
    """... tool axis within this angle of the face normal, degrees (0.01 to 30: a suction
    cup's bellows seal up to a few tens of degrees off the face)."""
    descend_speed: float = 0.35
    """Speed of the descent along the approach axis, m/s; 0.01 to 2 m/s (an industrial arm's
    tool speed near a part)."""
    overtravel: float = 0.006
    """How far past the predicted face the descent goes before calling a miss, m (further
    by as much as the track's lowest monocular face height lies below the predicted one, or
    the face would lie were it the pile's next larger kind, at most the tallest object's
    height: :func:`stackpick_sim.episodes.pick.descent_floor`); 0.0001 to 0.1 m (a suction
    cup's compliance is millimetres to centimetres)."""
    face_height_agreement: float = 0.001
    """The tracked face's height is the lowest of its monocular heights on which
    ``face_height_views`` of them agree within this, m
    (:func:`stackpick_sim.episodes.target.agreed_low_height`). A monocular height errs one
    way, too high: a fit that takes in the face's side wall, seen obliquely from the
    approaching wrist camera, is larger than the face, so read as nearer (5-20 mm too high on
    small printed lids, where the look pose's heights agree within 0.3 mm). 0.0001 to
    0.02 m."""
    face_height_views: int = 3
    """... and this many heights agree on it (1: the lowest height; more keeps a single fit
    that reads too far off the height); 1 to 20. Fewer heights so far: the median of the
    latest ones."""
    normal_vote_height_tol: float = 0.003
    """A view's pose votes on the tracked face's normal only while its monocular height lies
    within this of the face height (``face_height_agreement``), m: a fit that reads the face
    too high takes in its side wall, whose outline tilts both normal solutions off the
    face's (by 20 deg and more on small printed lids seen from the approaching camera,
    against the bellows' 20 deg). A placeholder, three times ``face_height_agreement``:
    the right fits' heights scatter by a few tenths of a millimetre, the wall's read 4-20 mm
    too high. 0.0001 to 0.1 m."""
    tracked_depth_margin: float = 0.25
    """Once a face is tracked, the detector expects the top face at the tracked face's
    predicted depth times 1 +- this share, [0, 1] (at the look pose: the whole pile's depth
    range). Ellipses too small or too large for a face in that range are not fitted, and the
    pose takes the face radius whose implied depth fits it best. Too narrow refuses the
    tracked face when the predicted depth is off (monocular heights read up to ~20 mm too
    high, ~10 % of the servo standoff); too wide lets the other radius in. 0.01 to 0.9."""
    kind_follow_time: float = 0.2
    """Where the scene's kinds differ in colour, the radius hypothesis of the kind the
    detector read most often on the tracked face acts while its last fused measurement is at
    most this much older than the latest of any hypothesis, s; after that it has lost the
    face and the parallax (NIS) chooses. Half the phases' longest blind time: a few missed
    frames at camera rates are not a lost face. 0 to 2 s."""
    belt_velocity_std: float = 0.01
    """Std of a tracked face's velocity about the belt's nominal one (``conveyor.speed``,
    along +y), m/s, the belt-frame tracker's prior: fused with the two-point start and held
    for ``belt_velocity_time`` (at least ``conveyor.speed_jitter``). The belt's own speed
    noise is ~2 mm/s on the paper scene; a face creeps or settles in its pile (+20 mm/s for
    about 0.1 s measured there). The start alone gives ~20 mm/s (0.5 px centre noise a frame
    apart). 0.0001 to 0.5 m/s."""
    belt_velocity_time: float = 0.2
    """Time constant with which the tracked velocity's deviation from the belt's relaxes
    between measurements, s (0: the prior acts at the start only). A face's own motion on
    the belt (settling in its pile, +20 mm/s for about 0.1 s on the paper scene) dies out
    as the belt's friction carries it; a velocity that fits biased by the image border or a
    grazing view pulled off the belt's (12-17 mm/s in the late approach on the realistic
    scene) is not carried into the blind descent (0.5 s, a 6-8 mm lip offset). Twice the
    settling time. 0 to 5 s."""
    belt_velocity_evidence: float = 6.9
    """The held prior's innovation test: another filter runs on the same measurements
    without the relaxation; once the measurements are this much more likely under it than
    under the held filter (log-likelihood ratio, nats, summed with a floor at 0: a CUSUM),
    the face moves on its own (slides, topples) and the tracker follows the measurements
    alone for the rest of the track. 6.9 = ln 1000: a face riding the belt sets it off less
    than once in a thousand measurements (tracks last a few dozen); one sliding across the
    belt at 20 mm/s sets it off within about 0.25 s (0.5 px centre noise at 0.3 m, 30 Hz).
    0.1 to 100."""
    grasp_dwell: float = 0.06
    """Time the suction is on before lifting, s; 0 to 2 s (a vacuum cup seals in tens to a
    few hundred milliseconds)."""
    lift_height: float = 0.10
    """Lift of the tool after the grasp, straight up, m; 0.005 to 0.5 m (clear of the pile,
    within the arm's reach)."""
    lift_speed: float = 0.4
    """Lift speed, m/s; 0.01 to 2 m/s (an industrial arm's tool speed with a load)."""
    lift_retreat: float = 0.0
    """Horizontal travel of the tool towards the robot's base (the J1 axis) during the lift,
    m, in proportion to the rise: a grasp near the edge of the workspace (a fast belt carries
    the face far out) cannot rise straight up with the arm stretched. 0 to 0.3 m."""
    verify_time: float = 0.15
    """Time the lifted object must stay held, s; 0 to 5 s."""
    timeout_look: float = 0.2
    timeout_detect: float = 0.4
    timeout_track: float = 0.5
    timeout_approach: float = 1.2
    timeout_servo: float = 1.0
    timeout_descend: float = 1.0
    timeout_grasp: float = 0.3
    timeout_lift: float = 0.8
    timeout_verify: float = 0.5
    """Longest sim time of each phase, s; past it the episode fails with ``timeout``. 0 to
    10 s each: the defaults are 0.2 to 1.2 s, and a phase that has not ended in ten times the
    slowest will not (a longer one only makes a failing episode take minutes)."""

    outline: OutlineTrackingParams = field(default_factory=OutlineTrackingParams)
    """Tracking mode: the tracked face's outline searched for around its prediction where
    the detector misses it (the ``[episode.outline]`` table:
    :class:`~stackpick_sim.config.vision_params.OutlineTrackingParams`)."""

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
        _within("episode.control_period", self.control_period, 1e-3, 0.1, "s")
        _require(0 <= self.max_retargets <= 3, "episode.max_retargets", self.max_retargets,
                 "an integer 0-3")
        _require(2 <= self.track_frames <= 30, "episode.track_frames", self.track_frames,
                 "2 to 30 frames")
        _require(1 <= self.face_height_views <= 20, "episode.face_height_views",
                 self.face_height_views, "an integer 1-20")
        for key, (lo, hi, unit) in EPISODE_RANGES.items():
            _within(f"episode.{key}", getattr(self, key), lo, hi, unit)
        _within("episode.lift_retreat", self.lift_retreat, 0, 0.3, "m")
        for key in ("look", "detect", "track", "approach", "servo", "descend", "grasp", "lift",
                    "verify"):
            _within(f"episode.timeout_{key}", getattr(self, f"timeout_{key}"), 0.0,
                    MAX_PHASE_TIMEOUT_S, "s")


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """A whole scene: what ``scenes/<name>.toml`` describes."""

    name: str = "paper"
    """The scene's name (records and summaries carry it); a file's name without ``.toml``."""
    description: str = ""
    """One line saying what the scene is for."""
    conveyor: ConveyorCfg = field(default_factory=ConveyorCfg)
    objects: ObjectsCfg = field(default_factory=ObjectsCfg)
    object_types: dict[str, ObjectTypeCfg] = field(default_factory=_default_types)
    camera: CameraCfg = field(default_factory=CameraCfg)
    lights: LightsCfg = field(default_factory=LightsCfg)
    sim: SimCfg = field(default_factory=SimCfg)
    suction: SuctionCfg = field(default_factory=SuctionCfg)
    episode: EpisodeCfg = field(default_factory=EpisodeCfg)
    vision: VisionCfg = field(default_factory=VisionCfg)
    randomize: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Domain randomisation: dotted scene key (``.N`` for a list's N-th element) -> [low,
    high], drawn per seed (stackpick_sim/sim/randomize.py); empty: nothing drawn."""

    def value_at(self, key: str) -> object:
        """The value of a dotted key (``.N`` indexes a list), or ConfigError naming it."""
        node: object = self
        for part in key.split("."):
            if isinstance(node, tuple) and part.isdigit() and int(part) < len(node):
                node = node[int(part)]
            elif isinstance(node, dict) and part in node:
                node = node[part]
            elif hasattr(node, "__dataclass_fields__") and part in node.__dataclass_fields__:
                node = getattr(node, part)
            else:
                raise ConfigError(f"randomize names {key!r}, which is not a scene key")
        return node

    def _check_randomize(self) -> None:
        for key, (lo, hi) in self.randomize.items():
            value = self.value_at(key)
            _require(isinstance(value, int | float) and not isinstance(value, bool),
                     f"randomize.{key}", value, "a number-valued scene key")
            _require(math.isfinite(lo) and math.isfinite(hi) and lo <= hi,
                     f"randomize.{key}", [lo, hi], "[low, high] with low <= high")

    def __post_init__(self) -> None:
        self._check_randomize()
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

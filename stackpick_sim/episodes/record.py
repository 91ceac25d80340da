"""What one episode leaves behind: its phases, failure reason and measurements.

A line of ``results.jsonl`` is :meth:`EpisodeRecord.as_dict` (an episode) or
:meth:`SceneErrorRecord.as_dict` (a seed whose pile could not be built); both carry
``schema_version``. :mod:`stackpick_sim.episodes.schema` reads and writes them; docs/records.md
lists every field with its unit. "Look view" pixels are those of the wrist camera at the look
pose (0.30 m above the belt, looking straight down): the paper's reference image.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from typing import Any

#: Phases in the order an episode goes through them.
PHASES: tuple[str, ...] = ("look", "detect", "track", "approach", "servo", "descend", "grasp",
                           "lift", "verify")

#: The fixed list of failure reasons. ``dropped`` covers any object falling: the picked one
#: out of the cup, or another one knocked off the belt (``knocked_off`` names those). All but
#: ``error`` are outcomes of the pick; ``error`` is an unexpected exception (a bug in a
#: plug-in stage or in the package, or a worker that died), not an outcome.
FAILURES: tuple[str, ...] = ("no_detection", "wrong_object", "lost_track", "servo_diverged",
                             "missed_grasp", "dropped", "joint_limit", "timeout",
                             "unstable_sim")
#: Failure reason of an episode that did not reach an outcome: an exception (in a plug-in or in
#: our code) or a worker that died. Not a result of the pick: a bug or a crash to look into.
ERROR_REASON = "error"
#: Reasons a record may give besides :data:`FAILURES`.
RUNNER_FAILURES: tuple[str, ...] = (ERROR_REASON,)

#: Version of the record layout; every record in ``results.jsonl`` carries it. A field added
#: later comes with a default, so that older records still read. Version 2 added the cup's
#: aim at contact (``target_kind``, ``believed_radius_m``, ``believed_kinds``,
#: ``aim_offset_mm``, ``lip_offset_mm``, ``aim_miss_mm``, ``lip_height_mm``).
SCHEMA_VERSION = 2

#: The picked object must rest in the cup at least this far above its start, m.
MIN_LIFT_M = 0.05


@dataclass(kw_only=True)
class PoseErrors:
    """A pose (x px, y px, theta_x deg, theta_y deg) estimated vs. true, and the errors."""

    estimated: tuple[float, float, float, float]
    actual: tuple[float, float, float, float]

    @property
    def center_error_px(self) -> float:
        """Distance of the two (x, y), px."""
        return float(((self.estimated[0] - self.actual[0]) ** 2
                      + (self.estimated[1] - self.actual[1]) ** 2) ** 0.5)

    @property
    def theta_x_error_deg(self) -> float:
        """|estimated - actual| tilt about x, deg."""
        return abs(self.estimated[2] - self.actual[2])

    @property
    def theta_y_error_deg(self) -> float:
        """|estimated - actual| tilt about y, deg."""
        return abs(self.estimated[3] - self.actual[3])

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly: both poses and the three errors."""
        return {"estimated": list(self.estimated), "actual": list(self.actual),
                "center_error_px": self.center_error_px,
                "theta_x_error_deg": self.theta_x_error_deg,
                "theta_y_error_deg": self.theta_y_error_deg}


@dataclass(kw_only=True)
class EpisodeRecord:
    """One episode's outcome (see the module docstring for the frames)."""

    seed: int
    scene: str
    detector: str
    """The detector's name as selected (built-in, ``module:attr`` or entry point)."""
    tracker_frame: str
    estimator: str = ""
    """The estimator's name as selected."""
    controller: str = ""
    """The controller's name as selected."""
    stage_versions: dict[str, str] = field(default_factory=dict)
    """``version`` of each stage that declares one (plug-ins): detector/estimator/controller."""
    belt_speed: float
    """Nominal belt speed, m/s."""
    success: bool = False
    failure: str | None = None
    failure_detail: str = ""
    """Free text: which check failed and with what numbers."""
    failed_phase: str | None = None
    picked_object: str | None = None
    target_object: str | None = None
    """The true object nearest the detected face at detection time (None: nothing there)."""
    top_objects: list[str] = field(default_factory=list)
    """Names of the true top objects at detection time."""
    knocked_off: list[str] = field(default_factory=list)
    lift_height_m: float | None = None
    """Rise of the picked object above its height at detection time, m."""
    detection: PoseErrors | None = None
    """Table 1: the first detection vs. the true pose of the target, in the look view."""
    pick_estimate: PoseErrors | None = None
    """Table 2: the Kalman estimate vs. the true pose at the pick moment, in the look view."""
    prediction_error_px: float | None = None
    """|predicted - actual| face centre at the pick moment, projected into the look view, px."""
    prediction_error_mm: float | None = None
    """|predicted - actual| face centre at the pick moment, 3-D, mm."""
    target_kind: str | None = None
    """The target object's kind (its ``object_types`` name), truth."""
    believed_radius_m: float | None = None
    """The face radius the controller took the tracked face to have when the cup reached it
    (the estimator's), m."""
    believed_kinds: list[str] = field(default_factory=list)
    """The object kinds the cup's aim took the tracked face to be (those whose radius is
    nearest ``believed_radius_m``)."""
    aim_offset_mm: float | None = None
    """How far from the tracked face centre the controller aimed the cup (0 on a disc, the
    ring's middle on a tape roll), mm."""
    lip_offset_mm: float | None = None
    """Where the cup axis met the target's true face plane, from its true centre, when the
    lip reached the face (or, after a descent that met nothing, at its end), mm: what the
    seal sees (:mod:`stackpick_sim.sim.suction`)."""
    aim_miss_mm: float | None = None
    """Distance from the controller's aim point to the cup axis at that moment, mm: how far
    the tool was off its own aim."""
    lip_height_mm: float | None = None
    """Height of the lip's centre above the target's true face plane at that moment, mm
    (about 0 at contact; at the end of a descent that met nothing, where the face was)."""
    servo_tilt_share: float | None = None
    """Share of the face's tilt the tool axis took at the servo standoff (1: along the face
    normal; less when the arm could not reach it there; the descent turns it to
    ``grasp_tilt_share``)."""
    redetections: int = 0
    """Times the first detection went unconfirmed and the top object was detected again."""
    retargets: int = 0
    """Times later frames outvoted the tracked face as the top one and the top object was
    detected again (:mod:`stackpick_sim.episodes.topvote`)."""
    grasp_tilt_share: float | None = None
    """Share of the tilt the tool takes at the face where it is predicted at the grasp (1
    unless the arm cannot meet the face square-on there)."""
    servo_joint_margin_rad: float | None = None
    """Smallest joint distance from a range end the reach check found at that pose, rad."""
    servo_self_clearance_m: float | None = None
    """Smallest gap between the forearm and the flange-side bodies at that pose, m."""
    cycle_time_s: float | None = None
    """Sim time from the first image to the end of the lift, s."""
    phases: dict[str, float] = field(default_factory=dict)
    """Sim time spent in each phase entered, s."""
    frames: int = 0
    """Camera frames captured (at ``camera.fps``)."""
    frames_processed: int = 0
    """Frames rendered and detected; the others came when the controller could not use
    them (after the grasp, or during the descent with the face predicted out of view)."""
    measurements_fused: int = 0
    sim_time_s: float = 0.0
    scene_build_wall_s: float = 0.0
    """Wall time to generate the pile (not part of ``wall_s``), s."""
    wall_s: float = 0.0
    """Wall time of the episode proper (after the pile exists), s."""
    wall_breakdown_s: dict[str, float] = field(default_factory=dict)
    """Wall time by activity: physics, render, vision, control, truth, s."""
    schema_version: int = SCHEMA_VERSION
    """Version of the record layout (:data:`SCHEMA_VERSION` when written by this package)."""

    @property
    def unfinished(self) -> bool:
        """Whether the episode reached no outcome: ``error`` (an exception or a dead worker)
        or the wall-clock limit (``timeout`` with no phase; a phase's own ``timeout`` is a
        phase that ran past its sim-time limit, an outcome)."""
        return self.failure == ERROR_REASON or (self.failure == "timeout"
                                                and self.failed_phase is None)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict; ``detection`` carries the three error fields even when null."""
        out = asdict(self)
        det = self.detection.as_dict() if self.detection is not None else None
        out["detection"] = det or {"center_error_px": None, "theta_x_error_deg": None,
                                   "theta_y_error_deg": None}
        out["pick_estimate"] = (self.pick_estimate.as_dict()
                                if self.pick_estimate is not None else None)
        return out


@dataclass(kw_only=True)
class SceneErrorRecord:
    """A seed whose pile could not be generated: no episode ran, so no rate counts it."""

    seed: int
    scene: str
    error: str
    """Why the pile could not be built."""
    schema_version: int = SCHEMA_VERSION

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict."""
        return asdict(self)


#: One line of ``results.jsonl``.
Record = EpisodeRecord | SceneErrorRecord


def episodes_of(records: Iterable[Record]) -> list[EpisodeRecord]:
    """The records of episodes (scene errors left out), in the given order."""
    return [r for r in records if isinstance(r, EpisodeRecord)]


#: Keys that differ between two runs of one seed only through the wall clock.
WALL_CLOCK_KEYS: tuple[str, ...] = ("wall_s", "wall_breakdown_s", "scene_build_wall_s")

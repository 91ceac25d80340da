"""The detector as data: an ordered tuple of named stages run on one typed state.

A :class:`Stage` is a name and a function ``(State, DetectorConfig) -> State``; the detector
(:class:`~stackpick_sim.vision.detector.TopObjectDetector`) runs ``DetectorConfig.stages``
in order, each timed into ``Detection.timings_ms`` under its name, with the time budget
checked between stages. A :class:`State` is a frozen record of what the stages pass on: the
frame and its intrinsics, the region of interest and its crop, the edge image and edge
pixels, the edge chains, the segment fits, the merged ellipses, the size gate, the top
rule's cues and choice, and finally the detection. A stage returns a new state
(:func:`dataclasses.replace`, or the cheaper :meth:`State.updated`); it reads what earlier
stages left, and a stage that needs what a missing stage makes raises :class:`StageError`
naming it.

The built-in stages (:data:`~stackpick_sim.vision.detector.STAGES`) are ``roi``, ``edges``,
``segments``, ``fitting``, ``merging``, ``refine``, ``gate``, ``top`` and ``pose``; see
docs/detector.md for what each does, which may be skipped and how to replace one.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.detection import Detection
from stackpick_sim.vision.edges import EdgeImage
from stackpick_sim.vision.limits import Deadline
from stackpick_sim.vision.markings import MarkingTest
from stackpick_sim.vision.merging import MergedEllipse
from stackpick_sim.vision.occlusion import TopChoice
from stackpick_sim.vision.roi import Roi

if TYPE_CHECKING:
    from stackpick_sim.vision.detector import DetectorConfig

#: One segment fit: (index of the chain it was fitted on, its (N, 2) pixels, the ellipse,
#: the RMS residual px), as :func:`~stackpick_sim.vision.fitting.fit_all` gives them.
Fit = tuple[int, NDArray[np.int32], Ellipse, float]


class StageError(StackpickError):
    """A stage lacks what an earlier stage makes (that stage was skipped or replaced by one
    that does not make it)."""


@dataclass(frozen=True, kw_only=True)
class Cues:
    """What the top rule reads besides the ellipses: ``k_crop``, the intrinsics of the region
    of interest's crop; ``rgb``, the crop when in colour; ``belt``, the bare belt's colour
    (None when unread); ``colour_of``, an ellipse's face colour; ``radius_of``, the radius of
    an ellipse's object kind read from its colour (None without the kinds' colours);
    ``height_of``, a radius's cylinder height; ``markings``, the test for a marking inside a
    face; ``top``, the top rule's settings; ``pose``, the pose's (the rest test reads its wall
    band test); ``radii``, the object kinds' radii (m); ``kinds_of``, without ``radius_of``
    (kinds that colour cannot tell apart), the radii of the kinds a face's size admits
    (:mod:`~stackpick_sim.vision.kind_size`); ``depth_radius_of``, the radius the depth tests
    read: ``radius_of``, else the one kind ``kinds_of`` admits."""

    k_crop: CameraIntrinsics
    rgb: NDArray[np.uint8] | None
    belt: NDArray[np.float64] | None
    colour_of: Callable[[Ellipse], NDArray[np.float64]] | None
    radius_of: Callable[[Ellipse], float | None] | None
    height_of: Callable[[float], float | None] | None
    markings: MarkingTest
    top: TopParams = field(default_factory=TopParams)
    pose: PoseParams = field(default_factory=PoseParams)
    radii: tuple[float, ...] = ()
    kinds_of: Callable[[Ellipse], tuple[float, ...]] | None = None
    depth_radius_of: Callable[[Ellipse], float | None] | None = None


def _no_points() -> NDArray[np.float64]:
    return np.zeros((0, 2), np.float64)


@dataclass(frozen=True, kw_only=True)
class State:
    """What the stages pass on; every pixel coordinate past ``roi`` is in the crop's pixels.

    Set before the first stage: ``image`` (the validated (H, W[, 3]) uint8 frame, within the
    pixel limit), its ``intrinsics`` and the time budget's ``deadline``; ``roi`` (the whole
    frame) with its crop ``work`` of size ``crop`` (H, W). Then, by the stage named: ``roi``
    the box around the pile and its crop; ``edges`` the edge image ``grad`` and the edge
    pixels ``points`` with their unit gradients ``grads`` ((N, 2) each); ``segments`` the
    edge chains; ``fitting`` the segment ``fits``; ``merging`` and ``refine`` the ``merged``
    ellipses; ``gate`` the size ``gate`` ((min, max) semi-major axis px, None: none);
    ``top`` the ``cues`` and the ``choice`` (``merged`` may gain a face of arc pairs);
    ``pose`` the ``detection``. ``timings_ms``: the stage times so far (ms, by stage name;
    one dict all states share, which the detection carries too).
    """

    image: NDArray[np.uint8]
    intrinsics: CameraIntrinsics
    deadline: Deadline
    roi: Roi
    work: NDArray[np.uint8]
    crop: tuple[int, int]
    grad: EdgeImage | None = None
    points: NDArray[np.float64] = field(default_factory=_no_points)
    grads: NDArray[np.float64] = field(default_factory=_no_points)
    segments: tuple[NDArray[np.int32], ...] = ()
    fits: tuple[Fit, ...] = ()
    merged: list[MergedEllipse] = field(default_factory=list)
    gate: tuple[float, float] | None = None
    cues: Cues | None = None
    choice: TopChoice | None = None
    detection: Detection | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)

    @property
    def pieces(self) -> tuple[NDArray[np.int32], ...]:
        """The pixels of each fit, in the fits' order."""
        return tuple([points for _, points, _, _ in self.fits])

    @property
    def chains(self) -> tuple[NDArray[np.int32], ...]:
        """The chains the merge indexes: the fitted pieces, then the edge chains."""
        return self.pieces + self.segments

    @property
    def fitted(self) -> set[int]:
        """Indices (into ``segments``) of the chains some piece of which was fitted."""
        return {c for c, _, _, _ in self.fits}

    @classmethod
    def start(cls, **given: object) -> State:
        """``State(**given)`` (the same fields, the others at their defaults) without the
        frozen dataclass constructor's cost (a fifth of it, on every frame); TypeError for a
        name that is not a field or a field without a default not given."""
        if not given.keys() <= _FIELDS or not _REQUIRED <= given.keys():
            raise TypeError(f"State fields: unknown {sorted(given.keys() - _FIELDS)}, "
                            f"missing {sorted(_REQUIRED - given.keys())}")
        new = object.__new__(State)
        d = new.__dict__
        d.update(_DEFAULTS)
        for name, make in _FACTORIES:
            if name not in given:
                d[name] = make()
        d.update(given)
        return new

    def updated(self, **changes: object) -> State:
        """This state with the fields ``changes`` names set: :func:`dataclasses.replace`
        without re-running the constructor (a tenth of its cost, on every stage of every
        frame); TypeError for a name that is not a field."""
        if not changes.keys() <= _FIELDS:
            raise TypeError(f"State has no field(s) {sorted(changes.keys() - _FIELDS)}")
        new = object.__new__(State)
        new.__dict__.update(self.__dict__)
        new.__dict__.update(changes)
        return new

    def edges(self, stage: str) -> EdgeImage:
        """The edge image, or StageError naming ``stage`` when no ``edges`` stage made it."""
        if self.grad is None:
            raise StageError(f"the {stage} stage needs the edge image: no edges stage ran "
                             "before it")
        return self.grad


_FIELDS = frozenset(f.name for f in fields(State))
#: The fields' defaults, their default factories and the fields without either.
_DEFAULTS = {f.name: f.default for f in fields(State) if f.default is not MISSING}
_FACTORIES = tuple((f.name, f.default_factory) for f in fields(State)
                   if f.default_factory is not MISSING)
_REQUIRED = _FIELDS - _DEFAULTS.keys() - {name for name, _ in _FACTORIES}


@dataclass(frozen=True)
class Stage:
    """A named step of the detector: ``run(state, config)`` returns the next state."""

    name: str
    run: Callable[[State, DetectorConfig], State]


class OutOfTime(Exception):
    """The time budget ran out after (or within) ``stage``."""

    def __init__(self, stage: str) -> None:
        super().__init__(stage)
        self.stage = stage


def check_time(deadline: Deadline, stage: str) -> None:
    """Raise OutOfTime (within ``stage``) when the ``deadline`` has passed."""
    if deadline.expired():
        raise OutOfTime(stage)


def run_stages(stages: Sequence[Stage], state: State, config: DetectorConfig, t0: float
               ) -> State:
    """Run ``stages`` in order from ``state``: each one's time (ms, since the previous one
    ended, the first since ``t0``) into the state's ``timings_ms`` under its name; OutOfTime
    after a stage that ends past the state's deadline."""
    timings = state.timings_ms
    t = t0
    for stage in stages:
        state = stage.run(state, config)
        now = time.perf_counter()
        timings[stage.name] = (now - t) * 1e3
        t = now
        check_time(state.deadline, stage.name)
    return state

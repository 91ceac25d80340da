"""Radius hypotheses: one tracked-face estimator per cylinder size, the consistent one acts.

See :class:`RadiusHypotheses`; each hypothesis is a
:class:`~stackpick_sim.episodes.target.TargetEstimator`. The built-in estimators ``belt``
and ``image`` (:class:`stackpick_sim.pipeline.Estimator`) are this in the two Kalman frames.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.sensing import Candidate, Observation
from stackpick_sim.episodes.target import NIS_SWITCH_MARGIN, TargetEstimator, TargetState
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.detector import object_kinds

FloatArray = NDArray[np.float64]

#: The built-in detectors whose posed face's radius is its kind read from its colour, where
#: the scene's kinds differ in colour (a plug-in's radius may come from anything).
COLOUR_READING_DETECTORS = ("ours", "rht", "findellipses")


class RadiusHypotheses:
    """One :class:`TargetEstimator` per candidate face radius; the most consistent one acts.

    A single image fixes a face's pose only up to scale: the face radius and its depth are
    tied. With two cylinder sizes the detector may choose the wrong radius, putting the face
    at the wrong height. Each hypothesis back-projects the same pixels onto its own plane;
    once the camera moves, only the right height keeps the track on a straight line
    (parallax), so the hypothesis with the smallest summed innovation (NIS) is used. The
    same interface as TargetEstimator.

    Where the scene's kinds differ in colour (``by_colour``), the detector reads each posed
    face's kind from its colour, a reading that does not depend on the outline's size. The
    parallax does: the fits of the approaching camera's views take in a side wall (too
    large) or a can's recessed panel (too small), and the hypothesis whose radius matches
    the wrong size, or one that has moved to another face of that size (a larger face under
    a small lid), wins on NIS. So there the kind the readings of the tracked face name most
    often acts while its hypothesis follows the face; NIS chooses only when it has lost it.
    """

    def __init__(self, cfg: SceneConfig, intrinsics: CameraIntrinsics, *, oracle: bool,
                 radii: tuple[float, ...], frame: str | None = None,
                 by_colour: bool = False) -> None:
        self._radii = radii
        self._args = (cfg, intrinsics, oracle)
        self.frame = frame or cfg.episode.tracker_frame
        self.name = self.frame
        self.by_colour = by_colour
        """Whether the detector's radius of a posed face is a reading of its kind's colour."""
        self.readings: dict[float, int] = {}
        """How often the detector read each hypothesis' radius on the tracked face."""
        self.hypotheses = self._fresh()
        self.active = self.hypotheses[0]

    def _fresh(self) -> list[TargetEstimator]:
        cfg, intrinsics, oracle = self._args
        return [TargetEstimator(cfg, intrinsics, oracle=oracle, frame=self.frame)
                for _ in self._radii]

    def reset(self) -> None:
        """Forget the face: back to the state before :meth:`start`."""
        self.hypotheses = self._fresh()
        self.active = self.hypotheses[0]
        self.readings = {}

    def start(self, obs: Observation, cand: Candidate) -> None:
        """Start every hypothesis on the first detection; the detector's radius acts first."""
        for h, r in zip(self.hypotheses, self._radii, strict=True):
            h.start(obs, cand, r)
        self.active = self._nearest(cand.radius)
        self.readings = {}
        self._read(cand)

    def _nearest(self, radius: float) -> TargetEstimator:
        return min(self.hypotheses, key=lambda h: abs((h.radius or 0) - radius))

    def _read(self, cand: Candidate | None) -> None:
        """Count the detector's radius of ``cand`` if it is a posed face."""
        if cand is None or cand.centre_cam is None or cand.radius <= 0:
            return
        radius = self._nearest(cand.radius).radius or 0.0
        self.readings[radius] = self.readings.get(radius, 0) + 1

    def _read_kind(self) -> TargetEstimator | None:
        """The hypothesis of the radius read most often (ties: the active's, then the
        earliest read), if the kinds differ in colour and it still follows the face: not
        lost, and fused within ``episode.kind_follow_time`` of the latest fused measurement."""
        if not self.by_colour or not self.readings:
            return None
        order = list(self.readings)
        radius = max(order, key=lambda r: (self.readings[r], r == self.active.radius,
                                           -order.index(r)))
        h = next(h for h in self.hypotheses if h.radius == radius)
        latest = max((g.last_fused_time or 0.0) for g in self.hypotheses)
        if (not h.initialised or h.lost
                or (h.last_fused_time or 0.0) < latest - self._args[0].episode.kind_follow_time):
            return None
        return h

    def offer(self, obs: Observation) -> bool:
        """Fuse ``obs`` into every hypothesis; switch to the most consistent one.

        The summed NIS compares hypotheses only over the same measurements: a frame that
        some hypothesis associated (fused or gated out) and another could not associate at
        all (its prediction too far from every face) costs the latter the gate's worth, as a
        gated-out measurement does.
        Otherwise a wrong height, whose track drifts off the face within a few frames,
        would stop accruing NIS and soon look better than the right one, which goes on
        paying for every measurement's noise. Only a hypothesis that fused at least as
        recently as the active one may take over: one that lost the face is no alternative.
        Where the kinds differ in colour, the kind read most often acts instead while its
        hypothesis follows the face (see the class docstring).
        """
        before = [h.nis for h in self.hypotheses]
        used = [h.offer(obs) for h in self.hypotheses]
        self._charge_unassociated(before, used)
        if self.by_colour and used[self.hypotheses.index(self.active)]:
            self._read(self.active.last_candidate)
        read = self._read_kind()
        self.active = read if read is not None else self._least_nis()
        return used[self.hypotheses.index(self.active)]

    def _charge_unassociated(self, before: list[float], used: list[bool]) -> None:
        """A hypothesis associated the frame if it fused it (``used``) or gated it out (its
        NIS rose from ``before``); where another did, one that found nothing near its
        prediction pays as much as a gated one."""
        associated = [u or h.nis > b for h, u, b in zip(self.hypotheses, used, before,
                                                        strict=True)]
        if any(associated):
            for h, a in zip(self.hypotheses, associated, strict=True):
                if not a and h.missed_last:
                    h.nis += h.tracker.config.gate_chi2

    def _least_nis(self) -> TargetEstimator:
        """The hypothesis that acts by NIS: the active one unless one that fused at least as
        recently has NIS_SWITCH_MARGIN less."""
        latest = self.active.last_fused_time or 0.0
        alive = [h for h in self.hypotheses
                 if h.initialised and (h.last_fused_time or 0.0) >= latest - 1e-9]
        best = min(alive, key=lambda h: (h.nis, h is not self.active), default=self.active)
        return best if best.nis + NIS_SWITCH_MARGIN < self.active.nis else self.active

    def state(self, t: float, world_T_cam_now: FloatArray) -> TargetState:
        """The active hypothesis' prediction at ``t`` s."""
        return self.active.state(t, world_T_cam_now)

    def expected_ellipse(self, obs: Observation) -> Ellipse | None:
        """The active hypothesis' ellipse of the face in ``obs``'s image, or None
        (:meth:`TargetEstimator.expected_ellipse`)."""
        expected = self.active.expected_ellipse(obs)
        return None if expected is None else expected[0]

    @property
    def initialised(self) -> bool:
        return self.active.initialised

    @property
    def lost(self) -> bool:
        return all(h.lost for h in self.hypotheses)

    @property
    def normal(self) -> FloatArray:
        return self.active.normal

    @property
    def face_z(self) -> float:
        return self.active.face_z

    @property
    def lowest_face_z(self) -> float:
        return self.active.lowest_face_z

    @property
    def radius(self) -> float | None:
        return self.active.radius

    @property
    def fused(self) -> int:
        return self.active.fused

    @property
    def last_fused_time(self) -> float | None:
        return self.active.last_fused_time


def kalman_estimator(cfg: SceneConfig, intrinsics: CameraIntrinsics, exact: bool,
                     frame: str) -> RadiusHypotheses:
    """The built-in tracker in ``frame``: one radius hypothesis per object kind, or the exact
    detector's own radius (``exact``: ground truth, trusted as such); the kind read from the
    colour acts where the scene's kinds differ in colour and the episode's detector reads it
    (COLOUR_READING_DETECTORS)."""
    radii = sorted({t.radius for t in cfg.object_types.values()}, reverse=True)
    types = [cfg.object_types[name] for name in cfg.objects.types]
    colours = object_kinds([(t.radius, t.rgba[:3], t.height) for t in types])[1]
    by_colour = (colours is not None and not exact
                 and cfg.episode.detector in COLOUR_READING_DETECTORS)
    return RadiusHypotheses(cfg, intrinsics, oracle=exact,
                            radii=(0.0,) if exact else tuple(radii), frame=frame,
                            by_colour=by_colour)


def belt_estimator(cfg: SceneConfig, intrinsics: CameraIntrinsics,
                   exact: bool) -> RadiusHypotheses:
    """``belt``: the Kalman filter on the belt plane, back-projected detections (metres)."""
    return kalman_estimator(cfg, intrinsics, exact, "belt")


def image_estimator(cfg: SceneConfig, intrinsics: CameraIntrinsics,
                    exact: bool) -> RadiusHypotheses:
    """``image``: the paper's Kalman filter on the image pixel, carried through camera moves."""
    return kalman_estimator(cfg, intrinsics, exact, "image")

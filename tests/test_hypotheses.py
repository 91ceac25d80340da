"""Which radius hypothesis acts: the kind read from the face's colour, else the parallax's
NIS (scripted hypotheses, no rendering)."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.hypotheses import RadiusHypotheses, kalman_estimator
from stackpick_sim.episodes.sensing import Candidate, Observation
from stackpick_sim.geometry import CameraIntrinsics

K = CameraIntrinsics(fx=290.0, fy=290.0, cx=160.0, cy=120.0, width=320, height=240)
SMALL, LARGE = 0.025, 0.035
FRAME_DT = 1.0 / 30.0


def _posed(radius: float) -> Candidate:
    """A posed top face whose kind the detector read as ``radius`` m."""
    return Candidate(pixel=np.array([160.0, 120.0]), normal_cam=np.array([0.0, 0.0, 1.0]),
                     centre_cam=np.array([0.0, 0.0, 0.25]), radius=radius, is_top=True,
                     ellipse=None)


class _Scripted:
    """Stands in for a TargetEstimator of one radius: each offer fuses the given candidate
    (adding ``nis_step`` to its NIS) or misses the face, as told."""

    def __init__(self, radius: float, nis_step: float) -> None:
        self.radius, self.nis_step, self.nis = radius, nis_step, 0.0
        self.initialised, self.lost, self.missed_last = True, False, False
        self.last_fused_time: float | None = 0.0
        self.last_candidate: Candidate | None = None
        self.fuses: Candidate | None = None
        self.tracker = type("T", (), {"config": type("C", (), {"gate_chi2": 13.8})()})()

    def offer(self, obs: Observation) -> bool:
        self.missed_last = self.fuses is None
        if self.fuses is None:
            return False
        self.nis += self.nis_step
        self.last_fused_time, self.last_candidate = obs.capture_time, self.fuses
        return True


def _obs(t: float) -> Observation:
    return Observation(capture_time=t, available_time=t, world_T_cam=np.eye(4),
                       candidates=(), detection=None, image=None)


def _hypotheses(by_colour: bool, overrides: tuple[str, ...] = ()
                ) -> tuple[RadiusHypotheses, _Scripted, _Scripted]:
    """The small lid's hypothesis pays more NIS per frame than the large one (the approach's
    fits take in the lid's side wall: too large for its radius); both fuse the lid, whose
    colour the detector reads as the small kind."""
    hyps = RadiusHypotheses(load_scene("realistic", overrides), K, oracle=False,
                            radii=(LARGE, SMALL), by_colour=by_colour)
    large, small = _Scripted(LARGE, 1.0), _Scripted(SMALL, 6.0)
    hyps.hypotheses = [large, small]  # type: ignore[list-item]
    hyps.active = small  # type: ignore[assignment]
    hyps.readings = {SMALL: 1}  # the first detection's reading
    for h in (large, small):
        h.fuses = _posed(SMALL)
    return hyps, large, small


def test_the_kind_read_from_the_colour_acts_while_it_follows_the_face() -> None:
    hyps, large, small = _hypotheses(by_colour=True)
    for i in range(1, 20):
        hyps.offer(_obs(i * FRAME_DT))
        assert hyps.radius == SMALL, f"left the colour's kind at frame {i}"
    assert hyps.readings == {SMALL: 20}
    assert large.nis + 50.0 < small.nis  # the parallax alone would have switched


@pytest.mark.parametrize("follow", [0.2, 0.5])
def test_the_parallax_decides_once_the_colour_kind_lost_the_face(follow: float) -> None:
    hyps, _, small = _hypotheses(by_colour=True,
                                 overrides=(f"episode.kind_follow_time={follow}",))
    for i in range(1, 4):
        hyps.offer(_obs(i * FRAME_DT))
    small.fuses = None  # its prediction drifted off the face: it no longer associates
    last = t = 3 * FRAME_DT
    while t + FRAME_DT - last <= follow:
        t += FRAME_DT
        hyps.offer(_obs(t))
        assert hyps.radius == SMALL  # a few missed frames are not a lost face
    hyps.offer(_obs(t + FRAME_DT))
    assert hyps.radius == LARGE


def test_without_colour_kinds_the_parallax_decides() -> None:
    hyps, _, _ = _hypotheses(by_colour=False)
    switched = None
    for i in range(1, 10):
        hyps.offer(_obs(i * FRAME_DT))
        if hyps.radius == LARGE and switched is None:
            switched = i
    assert switched is not None and switched <= 2
    assert hyps.readings == {SMALL: 1}  # readings are not counted


def test_the_most_read_kind_acts_and_the_active_breaks_ties() -> None:
    hyps, large, small = _hypotheses(by_colour=True)
    large.fuses = small.fuses = _posed(LARGE)  # the colour now reads the large kind
    hyps.offer(_obs(FRAME_DT))  # one reading each: the active (small) keeps the face
    assert hyps.readings == {SMALL: 1, LARGE: 1} and hyps.radius == SMALL
    small.nis_step = 0.0  # the small one is now the NIS' favourite too
    hyps.active = large  # type: ignore[assignment]
    hyps.offer(_obs(2 * FRAME_DT))  # read by the active (large): two readings to one
    assert hyps.radius == LARGE


def test_the_built_in_estimator_reads_colours_only_where_kinds_differ_in_colour() -> None:
    real = load_scene("realistic", ())
    assert kalman_estimator(real, K, False, "belt").by_colour
    assert not kalman_estimator(real, K, True, "belt").by_colour  # exact: one radius
    same = load_scene("realistic", [f"object_types.{n}.rgba=[0.5, 0.5, 0.5, 1.0]"
                                    for n in real.objects.types])
    assert not kalman_estimator(same, K, False, "belt").by_colour
    plugin = load_scene("realistic", ["episode.detector='tests.test_hypotheses:_posed'"])
    assert not kalman_estimator(plugin, K, False, "belt").by_colour

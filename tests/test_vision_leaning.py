"""The top stage's check of a face that passed the rule against the faces leaning on it whose
outline falls short of the rule's support (``vision.lean``): nothing may rest on a top object.
Pinned rendered cluttered and grey frames, and the faces it weighs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from dev_frames import GREY, GREY_DATA, dev_frame, top_iou

from stackpick_sim.config.loader import load_scene
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.leaning import leaning_faces
from stackpick_sim.vision.occlusion import OcclusionEvidence
from stackpick_sim.vision.params import LeanParams, TopParams


def _top_iou(frame: BenchFrame, enabled: bool) -> float:
    return top_iou(frame, replace(detector_config(frame), lean=LeanParams(enabled=enabled)))


def test_a_face_leaning_on_the_chosen_whole_face_takes_the_choice() -> None:
    # Cluttered frame 111448: a steep blue top object leans its wall on a lower blue
    # object's whole face; its own outline shows along 0.73 of its length (its boundary with
    # the blue faces beneath is faint), no T-junction, nothing inside. The lower face passes
    # the rule outright and is taken unless the lean is found.
    frame = dev_frame(111448)
    assert _top_iou(frame, enabled=False) < MATCH_IOU
    assert _top_iou(frame, enabled=True) > 0.9


def test_the_lean_is_found_over_every_kind_when_colour_tells_no_radius() -> None:
    # Grey frame 112237 (both kinds one grey): the top face, short of the rule's support
    # along its boundary with a grey neighbour, leans on the whole face the rule takes; the
    # rest test runs over the kinds' radii that the faces' sizes admit.
    frame = dev_frame(112237, GREY_DATA, "paper", GREY)
    assert _top_iou(frame, enabled=False) < MATCH_IOU
    assert _top_iou(frame, enabled=True) > MATCH_IOU


def _evidence(support: float, ends: int = 0, inside: int = 0) -> OcclusionEvidence:
    return OcclusionEvidence(support=support, longest_gap_px=0, occluded_ends=ends,
                             interior_edge_px=inside, perimeter_px=200, params=TopParams())


def test_only_short_outlined_faces_with_nothing_crossing_them_are_weighed() -> None:
    chosen = Ellipse(cx=100.0, cy=100.0, a=30.0, b=20.0, angle_deg=0.0)
    apart = [Ellipse(cx=100.0 + 80.0 * k, cy=200.0, a=25.0, b=15.0, angle_deg=0.0)
             for k in range(1, 6)]
    faces = [chosen, *apart]
    evidence = [_evidence(1.0),
                _evidence(0.7),            # short of the support: weighed
                _evidence(0.5),            # below lean.min_support
                _evidence(0.7, ends=1),    # cut at a T-junction: under another face
                _evidence(0.95),           # passes the rule: the rule weighs it
                _evidence(0.8)]            # unobstructed: the rule's rest test weighs it
    no_edges = np.zeros((0, 2), np.float64)
    assert leaning_faces(faces, evidence, 0, no_edges, LeanParams()) == [1]
    # A looser fit of a face fitted better (one holds the other's centre) is not weighed,
    # nor a second fit of the chosen face.
    looser = replace(apart[3], a=24.0)
    second = replace(chosen, a=31.0)
    faces = [chosen, apart[0], looser, apart[3], second]
    evidence = [_evidence(1.0), _evidence(0.7), _evidence(0.65), _evidence(0.95),
                _evidence(0.7)]
    assert leaning_faces(faces, evidence, 0, no_edges, LeanParams()) == [1]


@pytest.mark.parametrize("value", ["-0.1", "1.5"])
def test_the_least_support_is_held_to_its_range(value: str) -> None:
    with pytest.raises(ConfigError, match=r"vision\.lean\.min_support"):
        load_scene("cluttered", [f"vision.lean.min_support={value}"])

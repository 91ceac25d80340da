"""The contact test of reconstructed cylinders: which whole face's object rests on which."""

from __future__ import annotations

import numpy as np

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.occlusion import select_top
from stackpick_sim.vision.pose import unit_circle_poses
from stackpick_sim.vision.resting import (
    DEFAULT_TOP,
    UP_CAM,
    contact,
    rests_on,
    wall_evidences_of,
)
from stackpick_sim.vision.synthetic import render_cylinders
from stackpick_sim.vision.wall import face_colour, wall_evidences

CONTACT_GAP_M, MIN_REST_UP = DEFAULT_TOP.rest_contact_gap_m, DEFAULT_TOP.rest_min_up

K = CameraIntrinsics.from_fovy(45.0, 320, 240)
ORANGE, BLUE = (217, 153, 64), (77, 153, 217)  # the paper scene's large and small kinds
#: Paper scene seed 487 at the look pose (ground truth, camera frame): a small cylinder
#: (BLUE) tilted 42 deg leans its far rim on the side wall of a large one (ORANGE) tilted
#: 35 deg; both faces show whole, 2 mm apart in depth, and the small one is the top.
LARGE = (np.array([-0.0443, -0.0398, 0.2314]), np.array([0.5708, -0.04, 0.8201]), 0.035, 0.03)
SMALL = (np.array([0.0339, -0.041, 0.2294]), np.array([-0.6555, 0.1038, 0.748]), 0.025, 0.025)


def _unit(v: list[float]) -> np.ndarray:
    a = np.asarray(v, np.float64)
    return a / np.linalg.norm(a)


def _contact(a: tuple, b: tuple) -> tuple[float, float]:
    """Separation (m) and upward component of the contact normal from b to a."""
    bodies = [a, b]
    sep, normal = contact(np.array([o[0] for o in bodies]), np.array([o[1] for o in bodies]),
                          np.array([o[2] for o in bodies]), np.array([o[3] for o in bodies]),
                          np.array([[0, 1]]))
    return float(sep[0]), float(normal[0] @ UP_CAM)


def test_contact_of_stacked_side_by_side_and_apart_cylinders() -> None:
    down = np.array([0.0, 0.0, 1.0])  # upright: the inward normal points away from the camera
    lower = (np.array([0.0, 0.0, 0.27]), down, 0.035, 0.03)
    on_top = (np.array([0.01, 0.0, 0.245]), down, 0.025, 0.025)  # its bottom on lower's face
    beside = (np.array([0.06, 0.0, 0.275]), down, 0.025, 0.025)  # walls touch
    apart = (np.array([0.08, 0.0, 0.275]), down, 0.025, 0.025)
    # Touching: the separation is 0 up to the direction grid's error (~1.5 mm).
    sep, up = _contact(on_top, lower)
    assert abs(sep) < 2e-3 and up > 0.99
    sep, up = _contact(lower, on_top)  # the normal flips with the order
    assert abs(sep) < 2e-3 and up < -0.99
    sep, up = _contact(beside, lower)
    assert abs(sep) < 2e-3 and abs(up) < MIN_REST_UP
    sep, _ = _contact(apart, lower)
    assert sep > CONTACT_GAP_M


def test_contact_of_a_lean_on_a_side_wall_points_up_into_the_leaning_body() -> None:
    sep, up = _contact(SMALL, LARGE)
    assert abs(sep) < CONTACT_GAP_M and up >= MIN_REST_UP


def _lean_frame() -> tuple[np.ndarray, Ellipse, Ellipse]:
    """Seed 487's two cylinders rendered (the leaning one drawn last), with their faces."""
    rng = np.random.default_rng(487)
    render = render_cylinders([LARGE, SMALL], [ORANGE, BLUE], K)
    image = np.clip(np.round(render + rng.normal(0.0, 1.0, render.shape)), 0, 255)
    faces = [project_circle(o[0], o[1], o[2], K) for o in (LARGE, SMALL)]
    return image.astype(np.uint8), faces[0], faces[1]


def _radius_of(e: Ellipse) -> float:
    return 0.035 if e.cx < 160 else 0.025  # the large face lies left


#: The paper scene's kinds: cylinder height (m) of each radius (m).
HEIGHTS = {0.035: 0.03, 0.025: 0.025}
_height_of = HEIGHTS.get


def test_face_leaned_on_below_its_rim_is_not_top() -> None:
    image, large, small = _lean_frame()
    assert rests_on([large, small], K, _radius_of, _height_of, image) == [True, False]
    assert rests_on([small, large], K, _radius_of, _height_of, image) == [False, True]
    grad = edge_image(image)
    # Without the image or the heights both faces pass, 2 mm apart in depth: the larger won.
    assert select_top([large, small], grad, K, _radius_of).index == 0
    assert select_top([large, small], grad, K, _radius_of, image=image).index == 0
    for order in ([large, small], [small, large]):
        choice = select_top(order, grad, K, _radius_of, image=image, height_of=_height_of)
        assert choice.index is not None and order[choice.index] is small, choice.evidence


def test_unknown_radius_or_height_gives_no_evidence() -> None:
    image, large, small = _lean_frame()
    assert rests_on([large, small], K, lambda e: None, _height_of, image) == [False, False]
    assert rests_on([large, small], K, lambda e: 0.03, _height_of, image) == [False, False]
    assert rests_on([large, small], K, _radius_of, lambda r: None, image) == [False, False]


def test_face_seen_square_on_takes_the_smaller_tilt_and_can_be_leaned_on() -> None:
    # Paper scene seed 544 at the look pose: a flat small cylinder (no wall shows) and a small
    # one tilted 32 deg leaning on its rim; the tilted one is the top.
    flat = (np.array([0.0386, -0.0112, 0.2454]), _unit([0.0, 0.001, 1.0]), 0.025, 0.025)
    tilted = (np.array([0.0119, 0.0405, 0.2369]), _unit([0.257, -0.463, 0.848]), 0.025, 0.025)
    rng = np.random.default_rng(544)
    render = render_cylinders([flat, tilted], [BLUE, BLUE], K)
    image = np.clip(np.round(render + rng.normal(0.0, 1.0, render.shape)), 0, 255)
    image = image.astype(np.uint8)
    faces = [project_circle(o[0], o[1], o[2], K) for o in (flat, tilted)]
    assert rests_on(faces, K, lambda e: 0.025, _height_of, image) == [True, False]
    choice = select_top(faces, edge_image(image), K, lambda e: 0.025, image=image,
                        height_of=_height_of)
    assert choice.index == 1, choice.evidence


def test_wall_evidences_of_all_faces_are_each_faces_wall_evidences() -> None:
    image, large, small = _lean_frame()
    apart = Ellipse(cx=60.0, cy=200.0, a=20.0, b=14.0, angle_deg=30.0)  # on the belt
    faces = [large, small, apart]
    together = wall_evidences_of(faces, K, image)
    for face, got in zip(faces, together, strict=True):
        unit = unit_circle_poses(face, K)
        assert got == wall_evidences([(s.normal_cam, s.centre_cam) for s in unit], face, K,
                                     image, face_colour(face, image))
    # The colours the caller keeps give the same evidence.
    assert wall_evidences_of(faces, K, image, lambda e: face_colour(e, image)) == together


def test_faces_apart_whichever_their_solutions_are_not_tested_further() -> None:
    image, large, small = _lean_frame()
    far = Ellipse(cx=290.0, cy=210.0, a=18.0, b=15.0, angle_deg=0.0)  # a corner of the frame
    asked: list[Ellipse] = []

    def colour_of(e: Ellipse) -> np.ndarray:
        asked.append(e)
        return face_colour(e, image)

    # The lean is still found with a third face far from both; only the touching pair's
    # faces have their wall bands read.
    assert rests_on([large, small, far], K, _radius_of, _height_of, image,
                    colour_of=colour_of) == [True, False, False]
    assert far not in asked
    asked.clear()
    assert rests_on([large, far], K, _radius_of, _height_of, image,
                    colour_of=colour_of) == [False, False]
    assert not asked

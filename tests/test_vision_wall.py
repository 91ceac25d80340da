"""Tests of the wall colour evidence, the pose solutions, the region of interest and the
sub-pixel refit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, normal_from_tilt, project_circle
from stackpick_sim.vision.detector import DetectorConfig, detect
from stackpick_sim.vision.edges import edge_image, unblurred_gradients
from stackpick_sim.vision.pose import choose_by_band, circle_poses, unit_circle_poses
from stackpick_sim.vision.refine import edge_points, refine_on_profile, refine_subpixel, subpixel
from stackpick_sim.vision.roi import find_roi
from stackpick_sim.vision.synthetic import draw_ellipses, render_cylinders
from stackpick_sim.vision.wall import (
    FACE_SAMPLE_SCALE,
    FACE_SAMPLES,
    WallEvidence,
    face_colour,
    wall_evidence,
    wall_evidences,
)

K = CameraIntrinsics.from_fovy(45.0, 320, 240)


def _cylinder(tilt: tuple[float, float], colour: tuple[int, int, int] = (60, 100, 220)
              ) -> tuple[np.ndarray, Ellipse, np.ndarray]:
    normal = normal_from_tilt(*tilt)
    centre = np.array([0.01, 0.008, 0.25])
    render = render_cylinders([(centre, normal, 0.035, 0.03)], [colour], K)
    image = np.clip(np.round(render), 0, 255).astype(np.uint8)
    return image, project_circle(centre, normal, 0.035, K), normal


@pytest.mark.parametrize("tilt", [(30.0, 0.0), (-20.0, 15.0), (0.0, -35.0)])
def test_true_solution_band_shows_the_wall_colour(tilt: tuple[float, float]) -> None:
    image, ellipse, normal = _cylinder(tilt)
    sols = circle_poses(ellipse, K, 1.0)
    true_i = int(np.argmax([float(s.normal_cam @ normal) for s in sols]))
    ev = [wall_evidence(s.normal_cam, s.centre_cam, ellipse, K, image) for s in sols]
    assert ev[true_i].samples > 20 and ev[true_i].share > 0.8
    assert ev[1 - true_i].share < 0.2
    assert choose_by_band(ev) == true_i
    # The batched form gives the same evidence.
    both = wall_evidences([(s.normal_cam, s.centre_cam) for s in sols], ellipse, K, image,
                          face_colour(ellipse, image))
    assert both == ev


@pytest.mark.parametrize("tilt", [(30.0, 0.0), (-20.0, 15.0), (15.0, 10.0)])
def test_grey_object_wall_told_from_the_belt_by_the_belts_colour(tilt: tuple[float, float]
                                                                 ) -> None:
    # A grey object has the belt's hue: both bands pass the hue test and tie. The belt's
    # colour, read off the frame's border, rejects the wrong band's belt samples, and the
    # detector's pose takes the true solution.
    image, ellipse, normal = _cylinder(tilt, colour=(220, 220, 220))
    sols = circle_poses(ellipse, K, 1.0)
    true_i = int(np.argmax([float(s.normal_cam @ normal) for s in sols]))
    hue_only = [wall_evidence(s.normal_cam, s.centre_cam, ellipse, K, image) for s in sols]
    assert choose_by_band(hue_only) is None
    belt = find_roi(image).belt
    assert belt is not None
    with_belt = [wall_evidence(s.normal_cam, s.centre_cam, ellipse, K, image,
                               belt=np.array(belt)) for s in sols]
    assert with_belt[true_i].share > 0.8 and with_belt[1 - true_i].share < 0.2
    assert choose_by_band(with_belt) == true_i
    assert wall_evidences([(s.normal_cam, s.centre_cam) for s in sols], ellipse, K, image,
                          face_colour(ellipse, image), np.array(belt)) == with_belt
    det = detect(image, DetectorConfig(intrinsics=K, radii_m=(0.035,)))
    assert det.pose is not None
    assert abs(det.pose.theta_x_deg - tilt[0]) < 1.0 and abs(det.pose.theta_y_deg - tilt[1]) < 1.0


def test_band_rule_tie_and_lone_band() -> None:
    none = WallEvidence(samples=0, share=0.0)
    assert choose_by_band([none, none]) is None
    assert choose_by_band([WallEvidence(samples=40, share=0.9),
                           WallEvidence(samples=40, share=0.8)]) is None
    # A lone visible band that is not the face's colour speaks for the other solution.
    assert choose_by_band([WallEvidence(samples=30, share=0.0), none]) == 1
    assert choose_by_band([none, WallEvidence(samples=30, share=0.9)]) == 1


def test_roi_holds_the_object_and_empty_belt_keeps_the_frame() -> None:
    rng = np.random.default_rng(2)
    belt = np.clip(rng.normal(35, 2, (240, 320, 3)), 0, 255).astype(np.uint8)
    whole = find_roi(belt)
    assert (whole.u0, whole.v0, whole.u1, whole.v1) == (0, 0, 320, 240)
    disc = Ellipse(cx=220, cy=70, a=30, b=22, angle_deg=20)
    image = draw_ellipses((240, 320), [disc], noise_sigma=2.0, rng=rng)
    roi = find_roi(image)
    u0, v0, u1, v1 = disc.bounds()
    assert roi.u0 <= u0 - 2 and roi.v0 <= v0 - 2 and roi.u1 >= u1 + 2 and roi.v1 >= v1 + 2
    assert (roi.u1 - roi.u0) * (roi.v1 - roi.v0) < 0.3 * 320 * 240
    assert roi.belt is not None and np.allclose(roi.belt, 40.0, atol=1.0)


def test_roi_reads_the_belt_past_bright_strips_beyond_its_sides() -> None:
    # A camera high enough to see past the belt's sides: bright strips along the frame's top
    # and bottom take most of its border. The belt is still read as the frame's largest
    # surface: the belt's colour is the belt's (the strips, not belt, stay in the box).
    rng = np.random.default_rng(3)
    disc = Ellipse(cx=150, cy=120, a=28, b=25, angle_deg=0)
    image = draw_ellipses((240, 320), [disc], noise_sigma=2.0, rng=rng)
    colour = np.stack([image] * 3, axis=2)
    colour[:12] = colour[-12:] = 100
    roi = find_roi(colour)
    assert roi.belt is not None and np.allclose(roi.belt, 40.0, atol=1.0)


def test_detection_in_roi_is_reported_in_frame_pixels() -> None:
    image, ellipse, _ = _cylinder((0.0, 0.0))
    det = detect(image, DetectorConfig(intrinsics=K, radii_m=(0.035,)))
    assert det and det.top_ellipse is not None
    assert math.hypot(det.top_ellipse.cx - ellipse.cx, det.top_ellipse.cy - ellipse.cy) < 0.5
    for chain in det.segments:
        assert chain[:, 0].min() >= 0 and chain[:, 0].max() < 320


def test_subpixel_moves_edge_pixels_onto_a_straight_step() -> None:
    # A vertical step at u = 100.3 (area-sampled): edge pixels at u = 100 move right ~0.3 px.
    img = np.full((40, 200), 40.0)
    img[:, 101:] = 200.0
    img[:, 100] = 40.0 + 160.0 * 0.2
    grad = edge_image(np.round(img).astype(np.uint8))
    pts = np.stack([np.full(20, 100.0), np.arange(10.0, 30.0)], axis=1)
    moved = subpixel(grad, pts, np.tile([1.0, 0.0], (20, 1)))
    assert np.all(np.abs(moved[:, 0] - 100.3) < 0.15)
    assert np.allclose(moved[:, 1], pts[:, 1])


def test_subpixel_refit_recovers_a_drawn_ellipse() -> None:
    truth = Ellipse(cx=160.3, cy=118.7, a=35.2, b=30.6, angle_deg=25.0)
    image = draw_ellipses((240, 320), [truth], noise_sigma=1.0, rng=np.random.default_rng(4))
    grad = edge_image(image)
    pts, dirs = edge_points(grad)
    start = Ellipse(cx=160.0, cy=119.0, a=35.0, b=31.0, angle_deg=25.0)
    fit = refine_subpixel(start, grad, pts, dirs, (240, 320))
    assert abs(fit.cx - truth.cx) < 0.1 and abs(fit.cy - truth.cy) < 0.1
    assert abs(fit.a - truth.a) < 0.15 and abs(fit.b - truth.b) < 0.15


def test_profile_refit_recovers_a_drawn_ellipse_on_unblurred_gradients() -> None:
    truth = Ellipse(cx=140.3, cy=120.4, a=32.0, b=27.2, angle_deg=35.0)
    image = draw_ellipses((240, 320), [truth], noise_sigma=1.0, rng=np.random.default_rng(6))
    raw = unblurred_gradients(image, edge_image(image))
    assert raw.gx.shape == image.shape and raw.noise > 0
    start = Ellipse(cx=140.8, cy=120.0, a=31.6, b=27.6, angle_deg=33.0)
    fit = refine_on_profile(start, raw, (240, 320))
    assert abs(fit.cx - truth.cx) < 0.1 and abs(fit.cy - truth.cy) < 0.1
    assert abs(fit.a - truth.a) < 0.15 and abs(fit.b - truth.b) < 0.15
    assert abs(fit.angle_deg - truth.angle_deg) < 0.5
    # On a blank image there is no outline to fit: the start comes back unchanged.
    blank = np.full((240, 320), 40, np.uint8)
    assert refine_on_profile(start, unblurred_gradients(blank, edge_image(blank)),
                             (240, 320)) == start


def test_wall_band_brighter_than_a_wall_can_be_is_not_wall() -> None:
    # The same tilted cylinder, its wall repainted as bright as its face (as a same-coloured
    # lower face looks): at a 20 deg tilt a wall reaches at most ~tan(20 deg) of the face.
    image, ellipse, normal = _cylinder((20.0, 0.0))
    sols = circle_poses(ellipse, K, 1.0)
    true_i = int(np.argmax([float(s.normal_cam @ normal) for s in sols]))
    sol = sols[true_i]
    assert wall_evidence(sol.normal_cam, sol.centre_cam, ellipse, K, image).share > 0.8
    face = ellipse.mask(image.shape[:2])
    lit = image.copy()
    colour = np.median(image[face], axis=0)
    lit[(image.sum(axis=2) > 30) & ~face] = colour.astype(np.uint8)
    assert wall_evidence(sol.normal_cam, sol.centre_cam, ellipse, K, lit).share < 0.2


def test_wall_evidences_match_one_at_a_time_off_the_image_edge() -> None:
    # The same cylinder's face moved so that its bands run off the image: the one-pass form
    # drops the same off-image samples as wall_evidence.
    image, ellipse, _ = _cylinder((25.0, 10.0))
    for du, dv in ((0.0, 0.0), (-150.0, 0.0), (140.0, -100.0), (0.0, 105.0)):
        moved = Ellipse.of(ellipse.cx + du, ellipse.cy + dv, ellipse.a, ellipse.b,
                           ellipse.angle_deg)
        sols = unit_circle_poses(moved, K)
        face = face_colour(ellipse, image)
        one = [wall_evidence(s.normal_cam, s.centre_cam, moved, K, image, face) for s in sols]
        assert wall_evidences([(s.normal_cam, s.centre_cam) for s in sols], moved, K, image,
                              face) == one


def test_face_colour_is_the_median_of_the_interior_samples() -> None:
    rng = np.random.default_rng(5)
    image = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    # One well inside, one whose samples run off the top-left corner (clamped to it).
    for ellipse in (Ellipse.of(40.3, 29.6, 20.0, 12.0, 30.0),
                    Ellipse.of(2.0, 1.0, 30.0, 20.0, 0.0)):
        t = np.linspace(0.0, 2.0 * np.pi, FACE_SAMPLES, endpoint=False)
        th = math.radians(ellipse.angle_deg)
        x = FACE_SAMPLE_SCALE * ellipse.a * np.cos(t)
        y = FACE_SAMPLE_SCALE * ellipse.b * np.sin(t)
        u = np.clip(np.rint(ellipse.cx + math.cos(th) * x - math.sin(th) * y), 0, 79)
        v = np.clip(np.rint(ellipse.cy + math.sin(th) * x + math.cos(th) * y), 0, 59)
        expected = np.median(image[v.astype(int), u.astype(int)].astype(float), axis=0)
        np.testing.assert_array_equal(face_colour(ellipse, image), expected)


def test_each_unit_circle_pose_images_as_the_ellipse() -> None:
    _, ellipse, _ = _cylinder((30.0, -15.0))
    for sol in unit_circle_poses(ellipse, K):
        back = project_circle(sol.centre_cam, sol.normal_cam, 1.0, K)
        assert abs(back.cx - ellipse.cx) < 1e-6 and abs(back.cy - ellipse.cy) < 1e-6
        assert abs(back.a - ellipse.a) < 1e-6 and abs(back.b - ellipse.b) < 1e-6
        assert abs((back.angle_deg - ellipse.angle_deg + 90.0) % 180.0 - 90.0) < 1e-6


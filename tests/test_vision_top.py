"""Tests of the top-object rule, the pose and the detector on synthetic stacks."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from stackpick_sim.exceptions import ConfigError, ImageError
from stackpick_sim.geometry import (
    CameraIntrinsics,
    Ellipse,
    mask_iou,
    normal_from_tilt,
    project_circle,
    tilt_angles,
)
from stackpick_sim.vision import __all__ as vision_all
from stackpick_sim.vision import detector as detector_module
from stackpick_sim.vision.detector import DetectorConfig, detect, object_kinds
from stackpick_sim.vision.edges import detect_edges, edge_image
from stackpick_sim.vision.occlusion import select_rimmed, select_top, select_unobstructed
from stackpick_sim.vision.params import GateParams
from stackpick_sim.vision.pose import choose_radius, circle_poses
from stackpick_sim.vision.refine import edge_points
from stackpick_sim.vision.synthetic import (
    SyntheticConfig,
    draw_ellipses,
    generate_stack,
    render_cylinders,
)

SHAPE = (240, 320)
K = CameraIntrinsics.from_fovy(45.0, 320, 240)


def test_vision_all_names_exist() -> None:
    import stackpick_sim.vision as vision

    for name in vision_all:
        assert hasattr(vision, name), name


@pytest.mark.parametrize("upper_first", [False, True])
def test_t_junction_decides_which_disc_is_on_top(upper_first: bool) -> None:
    left = Ellipse(cx=130, cy=120, a=40, b=30, angle_deg=10)
    right = Ellipse(cx=180, cy=125, a=38, b=30, angle_deg=100)
    order = [left, right] if not upper_first else [right, left]
    image = draw_ellipses(SHAPE, order, noise_sigma=2.0, rng=np.random.default_rng(3))
    choice = select_top(order, detect_edges(image))
    assert choice.index == 1, choice.evidence
    under = choice.evidence[0]
    assert under.occluded and under.occluded_ends >= 1


def test_isolated_disc_is_top_candidate_and_rule_takes_foreign_ellipses() -> None:
    disc = Ellipse(cx=160, cy=120, a=30, b=22, angle_deg=45)
    image = draw_ellipses(SHAPE, [disc])
    wrong = Ellipse(cx=100, cy=60, a=20, b=15, angle_deg=0)  # e.g. a peer's false positive
    choice = select_top([wrong, disc], detect_edges(image))
    assert choice.index == 1
    assert choice.evidence[0].support < 0.2


def _two_discs(lower: Ellipse, lower_level: float, upper: Ellipse, upper_level: float,
               seed: int) -> np.ndarray:
    """A grey image: ``upper`` drawn over ``lower`` (grey levels given) on a dark background,
    seeded noise of std 1."""
    rng = np.random.default_rng(seed)
    image = np.full(SHAPE, 35.0)
    image[lower.mask(SHAPE)] = lower_level
    image[upper.mask(SHAPE)] = upper_level
    return np.clip(np.round(image + rng.normal(0.0, 1.0, SHAPE)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_last_resort_takes_a_face_whose_gap_is_an_invisible_boundary(seed: int) -> None:
    # A top disc on a lower one of the very same shade (as in the paper scene's seed 292):
    # the boundary over the lower disc does not show, so no face passes the rule; neither has
    # a T-junction or an edge inside, and the top shows more of its outline.
    lower = Ellipse(cx=140, cy=120, a=30, b=26, angle_deg=20)
    upper = Ellipse(cx=185, cy=125, a=42, b=37, angle_deg=110)
    image = _two_discs(lower, 150.0, upper, 150.0, seed)
    choice = select_top([lower, upper], detect_edges(image))
    assert choice.index is None
    assert select_unobstructed(choice.evidence) == 1


def test_last_resort_never_takes_a_face_with_a_t_junction() -> None:
    left = Ellipse(cx=130, cy=120, a=40, b=30, angle_deg=10)
    right = Ellipse(cx=180, cy=125, a=38, b=30, angle_deg=100)
    image = draw_ellipses(SHAPE, [left, right], noise_sigma=2.0, rng=np.random.default_rng(3))
    choice = select_top([left], detect_edges(image))  # the top disc was not fitted
    assert choice.index is None and choice.evidence[0].occluded_ends >= 1
    assert select_unobstructed(choice.evidence) is None


def _silhouette_fit(image: np.ndarray) -> Ellipse:
    """The ellipse fitted to the outer silhouette of the bright discs of a grey image."""
    mask = (image > 90).astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    (cx, cy), (w, h), angle = cv2.fitEllipseDirect(max(contours, key=len).astype(np.float32))
    return Ellipse(cx=cx, cy=cy, a=max(w, h) / 2, b=min(w, h) / 2,
                   angle_deg=angle if w >= h else angle + 90.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rim_band_last_resort_takes_a_face_fitted_on_a_lower_sliver(seed: int) -> None:
    # A top disc on a lower disc of its colour, a little darker, whose sliver shows up to
    # ~5 px beyond the top's rim (as in the paper scene's seed 202): the fit on the
    # strong silhouette holds the top's own faint rim inside, so it fails on interior edges.
    upper = Ellipse(cx=165, cy=120, a=48, b=47, angle_deg=0)
    lower = Ellipse(cx=158, cy=120, a=46, b=46, angle_deg=0)
    image = _two_discs(lower, 150.0, upper, 160.0, seed)
    fit = _silhouette_fit(image)
    grad = edge_image(image)
    points, _ = edge_points(grad)
    choice = select_top([fit], grad)
    assert choice.index is None and choice.evidence[0].interior_edge_px > 0
    assert select_rimmed([fit], choice.evidence, points) == 0
    assert mask_iou(fit, upper, SHAPE) > 0.9
    # A smaller disc lying inside the face puts its outline deep inside: no last resort.
    inner = Ellipse(cx=150, cy=125, a=20, b=18, angle_deg=0)
    image[inner.mask(SHAPE)] = 200
    grad = edge_image(image)
    points, _ = edge_points(grad)
    choice = select_top([fit], grad)
    assert choice.index is None
    assert select_rimmed([fit], choice.evidence, points) is None


def test_a_duplicate_fit_of_the_nearest_face_is_no_depth_rival() -> None:
    # Two whole faces; the nearer one (small kind) images smaller than the farther (large
    # kind) and is fitted twice. The duplicate is no rival: the nearer face still wins.
    near = Ellipse(cx=90, cy=120, a=38, b=38, angle_deg=0)
    far = Ellipse(cx=230, cy=120, a=44, b=44, angle_deg=0)
    image = draw_ellipses(SHAPE, [near, far], noise_sigma=1.0, rng=np.random.default_rng(5))
    twin = Ellipse(cx=90.4, cy=119.7, a=38.2, b=37.9, angle_deg=30)

    def radius_of(e: Ellipse) -> float:
        return 0.025 if e.cx < 160 else 0.035

    for order in ([far, near, twin], [twin, far, near]):
        choice = select_top(order, edge_image(image), K, radius_of)
        assert choice.index is not None and order[choice.index] is not far, choice.evidence


def test_unobstructed_face_clearly_nearer_than_a_whole_face_is_top() -> None:
    # The top disc lies on a lower disc of its shade (its arc there does not show: support
    # ~0.85, nothing crossing it) and is nearer than a separate whole face, which passes.
    lower = Ellipse(cx=140, cy=120, a=30, b=26, angle_deg=20)
    upper = Ellipse(cx=185, cy=125, a=42, b=37, angle_deg=110)
    far = Ellipse(cx=275, cy=55, a=32, b=30, angle_deg=0)
    rng = np.random.default_rng(6)
    image = np.full(SHAPE, 35.0)
    for e in (lower, upper, far):
        image[e.mask(SHAPE)] = 150.0
    image = np.clip(np.round(image + rng.normal(0.0, 1.0, SHAPE)), 0, 255).astype(np.uint8)

    def radius_of(e: Ellipse) -> float:
        return 0.035 if e is far else 0.025

    ellipses = [far, lower, upper]
    grad = edge_image(image)
    assert select_top(ellipses, grad).index == 0  # without depths: the only whole face
    choice = select_top(ellipses, grad, K, radius_of)
    assert choice.evidence[2].occluded and choice.index == 2, choice.evidence


def test_rule_on_no_ellipses_is_a_miss() -> None:
    choice = select_top([], np.zeros(SHAPE, np.uint8))
    assert not choice and choice.reason


def test_circle_poses_contain_the_truth() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        normal = normal_from_tilt(*rng.uniform(-45, 45, 2))
        centre = np.array([*rng.uniform(-0.06, 0.06, 2), rng.uniform(0.2, 0.3)])
        ellipse = project_circle(centre, normal, 0.03, K)
        poses = circle_poses(ellipse, K, 0.03)
        err = min(np.linalg.norm(p.normal_cam - normal) + np.linalg.norm(p.centre_cam - centre)
                  for p in poses)
        assert err < 1e-6


def test_radius_chosen_by_depth_range() -> None:
    # A face 0.25 m away with radius 0.035 m implies 0.179 m if its radius were 0.025 m.
    per_metre = 0.25 / 0.035
    assert choose_radius(per_metre, (0.025, 0.035), (0.22, 0.30)) == 0.035
    assert choose_radius(per_metre, (0.035, 0.025), (0.15, 0.19)) == 0.025


def test_wall_resolves_tilt_ambiguity() -> None:
    for tilt in ((25.0, 0.0), (-25.0, 0.0), (0.0, 30.0), (0.0, -30.0)):
        normal = normal_from_tilt(*tilt)
        centre = np.array([0.005, -0.004, 0.25])
        render = render_cylinders([(centre, normal, 0.035, 0.055)], [(220, 60, 50)], K)
        image = np.clip(np.round(render), 0, 255).astype(np.uint8)
        det = detect(image, DetectorConfig(intrinsics=K, radii_m=(0.035,)))
        assert det, det.reason
        assert det.pose is not None
        assert abs(det.pose.theta_x_deg - tilt[0]) < 1.0
        assert abs(det.pose.theta_y_deg - tilt[1]) < 1.0
        assert abs(det.pose.depth_m - 0.25) < 0.005


def test_stack_top_found_and_pose_accurate() -> None:
    successes, trials = 0, 12
    centre_errors = []
    for seed in range(trials):
        scene = generate_stack(np.random.default_rng(1000 + seed),
                               SyntheticConfig(noise_sigma=(2.0, 2.0)))
        det = detect(scene.image, DetectorConfig(intrinsics=scene.intrinsics))
        if not det or det.top_ellipse is None or det.pose is None:
            continue
        ious = [mask_iou(det.top_ellipse, o.ellipse, SHAPE) for o in scene.objects]
        best = int(np.argmax(ious))
        if ious[best] > 0.8 and scene.objects[best].is_top:
            successes += 1
            o = scene.objects[best]
            centre_errors.append(math.hypot(det.pose.x - o.face_center_px[0],
                                            det.pose.y - o.face_center_px[1]))
    assert successes >= 0.75 * trials
    assert float(np.median(centre_errors)) < 0.5


@pytest.mark.parametrize("image", [
    np.zeros((240, 320, 3), np.uint8),
    np.full((240, 320), 255, np.uint8),
    np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8),
    np.zeros((5, 7), np.uint8),
    np.zeros((1200, 1600), np.uint8),
    np.random.default_rng(1).random((100, 120)).astype(np.float32),
    np.zeros((60, 80, 4), np.uint16),
    np.zeros((60, 80, 1), bool),
])
def test_garbage_images_give_a_result(image: np.ndarray) -> None:
    det = detect(image)
    if not det:
        assert det.reason
    assert "total" in det.timings_ms or det.reason


@pytest.mark.parametrize("image", [
    np.zeros((10, 10, 2), np.uint8),
    np.zeros((10,), np.uint8),
    np.zeros((20, 20), np.complex64),
    np.full((20, 20), np.nan, np.float32),
    [[0, 1], [1, 0]],
])
def test_non_images_raise_image_error(image: object) -> None:
    with pytest.raises(ImageError):
        detect(image)  # type: ignore[arg-type]


def test_detection_dict_has_documented_keys() -> None:
    scene = generate_stack(np.random.default_rng(7))
    out = detect(scene.image).as_dict()
    assert set(out) >= {"ellipses", "top", "pose", "timings_ms"}
    for e in out["ellipses"]:
        assert set(e) == {"cx", "cy", "a", "b", "angle_deg", "support"}
    if out["pose"] is not None:
        assert {"x", "y", "theta_x", "theta_y"} <= set(out["pose"])
    assert detector_module.DEFAULT_RADII_M


def test_synthetic_ground_truth_is_consistent() -> None:
    scene = generate_stack(np.random.default_rng(5))
    assert scene.top_indices and scene.objects[-1].is_top
    for o in scene.objects:
        assert tilt_angles(o.normal_cam) == (o.theta_x_deg, o.theta_y_deg)
        assert 0.0 <= o.visible_fraction <= 1.0


def _gapped_outline(ellipse: Ellipse, gap_deg: tuple[int, int]) -> np.ndarray:
    """(H, W) 0/1 edge map of ``ellipse``'s outline without the arc between ``gap_deg``."""
    edges = np.zeros(SHAPE, np.uint8)
    cv2.ellipse(edges, (round(ellipse.cx), round(ellipse.cy)),
                (round(ellipse.a), round(ellipse.b)), ellipse.angle_deg, gap_deg[1],
                gap_deg[0] + 360, 1, 1)
    return edges


@pytest.mark.parametrize("into_face", [False, True])
def test_gap_end_is_a_t_junction_only_when_the_contour_enters_the_face(into_face: bool
                                                                       ) -> None:
    # A gap in a face's outline whose end touches a contour lying wholly outside the face
    # (the object's own wall line, or an outline under it) is no T-junction; a contour
    # running on into the face is (it lies on top).
    face = Ellipse(cx=160, cy=120, a=40, b=30, angle_deg=0)
    edges = _gapped_outline(face, (60, 110))
    end = face.points(360)[60]  # the gap's end at 60 deg (x along the major axis)
    radial = end - np.array([face.cx, face.cy])
    outward = radial / np.linalg.norm(radial)
    if into_face:  # crosses the outline at the gap end
        start, stop = end + 12 * outward, end - 12 * outward
    else:  # runs past the gap end 2.5 px outside, along the outline
        along = np.array([-outward[1], outward[0]])
        start, stop = end + 2.5 * outward - 10 * along, end + 2.5 * outward + 10 * along
    cv2.line(edges, (round(start[0]), round(start[1])), (round(stop[0]), round(stop[1])), 1, 1)
    evidence = select_top([face], edges).evidence[0]
    if into_face:
        assert evidence.occluded_ends >= 1
    else:
        assert evidence.occluded_ends == 0 and evidence.longest_gap_px >= 8


def test_size_gate_drops_ellipses_too_small_for_any_face_in_the_depth_range() -> None:
    # Two separate discs: one of the size a 0.03 m face has at 0.3 m, one far smaller.
    face = Ellipse(cx=200, cy=120, a=K.fy * 0.03 / 0.3, b=25, angle_deg=20)
    small = Ellipse(cx=80, cy=120, a=12, b=9, angle_deg=0)
    image = draw_ellipses(SHAPE, [face, small], noise_sigma=1.0, rng=np.random.default_rng(5))
    free = detect(image, DetectorConfig(intrinsics=K, radii_m=(0.03,)))
    assert any(abs(d.ellipse.a - small.a) < 1.5 for d in free.ellipses)
    gated = detect(image, DetectorConfig(intrinsics=K, radii_m=(0.03,),
                                         depth_range_m=(0.25, 0.35)))
    assert [round(d.ellipse.cx) for d in gated.ellipses] == [200]
    lo, hi = detector_module.TopObjectDetector(
        DetectorConfig(intrinsics=K, radii_m=(0.03,), depth_range_m=(0.25, 0.35)))._axis_range(K)
    assert lo == pytest.approx(GateParams().slack[0] * K.fy * 0.03 / 0.35)
    assert hi == pytest.approx(GateParams().slack[1] * K.fy * 0.03 / 0.25)


def test_one_face_fitted_twice_is_reported_once() -> None:
    face = Ellipse(cx=160, cy=120, a=40, b=30, angle_deg=30)
    near = replace(face, cx=face.cx + 0.8, a=face.a - 0.5)
    other = Ellipse(cx=160, cy=120, a=25, b=18, angle_deg=30)  # concentric, not the same
    assert detector_module._same_outlines([face, near, other], [0, 1, 2]) == {(0, 1), (1, 0)}
    evidence = select_top([face, near, other], np.zeros(SHAPE, np.uint8))
    kept = detector_module._distinct([0, 1, 2], [face, near, other], evidence)
    assert len(kept) == 2 and 2 in kept


def test_kind_colours_must_match_the_radii() -> None:
    with pytest.raises(ConfigError):
        DetectorConfig(radii_m=(0.035, 0.025), kind_colours=((0.8, 0.6, 0.2),))
    with pytest.raises(ConfigError):
        DetectorConfig(radii_m=(0.035,), kind_colours=((1.5, 0.6, 0.2),))
    DetectorConfig(radii_m=(0.035, 0.025), kind_colours=((0.8, 0.6, 0.2), (0.3, 0.6, 0.8)))


def test_heights_must_match_the_radii() -> None:
    with pytest.raises(ConfigError, match="heights_m"):
        DetectorConfig(radii_m=(0.035, 0.025), heights_m=(0.03,))
    with pytest.raises(ConfigError, match="heights_m"):
        DetectorConfig(radii_m=(0.035,), heights_m=(0.0,))
    DetectorConfig(radii_m=(0.035, 0.025), heights_m=(0.03, 0.025))


def test_clearly_nearer_whole_face_wins_when_radii_are_known() -> None:
    big = Ellipse(cx=100, cy=120, a=40, b=38, angle_deg=0)  # radius 0.035 m: ~0.25 m deep
    small = Ellipse(cx=230, cy=120, a=34, b=33, angle_deg=0)  # radius 0.025 m: ~0.21 m deep
    image = draw_ellipses(SHAPE, [big, small], noise_sigma=1.0, rng=np.random.default_rng(2))
    edges = detect_edges(image)
    assert select_top([big, small], edges, K).index == 0  # no radii: the larger ellipse

    def radius_of(e: Ellipse) -> float:
        return 0.035 if e.cx < 160 else 0.025

    assert select_top([big, small], edges, K, radius_of).index == 1

    def same_radius(e: Ellipse) -> float:
        return 0.03  # depths then differ by < top.depth_tie_m: the size rule decides

    assert select_top([big, small], edges, K, same_radius).index == 0


def test_far_rim_of_a_tilted_cylinder_is_not_reported_as_a_face() -> None:
    face = Ellipse(cx=160, cy=120, a=40, b=30, angle_deg=0)  # minor axis vertical
    rim = replace(face, cy=face.cy + 0.5 * face.a)  # shifted along the minor axis
    sideways = replace(face, cx=face.cx + 0.5 * face.a)  # along the major axis: not a rim
    other = Ellipse(cx=160, cy=140, a=25, b=20, angle_deg=0)  # another size: not a rim
    assert detector_module._far_rim(rim, face)
    assert not detector_module._far_rim(sideways, face)
    assert not detector_module._far_rim(other, face)
    assert not detector_module._far_rim(face, face)  # no offset
    ellipses = [face, rim, sideways]
    choice = select_top(ellipses, np.zeros(SHAPE, np.uint8))
    evidence = tuple(replace(ev, support=s) for ev, s in zip(choice.evidence, (1.0, 0.6, 0.7),
                                                             strict=True))
    kept = detector_module._distinct([0, 1, 2], ellipses, replace(choice, evidence=evidence))
    assert kept == [0, 2]
    top_rim = replace(choice, index=1, evidence=evidence)  # the top is never dropped
    assert 1 in detector_module._distinct([0, 1, 2], ellipses, top_rim)


def test_object_kinds_give_colours_only_when_kinds_differ_in_colour() -> None:
    orange, blue = (0.85, 0.6, 0.25), (0.3, 0.6, 0.85)
    assert object_kinds([(0.025, blue, 0.025), (0.035, orange, 0.03)]) == (
        (0.035, 0.025), (orange, blue), (0.03, 0.025))
    # the same kind listed twice is one kind
    assert object_kinds([(0.035, orange, 0.03), (0.035, orange, 0.03)]) == (
        (0.035,), (orange,), (0.03,))
    # two radii in one colour (or in a brighter shade of it): no colour cue
    assert object_kinds([(0.035, orange, 0.03), (0.025, (0.425, 0.3, 0.125), 0.025)])[:2] == (
        (0.035, 0.025), None)
    # one radius in two colours: no colour cue either
    assert object_kinds([(0.035, orange, 0.03), (0.035, blue, 0.03),
                         (0.025, blue, 0.025)])[1] is None
    # one radius in two heights: no heights (the colours still tell the radii)
    assert object_kinds([(0.035, orange, 0.03), (0.035, orange, 0.05),
                         (0.025, blue, 0.025)])[1:] == ((orange, blue), None)
    with pytest.raises(ValueError, match="no object kinds"):
        object_kinds([])


def test_deep_edge_count_on_the_spanned_rows_equals_the_full_count() -> None:
    """deep_edge_counts' row-interval count (edge pixels in np.nonzero order) is the count of
    Ellipse.inside over all the pixels, exactly."""
    from stackpick_sim.vision.occlusion import deep_edge_counts

    rng = np.random.default_rng(3)
    vv, uu = np.nonzero(rng.random((240, 320)) < 0.05)
    points = np.stack([uu, vv], axis=1).astype(np.float64)
    faces = [Ellipse(cx=float(rng.uniform(0, 320)), cy=float(rng.uniform(0, 240)),
                     a=float(a), b=float(a * rng.uniform(0.3, 1.0)),
                     angle_deg=float(rng.uniform(0, 180)))
             for a in rng.uniform(10, 60, 20)]
    for depth in (0.0, 3.5):
        assert deep_edge_counts(faces, points, depth) == [
            int(np.count_nonzero(f.inside(points, depth))) for f in faces]

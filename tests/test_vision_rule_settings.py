"""The top rule's (with its wall cover and marking tests'), the fits', the edge support's and
the tracked outline search's settings: reached from a scene's ``[vision]`` (``[episode]``)
table and ``--set``, checked on load, and acting where they should."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from two_faces import FACES, SHAPE, K, two_face_image

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.vision_params import OutlineTrackingParams
from stackpick_sim.episodes.detectors import scene_detector_config
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse, mask_iou, normal_from_tilt, project_circle
from stackpick_sim.vision.benchmark.frames import BenchFrame, load_frame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.detector import DetectorConfig, TopObjectDetector, detect
from stackpick_sim.vision.markings import off_rim_share, rim_band, two_surfaces
from stackpick_sim.vision.moving_edges import track_outline
from stackpick_sim.vision.occlusion import select_top, select_unobstructed
from stackpick_sim.vision.params import (
    EdgeParams,
    FitParams,
    MarkingParams,
    PoseParams,
    TopParams,
)
from stackpick_sim.vision.pose import circle_poses
from stackpick_sim.vision.synthetic import draw_ellipses
from stackpick_sim.vision.wall import band_points, wall_evidence
from stackpick_sim.vision.wall_cover import covered_share, covered_shares, under_another

#: Pinned paper-scene frames with their ground truth (see test_vision_dev_frames).
DEV_FRAMES = Path(__file__).parent / "data" / "paper_dev_frames"


def _dev_frame(seed: int) -> BenchFrame:
    scene = load_scene("paper")
    kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
                  for t in scene.object_types.values())
    return load_frame(DEV_FRAMES, seed, scene.conveyor.top_z, scene.objects.max_face_height,
                      kinds)


def _top_is_true(frame: BenchFrame, config: DetectorConfig) -> bool:
    """Whether the detector's choice on ``frame`` is a true top face."""
    found = TopObjectDetector(config).detect(frame.image_rgb).top_ellipse
    return found is not None and max(mask_iou(found, f.ellipse, frame.shape)
                                     for f in frame.tops) > MATCH_IOU


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return two_face_image()


def test_rule_settings_reach_the_detector_from_a_scene_file(tmp_path: Path) -> None:
    path = tmp_path / "strict.toml"
    path.write_text("[vision.top]\nmin_support = 0.95\ndepth_tie_m = 0.02\n"
                    "[vision.fits]\nmin_axis_px = 8.0\n"
                    "[vision.edges]\nsupport_noise_multiple = 3.0\n")
    config = scene_detector_config(load_scene(str(path)), K, (0.2, 0.3))
    assert config.top == TopParams(min_support=0.95, depth_tie_m=0.02)
    assert config.fits == FitParams(min_axis_px=8.0)
    assert config.edges == EdgeParams(support_noise_multiple=3.0)


def test_rule_settings_reach_the_detector_from_set() -> None:
    cfg = load_scene("paper", ["vision.top.min_gap_px=12", "vision.top.rim_band_px=4.0",
                               "vision.fits.max_axis_diagonals=0.5",
                               "vision.edges.support_min_contrast=1.0"])
    config = scene_detector_config(cfg, K, (0.2, 0.3))
    assert config.top.min_gap_px == 12 and config.top.rim_band_px == 4.0
    assert config.fits.max_axis_diagonals == 0.5 and config.edges.support_min_contrast == 1.0


@pytest.mark.parametrize(("override", "message"), [
    ("vision.top.min_support=1.2", "vision.top.min_support = 1.2 is out of range; allowed: 0 "
                                   "to 1"),
    ("vision.top.depth_tie_m=-0.01", "vision.top.depth_tie_m = -0.01 is out of range; allowed: "
                                     "0 to 1 m"),
    ("vision.top.min_gap_px=0", "vision.top.min_gap_px = 0 is out of range; allowed: 1 to "
                                "1000 px"),
    ("vision.fits.min_axis_px=0", "vision.fits.min_axis_px = 0.0 is out of range; allowed: 1 "
                                  "to 1000 px"),
    ("vision.edges.support_noise_multiple=200", "vision.edges.support_noise_multiple = 200.0 "
                                                "is out of range; allowed: 0 to 100"),
])
def test_out_of_range_rule_settings_give_one_line_errors(override: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as err:
        load_scene("paper", [override])
    assert "\n" not in str(err.value)


def test_the_least_axis_drops_thinner_faces(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    assert sorted(round(e.ellipse.cx) for e in detect(image, config).ellipses) == [150, 200]
    # Only the top face's semi-minor axis (38 px) reaches 36 px: the lower face (34 px) is
    # fitted nowhere, by no stage.
    thick = detect(image, replace(config, fits=FitParams(min_axis_px=36.0)))
    assert [round(e.ellipse.cx) for e in thick.ellipses] == [150]
    assert thick.top == 0
    assert not detect(image, replace(config, fits=FitParams(min_axis_px=50.0))).ellipses


def test_the_support_threshold_sets_what_counts_as_an_outline(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    assert detect(image, config).top is not None
    # Contrast of 100 times the noise level shows nowhere: no outline is supported.
    blind = detect(image, replace(config, edges=EdgeParams(support_noise_multiple=100.0)))
    assert blind.top is None


def _with_gap(face: Ellipse, share: float) -> np.ndarray:
    """An edge map of ``face``'s outline (one pixel wide) with ``share`` of it missing."""
    edges = np.zeros(SHAPE, np.uint8)
    t = np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)[: int(2000 * (1.0 - share))]
    c, s = np.cos(np.radians(face.angle_deg)), np.sin(np.radians(face.angle_deg))
    x, y = face.a * np.cos(t), face.b * np.sin(t)
    u, v = np.rint(face.cx + c * x - s * y).astype(int), np.rint(face.cy + s * x + c * y)
    edges[v.astype(int), u] = 1
    return edges


def test_the_least_support_decides_whether_a_cut_face_is_top() -> None:
    face = FACES[1]
    edges = _with_gap(face, 0.15)  # a 15% gap with nothing at its ends
    assert select_top([face], edges).index is None  # support ~0.85 < 0.9
    assert select_top([face], edges, params=TopParams(min_support=0.8)).index == 0
    assert select_top([face], _with_gap(face, 0.05)).index == 0  # a 5% gap passes


def test_the_unobstructed_fallback_follows_its_least_support() -> None:
    face = FACES[1]
    edges = _with_gap(face, 0.15)  # nothing crossing it, support ~0.85
    assert select_unobstructed(select_top([face], edges).evidence) == 0
    strict = TopParams(unobstructed_min_support=0.9)
    assert select_unobstructed(select_top([face], edges, params=strict).evidence) is None


def test_the_wall_cover_follows_its_least_share() -> None:
    tilted = project_circle(np.array([0.0, 0.0, 0.28]), normal_from_tilt(35.0, 0.0), 0.035, K)
    sol = circle_poses(tilted, K, 1.0)[0]
    centre = band_points(sol.normal_cam, sol.centre_cam, tilted, K).mean(axis=0)
    # A frontal face over the middle of the tilted face's predicted wall band.
    over = Ellipse(cx=float(centre[0]), cy=float(centre[1]), a=25.0, b=25.0, angle_deg=0.0)
    share = covered_share(tilted, over, K)
    assert under_another([tilted, over], K) == [True, False]
    higher = TopParams(cover_min_share=min(1.0, share + 0.05))
    assert under_another([tilted, over], K, params=higher) == [False, False]


def test_the_two_surface_test_follows_its_brightness_range() -> None:
    # A tilted face (orange) inside the fit round it and its wall, the wall at 0.55 of the
    # face's brightness in the same hue.
    face = Ellipse(cx=160, cy=110, a=36, b=24, angle_deg=0)
    silhouette = Ellipse(cx=160, cy=120, a=37, b=34, angle_deg=0)
    orange = np.array([0.85, 0.6, 0.25])
    image = np.full((*SHAPE, 3), 30.0)
    image[silhouette.mask(SHAPE)] = 255.0 * 0.55 * orange
    image[face.mask(SHAPE)] = 255.0 * orange
    rgb = np.clip(np.round(image), 0, 255).astype(np.uint8)
    assert two_surfaces(silhouette, face, rgb, 2.5)
    wide = MarkingParams(surface_brightness_range=(0.5, 2.0))
    assert not two_surfaces(silhouette, face, rgb, 2.5, wide)


def test_marking_settings_reach_the_detector_and_are_checked() -> None:
    cfg = load_scene("paper", ["vision.markings.crossing_min_support=0.8",
                               "vision.markings.surface_brightness_range=[0.6, 1.5]"])
    config = scene_detector_config(cfg, K, (0.2, 0.3))
    assert config.markings == MarkingParams(crossing_min_support=0.8,
                                            surface_brightness_range=(0.6, 1.5))
    with pytest.raises(ConfigError, match=r"vision\.markings\.surface_brightness_range = "
                                          r"\[1\.5, 0\.6\] must be \[low, high\]") as err:
        load_scene("paper", ["vision.markings.surface_brightness_range=[1.5, 0.6]"])
    assert "\n" not in str(err.value)


def test_outline_tracking_settings_reach_the_search() -> None:
    cfg = load_scene("paper", ["episode.outline.min_step=200", "episode.outline.search_px=4"])
    params = cfg.episode.outline
    assert params == OutlineTrackingParams(min_step=200.0, search_px=4.0)
    face = FACES[1]
    image = draw_ellipses(SHAPE, [face], noise_sigma=1.0, rng=np.random.default_rng(5))
    gray = np.asarray(image, np.float32)
    predicted = replace(face, cx=face.cx + 2.0)
    assert track_outline(gray, predicted) is not None
    # No grey-level step along the normals reaches 200 levels/px: no outline.
    assert track_outline(gray, predicted, params=params) is None
    with pytest.raises(ConfigError, match=r"episode\.outline\.min_inlier_share = 1\.5 is out "
                                          r"of range; allowed: 0 to 1") as err:
        load_scene("paper", ["episode.outline.min_inlier_share=1.5"])
    assert "\n" not in str(err.value)


def _face_over_wall(face: Ellipse, wall: np.ndarray, wall_rgb: tuple[int, int, int],
                    face_rgb: tuple[int, int, int]) -> np.ndarray:
    """A dark frame with the (N, 2) wall pixels painted 3 px wide in ``wall_rgb`` and
    ``face`` over them in ``face_rgb``."""
    image = np.full((*SHAPE, 3), 30, np.uint8)
    for u, v in np.rint(wall).astype(int):
        image[max(0, v - 1):v + 2, max(0, u - 1):u + 2] = wall_rgb
    image[face.mask(SHAPE)] = face_rgb
    return image


def test_the_wall_band_test_follows_its_brightness_margin() -> None:
    # A face tilted 20 deg over a "wall" as bright as the face itself: a wall of a face
    # tilted 20 deg is at most tan(20 deg) + margin = 0.66 as bright, unless the margin
    # allows more.
    face = project_circle(np.array([0.0, 0.0, 0.28]), normal_from_tilt(20.0, 0.0), 0.035, K)
    sol = circle_poses(face, K, 1.0)[0]
    band = band_points(sol.normal_cam, sol.centre_cam, face, K)
    orange = (217, 153, 64)
    image = _face_over_wall(face, band, orange, orange)
    colour = np.array(orange, np.float64)
    strict = wall_evidence(sol.normal_cam, sol.centre_cam, face, K, image, colour)
    loose = wall_evidence(sol.normal_cam, sol.centre_cam, face, K, image, colour,
                          params=PoseParams(band_brightness_margin=2.0))
    assert strict.samples == loose.samples > 0
    assert strict.share < 0.2 < 0.8 < loose.share


def test_kinds_closer_in_colour_than_the_least_distance_give_no_colour_cue() -> None:
    # The small kind in a tan 0.07 from the large kind's orange (chromaticity, L1).
    near = ("object_types.small.rgba=[0.85,0.66,0.33,1.0]",)
    default = scene_detector_config(load_scene("paper", list(near)), K, (0.2, 0.3))
    assert default.kind_colours is None  # within the default 0.1: no radius from colour
    finer = scene_detector_config(
        load_scene("paper", [*near, "vision.top.kind_min_chroma_distance=0.05"]), K, (0.2, 0.3))
    assert finer.kind_colours is not None and len(finer.kind_colours) == 2
    with pytest.raises(ConfigError, match=r"vision\.top\.kind_min_chroma_distance = 3\.0 is "
                                          r"out of range; allowed: 0 to 2") as err:
        load_scene("paper", ["vision.top.kind_min_chroma_distance=3.0"])
    assert "\n" not in str(err.value)


def test_the_rim_band_test_follows_its_sample_scale() -> None:
    # A blue face with a tan ring along its outer 10 % (another surface at the rim).
    face = Ellipse(cx=160, cy=120, a=40, b=38, angle_deg=0)
    inner = Ellipse(cx=160, cy=120, a=36, b=34.2, angle_deg=0)
    image = np.full((*SHAPE, 3), 30, np.uint8)
    image[face.mask(SHAPE)] = (209, 189, 140)
    image[inner.mask(SHAPE)] = (77, 153, 217)
    band = MarkingParams().rim_sample_scale
    assert off_rim_share(face, image) < 0.05  # the band (0.94) lies on the ring alone
    assert rim_band(face).shape == rim_band(face, band).shape
    mixed = MarkingParams(rim_sample_scale=0.9)  # the band along the ring's inner edge
    assert off_rim_share(face, image, mixed) > 0.2
    cfg = load_scene("paper", ["vision.markings.rim_sample_scale=0.9"])
    assert scene_detector_config(cfg, K, (0.2, 0.3)).markings.rim_sample_scale == 0.9


def test_the_rest_check_gate_follows_the_perspective_enlargement() -> None:
    # A top face whose fit took in a same-colour lower face's sliver rests on the whole face
    # the rule chooses: the rest check reaches it only when it reads nearer than that face,
    # through r / a, within the enlargement.
    frame = _dev_frame(1769)
    config = detector_config(frame)
    top = TopParams(hidden_check=False)
    assert _top_is_true(frame, replace(config, top=top))
    strict = replace(top, perspective_enlargement=0.8)
    assert not _top_is_true(frame, replace(config, top=strict))


def test_the_wall_band_follows_its_depths_and_margin() -> None:
    face = project_circle(np.array([0.0, 0.0, 0.28]), normal_from_tilt(30.0, 0.0), 0.035, K)
    sol = circle_poses(face, K, 1.0)[0]
    # A wall drawn from the face's rim to 0.7 radii deep, at a wall's brightness.
    deep = band_points(sol.normal_cam, sol.centre_cam, face, K,
                       tuple(np.linspace(0.05, 0.7, 14)), 0.0)
    image = _face_over_wall(face, deep, (109, 77, 32), (217, 153, 64))
    colour = np.array([217.0, 153.0, 64.0])
    on = wall_evidence(sol.normal_cam, sol.centre_cam, face, K, image, colour)
    assert on.samples > 0 and on.share > 0.8
    beyond = wall_evidence(sol.normal_cam, sol.centre_cam, face, K, image, colour,
                           params=PoseParams(wall_depths=(1.2, 1.5)))
    assert beyond.share < 0.2  # sampled past the drawn wall: belt
    wide = wall_evidence(sol.normal_cam, sol.centre_cam, face, K, image, colour,
                         params=PoseParams(wall_margin_px=6.0))
    assert wide.samples < on.samples
    with pytest.raises(ConfigError, match=r"vision\.pose\.wall_depths = \[\] is out of "
                                          r"range") as err:
        load_scene("paper", ["vision.pose.wall_depths=[]"])
    assert "\n" not in str(err.value)


def test_the_wall_cover_follows_its_extra_depths() -> None:
    tilted = project_circle(np.array([0.0, 0.0, 0.28]), normal_from_tilt(35.0, 0.0), 0.035, K)
    sol = circle_poses(tilted, K, 1.0)[0]
    # A small face over the far edge of the predicted wall only: beyond the band's point
    # farthest from the face at 0.8 radii deep, reaching 2 px into it (the 0.6 radii band
    # lies ~4 px nearer the face).
    ring = band_points(sol.normal_cam, sol.centre_cam, tilted, K, (0.8,))
    out = ring - np.array([tilted.cx, tilted.cy])
    far = ring[np.argmax(np.hypot(out[:, 0], out[:, 1]))]
    away = (far - [tilted.cx, tilted.cy]) / np.hypot(*(far - [tilted.cx, tilted.cy]))
    centre = far + 5.0 * away
    over = Ellipse(cx=float(centre[0]), cy=float(centre[1]), a=8.0, b=8.0, angle_deg=0.0)
    with_far = covered_shares([tilted, over], K)[0, 1]
    near_only = covered_shares([tilted, over], K,
                               params=TopParams(cover_extra_depths=()))[0, 1]
    assert with_far > 0.0 == near_only


def test_the_final_outline_search_follows_its_reach() -> None:
    # A face (grey 200 on the belt) ringed 4 px outside by a brighter band: the stronger step.
    face = FACES[1]
    ring = replace(face, a=face.a + 8.0, b=face.b + 8.0)
    edge = replace(face, a=face.a + 4.0, b=face.b + 4.0)
    image = np.full(SHAPE, 30.0)
    image[ring.mask(SHAPE)] = 255.0
    image[edge.mask(SHAPE)] = 30.0
    image[face.mask(SHAPE)] = 200.0
    gray = np.asarray(cv2.GaussianBlur(image, (0, 0), 1.0), np.float32)
    close = track_outline(gray, face, search_px=2.0)
    assert close is not None and abs(close.a - face.a) < 1.0
    reach = OutlineTrackingParams(close_search_px=6.0)
    wide = track_outline(gray, face, search_px=2.0, params=reach)
    assert wide is None or abs(wide.a - face.a) > 2.0  # the ring's edge taken, or no fit

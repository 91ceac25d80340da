"""The detector as named stages (skip, replace, time) and its settings as per-stage sections
reachable from a scene's [vision] table, --set and sweep --param."""

from __future__ import annotations

import argparse
from dataclasses import fields, replace

import numpy as np
import pytest
from two_faces import SHAPE, K, two_face_image

from stackpick_sim.cli import detect_cmd
from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.vision_params import SKIPPABLE_STAGES
from stackpick_sim.episodes.detectors import scene_detector_config
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.runs.sweep import grid, parse_param
from stackpick_sim.vision.detector import REQUIRED_STAGES, STAGES, DetectorConfig, detect
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.limits import Deadline
from stackpick_sim.vision.params import (
    EdgeParams,
    FitParams,
    GateParams,
    MergeParams,
    PoseParams,
    RefineParams,
    ReportParams,
    RoiParams,
    SegmentParams,
    TopParams,
)
from stackpick_sim.vision.roi import Roi, find_roi
from stackpick_sim.vision.segments import link_segments
from stackpick_sim.vision.stages import Stage, StageError, State


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return two_face_image()


def _key(det: object) -> list[tuple[float, ...]]:
    return [tuple(e.ellipse.as_dict().values()) for e in det.ellipses]  # type: ignore[attr-defined]


def test_every_stage_is_timed_under_its_name(image: np.ndarray) -> None:
    found = detect(image, DetectorConfig(intrinsics=K))
    assert found.top is not None, found.reason
    assert [s.name for s in STAGES] == ["roi", "edges", "segments", "fitting", "merging",
                                        "refine", "gate", "top", "pose"]
    assert set(found.timings_ms) == {s.name for s in STAGES} | {"total"}
    assert found.timings_ms["total"] >= sum(found.timings_ms[s.name] for s in STAGES) - 1e-6


def test_skipping_the_refit_reports_the_merged_fits(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    refined = detect(image, config)
    merged = detect(image, config.without("refine"))
    assert "refine" not in merged.timings_ms
    assert merged.top is not None and len(merged.ellipses) == len(refined.ellipses)
    assert _key(merged) != _key(refined)  # the refit moves the fits onto the edge pixels


def test_skipping_the_roi_searches_the_whole_frame(image: np.ndarray) -> None:
    seen: list[State] = []

    def spy(state: State, config: DetectorConfig) -> State:
        seen.append(state)
        return state

    config = DetectorConfig(intrinsics=K).without("roi").with_stage("gate", spy)
    found = detect(image, config)
    assert found.top is not None and "roi" not in found.timings_ms
    assert seen[0].crop == SHAPE and seen[0].roi.offset == (0, 0)
    with_roi = detect(image, DetectorConfig(intrinsics=K).with_stage("gate", spy))
    assert seen[1].crop != SHAPE  # the box around the two faces
    assert with_roi.top is not None


def test_a_replaced_stage_runs_in_its_place_and_its_output_is_used(image: np.ndarray) -> None:
    def only_the_larger(state: State, config: DetectorConfig) -> State:
        return replace(state, merged=[m for m in state.merged if m.ellipse.a >= 43])

    assert len(detect(image, DetectorConfig(intrinsics=K)).ellipses) == 2
    found = detect(image, DetectorConfig(intrinsics=K).with_stage("gate", only_the_larger))
    assert [round(e.ellipse.cx) for e in found.ellipses] == [150]
    assert "gate" in found.timings_ms


def test_a_stage_missing_what_an_earlier_stage_makes_names_it(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K).with_stage("edges", lambda state, config: state)
    with pytest.raises(StageError, match="segments stage needs the edge image"):
        detect(image, config)


def test_required_stages_cannot_be_skipped_and_unknown_ones_are_named() -> None:
    config = DetectorConfig()
    for name in REQUIRED_STAGES:
        with pytest.raises(ConfigError, match="cannot be skipped"):
            config.without(name)
    with pytest.raises(ConfigError, match="no stage 'blur'"):
        config.without("blur")
    with pytest.raises(ConfigError, match="no stage 'blur'"):
        config.with_stage("blur", lambda state, config: state)
    with pytest.raises(ConfigError, match="include top"):
        DetectorConfig(stages=tuple(s for s in STAGES if s.name != "top"))
    with pytest.raises(ConfigError, match="distinct"):
        DetectorConfig(stages=(*STAGES, Stage("roi", STAGES[0].run)))


def test_report_settings_change_what_is_reported(image: np.ndarray) -> None:
    every = detect(image, DetectorConfig(intrinsics=K))
    assert len(every.ellipses) == 2
    # The lower face shows about 70% of its outline.
    strict = detect(image, DetectorConfig(intrinsics=K, report=ReportParams(min_support=0.8)))
    assert [round(e.ellipse.cx) for e in strict.ellipses] == [150] and strict.top == 0
    top_only = detect(image, DetectorConfig(intrinsics=K, report=ReportParams(min_support=1.0)))
    assert len(top_only.ellipses) <= 1 and top_only.top == 0  # the top is always reported


def test_the_size_gate_follows_its_slack(image: np.ndarray) -> None:
    # The faces' semi-major axes are 45 and 40 px; a depth range whose gate admits 43-60 px.
    near, far = K.fy * 0.035 / 60.0, K.fy * 0.035 / 43.0
    config = DetectorConfig(intrinsics=K, radii_m=(0.035,), depth_range_m=(near, far),
                            gate=GateParams(slack=(1.0, 1.0)))
    assert [round(e.ellipse.cx) for e in detect(image, config).ellipses] == [150]
    assert len(detect(image, config.without("gate")).ellipses) == 2


def test_edge_settings_reach_the_edge_map(image: np.ndarray) -> None:
    # Noise edges appear once the high threshold drops to the noise level.
    plain = edge_image(image).edges.sum()
    assert edge_image(image, EdgeParams(noise_multiple=1.0, contrast_fraction=0.0,
                                        min_high_threshold=0.0)
                      ).edges.sum() > 2 * plain
    assert edge_image(image, EdgeParams(blur_sigma_px=2.5)).edges.sum() < plain


def test_fit_settings_reach_the_fits(image: np.ndarray) -> None:
    found = detect(image, DetectorConfig(intrinsics=K, fits=FitParams(min_fit_px=1000)))
    assert not found.ellipses and found.top is None  # no chain is that long
    assert detect(image, DetectorConfig(intrinsics=K, fits=FitParams(max_residual_px=0.3))
                  ).top is not None


def test_segment_settings_reach_the_chains(image: np.ndarray) -> None:
    cfg = load_scene("paper", ["vision.segments.min_chain_px=1000"])
    config = scene_detector_config(cfg, K, (0.2, 0.3))
    assert config.segments == SegmentParams(min_chain_px=1000)
    found = detect(image, replace(config, depth_range_m=None))
    assert not found.ellipses and found.top is None  # no chain is that long
    plain = link_segments(edge_image(image).edges)
    coarse = link_segments(edge_image(image).edges, params=SegmentParams(poly_epsilon_px=4.0))
    assert [c.shape[0] for c in coarse.chains] != [c.shape[0] for c in plain.chains]


def test_merge_settings_reach_the_merge(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    plain = detect(image, config)
    assert plain.ellipses
    strict = detect(image, replace(config, merging=MergeParams(min_support=1.0)))
    assert len(strict.ellipses) < len(plain.ellipses)  # no outline is supported all round
    cfg = load_scene("paper", ["vision.merging.k=0.5", "vision.merging.tolerance_px=1.0"])
    assert scene_detector_config(cfg, K, (0.2, 0.3)).merging == MergeParams(k=0.5,
                                                                             tolerance_px=1.0)


def test_refine_settings_reach_the_refit(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    narrow = detect(image, replace(config, refine=RefineParams(tolerances_px=(0.5,))))
    assert _key(narrow) != _key(detect(image, config))  # fewer pixels along each outline
    never = detect(image, replace(config, refine=RefineParams(min_pixels=10_000)))
    assert _key(never) == _key(detect(image, config.without("refine")))


def test_final_fit_settings_reach_the_pose(image: np.ndarray) -> None:
    config = DetectorConfig(intrinsics=K)
    plain = detect(image, config)
    assert plain.pose is not None
    for pose in (PoseParams(subpixel_tolerance_px=0.3, profile_rounds=0),
                 PoseParams(profile_min_share=1.0, subpixel_tolerance_px=0.3)):
        moved = detect(image, replace(config, pose=pose))
        assert moved.pose is not None and moved.pose != plain.pose
    cfg = load_scene("paper", ["vision.pose.profile_rounds=2", "vision.refine.min_normal_cos=0.9"])
    got = scene_detector_config(cfg, K, (0.2, 0.3))
    assert got.pose.profile_rounds == 2 and got.refine.min_normal_cos == 0.9


def test_roi_settings_reach_the_box(image: np.ndarray) -> None:
    rgb = np.repeat(image[:, :, None], 3, axis=2)
    tight, wide = find_roi(rgb), find_roi(rgb, RoiParams(margin_px=30))
    assert wide.u0 == max(0, tight.u0 - 20) and wide.v1 == min(SHAPE[0], tight.v1 + 20)


@pytest.mark.parametrize(("override", "message"), [
    ("vision.report.min_support=1.5", "vision.report.min_support = 1.5 is out of range; "
                                      "allowed: 0 to 1"),
    ("vision.gate.slack=[1.3, 1.2]", "vision.gate.slack = [1.3, 1.2] must be [low, high]"),
    ("vision.segments.corner_angle_deg=200", "vision.segments.corner_angle_deg = 200.0 is out "
                                             "of range; allowed: 1 to 180 deg"),
    ("vision.merging.absorb_fraction=1.2", "vision.merging.absorb_fraction = 1.2 is out of "
                                           "range; allowed: 0 to 1"),
    ("vision.pose.profile_step_px=0", "vision.pose.profile_step_px = 0.0 is out of range; "
                                      "allowed: 0.1 to 2 px"),
    ("vision.top.contrast_rounds=0", "vision.top.contrast_rounds = 0 is out of range; "
                                     "allowed: 1 to 10 rounds"),
    ("vision.roi.decimation=3", "vision.roi.decimation = 3 is out of range; allowed: a power"),
    ("vision.top.fallbacks=['rimmed', 'bogus']", "vision.top.fallbacks"),
    ("vision.report.rim_angle_deg=true", "has the wrong type"),
    ("vision.merge.k=1", "unknown scene key 'vision.merge.k'"),
])
def test_out_of_range_settings_give_one_line_errors(override: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("[", r"\[")) as err:
        load_scene("paper", [override])
    assert "\n" not in str(err.value)


def test_scene_settings_reach_the_detector_and_the_sweep() -> None:
    cfg = load_scene("paper", ["vision.report.min_support=0.8", "vision.top.fallbacks=[]",
                               "vision.roi.margin_px=6", "vision.ellipses.min_normal_cos=0.9"])
    config = scene_detector_config(cfg, K, (0.2, 0.3))
    assert config.report.min_support == 0.8 and config.top.fallbacks == ()
    assert config.roi.margin_px == 6 and config.ellipses.min_normal_cos == 0.9
    assert config.report.duplicate_share == ReportParams().duplicate_share
    cells = grid([parse_param("vision.gate.slack=[0.8,1.3]"),
                  parse_param("vision.report.misfit_share=0.4,0.6")])
    got = [load_scene("paper", c.overrides) for c in cells]
    assert [(s.vision.gate.slack, s.vision.report.misfit_share) for s in got] == [
        ((0.8, 1.3), 0.4), ((0.8, 1.3), 0.6)]


def test_stages_are_skipped_from_the_scene() -> None:
    assert set(REQUIRED_STAGES) | set(SKIPPABLE_STAGES) == {s.name for s in STAGES}
    cfg = load_scene("paper", ["vision.skip_stages=['refine', 'gate']"])
    names = [s.name for s in scene_detector_config(cfg, K, (0.2, 0.3)).stages]
    assert names == ["roi", "edges", "segments", "fitting", "merging", "top", "pose"]
    with pytest.raises(ConfigError, match=r"vision\.skip_stages = \['top'\] is out of range"):
        load_scene("paper", ["vision.skip_stages=['top']"])


def test_detect_command_takes_vision_settings_from_set() -> None:
    args = argparse.Namespace(scene=None, overrides=["vision.top.rest_check=false"], fovy=None,
                              radii=None, depth_range=None)
    config = detect_cmd.detector_config(args, 320, 240)
    assert config.top == TopParams(rest_check=False)


def test_a_state_updated_is_the_state_replaced(image: np.ndarray) -> None:
    seen: list[State] = []
    detect(image, DetectorConfig(intrinsics=K).with_stage(
        "gate", lambda state, config: seen.append(state) or state))
    state = seen[0]
    assert state.updated(gate=(1.0, 2.0)) == replace(state, gate=(1.0, 2.0))
    assert state.gate is None  # unchanged
    with pytest.raises(TypeError, match="ellipses"):
        state.updated(ellipses=[])


def test_a_state_started_is_the_state_constructed(image: np.ndarray) -> None:
    given = {"image": image, "intrinsics": K, "deadline": Deadline(0.0, 100.0),
             "roi": Roi.of(0, 0, SHAPE[1], SHAPE[0]), "work": image, "crop": SHAPE,
             "timings_ms": {}}
    started, built = State.start(**given), State(**given)  # type: ignore[arg-type]
    for f in fields(State):
        got, want = getattr(started, f.name), getattr(built, f.name)
        if isinstance(want, np.ndarray):
            assert got.dtype == want.dtype and np.array_equal(got, want), f.name
        else:
            assert got == want, f.name
    assert started.roi == Roi(u0=0, v0=0, u1=SHAPE[1], v1=SHAPE[0])
    # Each state its own mutable defaults, as the constructor's.
    assert State.start(**given).merged is not started.merged
    with pytest.raises(TypeError, match="ellipses"):
        State.start(**given, ellipses=[])
    with pytest.raises(TypeError, match="deadline"):
        State.start(**{k: v for k, v in given.items() if k != "deadline"})

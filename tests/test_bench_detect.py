"""Tests of the detection benchmark: scoring rules and the bench-detect CLI on a tiny data set."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.benchmark.frames import BenchFrame, TruthFace, load_frame
from stackpick_sim.vision.benchmark.scoring import MethodOutput, score_frame
from stackpick_sim.vision.synthetic import draw_ellipses

SHAPE = (240, 320)
K = CameraIntrinsics.from_fovy(45.0, 320, 240)
TOP = Ellipse(cx=180, cy=125, a=38, b=33, angle_deg=110)
UNDER = Ellipse(cx=140, cy=120, a=40, b=34, angle_deg=20)
HIDDEN = Ellipse(cx=175, cy=125, a=20, b=18, angle_deg=0)


def face(name: str, e: Ellipse, visible: float, top: bool) -> TruthFace:
    return TruthFace(name=name, radius_m=0.035, ellipse=e, face_center_px=(e.cx, e.cy),
                     theta_x_deg=1.0, theta_y_deg=-2.0, visible_fraction=visible, is_top=top)


FRAME = BenchFrame(seed=7, image_rgb=np.zeros((*SHAPE, 3), np.uint8), intrinsics=K,
                   depth_range_m=(0.15, 0.28),
                   faces=(face("a", UNDER, 0.7, False), face("b", TOP, 1.0, True),
                          face("c", HIDDEN, 0.1, False)))


def output(ellipses: tuple[Ellipse, ...], top: Ellipse | None,
           pose: tuple[float, float, float, float] | None) -> MethodOutput:
    return MethodOutput(ellipses=ellipses, top=top, pose=pose, total_ms=1.0, detector_ms=1.0,
                        stages_ms={})


def test_perfect_output_scores_full_marks() -> None:
    s = score_frame(output((TOP, UNDER), TOP, (TOP.cx + 0.3, TOP.cy - 0.4, 1.5, -2.0)), FRAME)
    assert s.success and (s.true_pos, s.false_pos, s.false_neg) == (2, 0, 0)
    assert s.centre_err_px is not None and abs(s.centre_err_px - 0.5) < 1e-9
    assert s.theta_x_err_deg is not None and abs(s.theta_x_err_deg - 0.5) < 1e-9


def test_wrong_or_shifted_top_fails_and_counts_false_positive() -> None:
    shifted = Ellipse(cx=TOP.cx + 12, cy=TOP.cy, a=TOP.a, b=TOP.b, angle_deg=TOP.angle_deg)
    s = score_frame(output((shifted,), shifted, (0.0, 0.0, 0.0, 0.0)), FRAME)
    assert not s.success and s.centre_err_px is None
    assert (s.true_pos, s.false_pos, s.false_neg) == (0, 1, 2)
    s2 = score_frame(output((UNDER,), UNDER, None), FRAME)
    assert not s2.success and s2.true_pos == 1


def test_detecting_a_mostly_hidden_face_is_neither_true_nor_false() -> None:
    s = score_frame(output((HIDDEN,), None, None), FRAME)
    assert (s.true_pos, s.false_pos, s.false_neg) == (0, 0, 2)


def write_frame(directory: Path, seed: int) -> None:
    gray = draw_ellipses(SHAPE, [UNDER, TOP], noise_sigma=1.0, rng=np.random.default_rng(seed))
    cv2.imwrite(str(directory / f"{seed:06d}.png"), cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    world_t_cam = np.diag([1.0, -1.0, -1.0, 1.0])
    world_t_cam[2, 3] = 0.40
    objects = []
    for name, e, vis, top in (("a", UNDER, 0.7, False), ("b", TOP, 1.0, True)):
        objects.append({"name": name, "type": "large", "radius": 0.035, "height": 0.03,
                        "ellipse": e.as_dict(), "face_center_px": [e.cx, e.cy],
                        "theta_x_deg": 0.0, "theta_y_deg": 0.0, "visible_fraction": vis,
                        "is_top": top})
    record = {"width": 320, "height": 240,
              "intrinsics": {"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy},
              "world_T_cam": world_t_cam.tolist(), "objects": objects}
    (directory / f"{seed:06d}.json").write_text(json.dumps(record))


def test_load_frame_reads_dataset_record(tmp_path: Path) -> None:
    write_frame(tmp_path, 3)
    frame = load_frame(tmp_path, 3, belt_top_z=0.10, max_face_height=0.15)
    assert frame.shape == SHAPE and frame.image_rgb.shape == (*SHAPE, 3)
    assert [f.name for f in frame.tops] == ["b"]
    # the camera is 0.30 m above the belt: faces lie from 0.15 m above it down to it
    assert np.allclose(frame.depth_range_m, (0.30 - 0.15, 0.30))


def test_cli_writes_tables_for_a_data_set(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    data, out = tmp_path / "data", tmp_path / "out"
    data.mkdir()
    for seed in (0, 1):
        write_frame(data, seed)
    code = main(["bench-detect", "--data", str(data), "--out", str(out),
                 "--methods", "ours,findellipses", "--quiet"])
    assert code == 0
    err = capsys.readouterr().err
    assert "bench-detect" not in err  # --quiet: no progress bar
    assert "has no index.json" in err  # the kinds are --scene's: said once
    results = json.loads((out / "results.json").read_text())
    ours = results["methods"]["ours"]
    assert ours["frames"] == 2 and ours["top_success"] == 1.0
    assert set(results["methods"]) == {"ours", "findellipses"}
    text = (out / "results.md").read_text()
    assert "| ours |" in text and "Table 1" in text


def test_dataset_kinds_read_from_the_index(tmp_path: Path) -> None:
    from stackpick_sim.vision.benchmark.frames import dataset_kinds

    assert dataset_kinds(tmp_path) == ()
    types = {"large": {"radius": 0.035, "height": 0.03, "rgba": [0.85, 0.6, 0.25, 1.0]},
             "small": {"radius": 0.025, "height": 0.025, "rgba": [0.3, 0.6, 0.85, 1.0]}}
    (tmp_path / "index.json").write_text(json.dumps({"scene": {"object_types": types}}))
    assert dataset_kinds(tmp_path) == ((0.035, (0.85, 0.6, 0.25), 0.03),
                                       (0.025, (0.3, 0.6, 0.85), 0.025))


def test_a_data_set_without_index_takes_the_kinds_of_the_scene(tmp_path: Path) -> None:
    from stackpick_sim.config.loader import load_scene
    from stackpick_sim.vision.benchmark.frames import iter_dataset

    write_frame(tmp_path, 5)
    cfg = load_scene("paper")
    (frame,) = iter_dataset(tmp_path, None, cfg)
    radii = sorted(k[0] for k in frame.kinds)
    assert radii == sorted(t.radius for t in cfg.object_types.values())
    # with an index, its recorded scene's kinds
    types = {"only": {"radius": 0.05, "height": 0.02, "rgba": [0.2, 0.2, 0.2, 1.0]}}
    (tmp_path / "index.json").write_text(json.dumps({"scene": {"object_types": types}}))
    (frame,) = iter_dataset(tmp_path, None, cfg)
    assert frame.kinds == ((0.05, (0.2, 0.2, 0.2), 0.02),)

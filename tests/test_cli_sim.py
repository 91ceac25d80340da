"""`stackpick render` and `stackpick dataset` end to end: the files they promise, readable."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import pytest

from stackpick_sim.cli.main import main


def test_render_writes_frame_truth_overlay_external_and_scene(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["render", "--seed", "3", "--out", str(tmp_path)]) == 0
    frame = cv2.imread(str(tmp_path / "frame.png"))
    assert frame is not None and frame.shape == (240, 320, 3)
    overlay = cv2.imread(str(tmp_path / "overlay.png"))
    # The frame at twice its size, a legend strip below it.
    assert overlay is not None and overlay.shape[1] == 640 and 480 < overlay.shape[0] < 560
    assert cv2.imread(str(tmp_path / "external.png")) is not None
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["seed"] == 3 and truth["top_objects"]
    assert (tmp_path / "scene.xml").read_text().lstrip().startswith("<mujoco")
    assert "TOP" in capsys.readouterr().out


def test_dataset_writes_one_image_and_json_per_seed(tmp_path: Path) -> None:
    assert main(["dataset", "--seeds", "0:3", "--out", str(tmp_path), "--quiet",
                 "--set", "camera.noise_std=2"]) == 0
    for seed in range(3):
        image = cv2.imread(str(tmp_path / f"{seed:06d}.png"))
        assert image is not None and image.shape == (240, 320, 3)
        record = json.loads((tmp_path / f"{seed:06d}.json").read_text())
        assert record["seed"] == seed
        assert {"intrinsics", "world_T_cam", "objects", "top_objects"} <= set(record)
        for obj in record["objects"]:
            assert isinstance(obj["is_top"], bool) and isinstance(obj["on_belt"], bool)
    index = json.loads((tmp_path / "index.json").read_text())
    assert [s["seed"] for s in index["seeds"]] == [0, 1, 2]
    assert index["scene"]["camera"]["noise_std"] == 2.0


def test_a_stopped_dataset_run_leaves_its_index(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from stackpick_sim.cli import dataset_cmd

    real = dataset_cmd.seeded_look_frame

    def stop_at_the_second(cfg: Any, seed: int) -> Any:
        if seed == 1:
            raise KeyboardInterrupt  # the user stops a long run
        return real(cfg, seed)

    monkeypatch.setattr(dataset_cmd, "seeded_look_frame", stop_at_the_second)
    assert main(["dataset", "--scene", "cluttered", "--seeds", "0:3", "--out", str(tmp_path),
                 "--quiet"]) == 130  # the exit code of an interrupted command
    index = json.loads((tmp_path / "index.json").read_text())
    assert [s["seed"] for s in index["seeds"]] == [0]
    assert index["scene"]["name"] == "cluttered"  # the kinds a benchmark of it needs


@pytest.mark.parametrize("make_out", ["missing_parent", "a_file"])
def test_unwritable_output_is_one_line_and_exit_2(make_out: str, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    if make_out == "a_file":
        out = tmp_path / "taken"
        out.write_text("not a directory")
    else:
        blocker = tmp_path / "file"
        blocker.write_text("")
        out = blocker / "sub"  # a directory cannot be made inside a file
    assert main(["dataset", "--seeds", "0", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err and str(out.name) in err

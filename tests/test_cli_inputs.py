"""Bad input to the command line: one line on stderr and exit code 2, nothing half-written."""

from __future__ import annotations

import errno
import json
import math
import os
from pathlib import Path

import cv2
import mujoco
import numpy as np
import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.config.loader import load_scene
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import CameraIntrinsics
from stackpick_sim.vision.synthetic import generate_stack


def one_error_line(capfd: pytest.CaptureFixture[str]) -> str:
    """The captured stderr, asserting it is one ``error:`` line (libraries' lines included)."""
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "error:" in err, err
    return err


@pytest.fixture(scope="module")
def stack_png(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("img") / "stack.png"
    scene = generate_stack(np.random.default_rng(4))
    cv2.imwrite(str(path), cv2.cvtColor(scene.image, cv2.COLOR_RGB2BGR))
    return path


def test_detect_on_a_non_utf8_path_is_one_line(tmp_path: Path,
                                               capfd: pytest.CaptureFixture[str]) -> None:
    path = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"nothere\xff.png"))
    assert main(["detect", path, "--json"]) == 2
    assert "nothere\\xff.png" in one_error_line(capfd)


def test_detect_on_a_missing_file_prints_no_opencv_warning(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    assert main(["detect", str(tmp_path / "nothere.png")]) == 2
    assert "WARN" not in one_error_line(capfd)


def test_detect_on_a_fifo_returns_at_once(tmp_path: Path,
                                          capfd: pytest.CaptureFixture[str]) -> None:
    os.mkfifo(tmp_path / "f.png")
    assert main(["detect", str(tmp_path / "f.png")]) == 2
    assert "not a regular file" in one_error_line(capfd)


@pytest.mark.parametrize("fovy", ["0", "nan", "inf", "-45", "360", "1e-300"])
def test_detect_refuses_a_field_of_view_outside_its_range(
        fovy: str, stack_png: Path, capfd: pytest.CaptureFixture[str]) -> None:
    assert main(["detect", str(stack_png), "--fovy", fovy, "--json"]) == 2
    assert "1 to 170 degrees" in one_error_line(capfd)


@pytest.mark.parametrize("args", [["--radii", "inf"], ["--radii", "1e300"], ["--radii", "0"],
                                  ["--depth-range", "inf", "inf"],
                                  ["--depth-range", "0.3", "0.2"],
                                  ["--depth-range", "nan", "0.3"]])
def test_detect_refuses_radii_and_depths_outside_their_ranges(
        args: list[str], stack_png: Path, capfd: pytest.CaptureFixture[str]) -> None:
    assert main(["detect", str(stack_png), *args, "--json"]) == 2
    assert "allowed:" in one_error_line(capfd)


def test_detect_json_is_strict_json(stack_png: Path,
                                    capfd: pytest.CaptureFixture[str]) -> None:
    assert main(["detect", str(stack_png), "--json", "--fovy", "1", "--radii", "1"]) == 0

    def refuse(constant: str) -> float:
        raise AssertionError(f"{constant} in JSON output")

    doc = json.loads(capfd.readouterr().out, parse_constant=refuse)
    assert "ellipses" in doc


@pytest.mark.parametrize("name", ["out.xyz", "noext", "adir.png", "/dev/full"])
def test_detect_overlay_to_a_path_with_no_writer_is_one_line(
        name: str, stack_png: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "adir.png").mkdir()
    target = name if name.startswith("/") else str(tmp_path / name)
    if not os.path.exists(target) and name.startswith("/"):
        pytest.skip(f"{name} does not exist here")
    assert main(["detect", str(stack_png), "--overlay", target]) == 2
    assert os.path.basename(name) in one_error_line(capfd)


def test_detect_overlay_of_a_16_bit_png_is_scaled_not_wrapped(stack_png: Path,
                                                              tmp_path: Path) -> None:
    deep = cv2.imread(str(stack_png)).astype(np.uint16) * 256 + 255
    cv2.imwrite(str(tmp_path / "deep.png"), deep)
    assert main(["detect", str(tmp_path / "deep.png"), "--overlay",
                 str(tmp_path / "o.png")]) == 0
    h, w = deep.shape[:2]
    overlay = cv2.imread(str(tmp_path / "o.png"))[:2 * h:2, :2 * w:2]  # drawn at 2x
    untouched = np.all(overlay == deep // 257, axis=2)  # a cast would give 255 everywhere
    assert untouched.mean() > 0.9


def test_render_to_a_non_utf8_directory(tmp_path: Path,
                                        capfd: pytest.CaptureFixture[str]) -> None:
    out = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"out\xff"))
    assert main(["render", "--seed", "1", "--out", out]) == 0
    assert "wrote" in capfd.readouterr().out
    assert sorted(os.listdir(out)) == ["external.png", "frame.png", "overlay.png", "scene.xml",
                                       "truth.json"]


@pytest.mark.parametrize("command", [["render", "--seed", "1"],
                                     ["dataset", "--seeds", "1", "--quiet"]])
def test_a_full_disk_is_one_line_no_wrote_and_no_empty_files(
        command: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capfd: pytest.CaptureFixture[str]) -> None:
    def full_disk(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    assert main([*command, "--out", str(tmp_path / "o")]) == 2
    out = capfd.readouterr()
    assert "wrote" not in out.out
    assert out.err.count("\n") == 1 and "No space left on device" in out.err
    assert list((tmp_path / "o").iterdir()) == []


def test_mujoco_warnings_leave_no_log_file_and_are_still_counted(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import stackpick_sim.sim  # noqa: F401 - installs the warning handler

    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
    data = mujoco.MjData(model)
    data.qvel[:] = 1e300
    mujoco.mj_step(model, data)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fx", [0.0, -1.0, math.nan, math.inf])
def test_camera_intrinsics_refuse_a_focal_length_that_is_not_positive(fx: float) -> None:
    with pytest.raises(ConfigError, match="fx"):
        CameraIntrinsics(fx=fx, fy=100.0, cx=10.0, cy=10.0, width=20, height=20)


def test_camera_intrinsics_refuse_an_empty_image() -> None:
    with pytest.raises(ConfigError, match="width"):
        CameraIntrinsics(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=0, height=20)


# --- scene files and --set values ---------------------------------------------------------

@pytest.mark.parametrize(("content", "message"), [
    ("a = " + "[" * 2000 + "]" * 2000 + "\n", "levels deep"),
    ("[" + ".".join(["a"] * 2000) + "]\nx = 1\n", "levels deep"),
    ('name = "x"\n'.encode("utf-16"), "not UTF-8"),
    ('name = "caf\xe9"\n'.encode("latin-1"), "not UTF-8"),
])
def test_unreadable_scene_files_are_one_config_error(content: str | bytes, message: str,
                                                     tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises(ConfigError, match=message):
        load_scene(str(path))


def test_a_scene_file_with_a_utf8_bom_loads(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_bytes(b"\xef\xbb\xbf" + b'description = "bom"\n')
    assert load_scene(str(tmp_path / "s.toml")).description == "bom"


@pytest.mark.parametrize(("override", "message"), [
    ("conveyor.speed=" + "[" * 2000 + "]" * 2000, "levels deep"),
    ("conveyor.speed=0.2\nconveyor.x=0.5", "several lines"),
])
def test_bad_set_values_are_one_config_error(override: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_scene("paper", [override])


def test_a_deep_set_value_on_the_command_line_is_exit_2(
        capfd: pytest.CaptureFixture[str]) -> None:
    deep = "[" * 2000 + "]" * 2000
    assert main(["render", "--seed", "0", "--out", "unused", "--set",
                 f"conveyor.speed={deep}"]) == 2
    one_error_line(capfd)


@pytest.mark.parametrize("key", [
    "conveyor.jitter_period", "conveyor.width", "conveyor.length", "conveyor.speed_jitter",
    "conveyor.friction", "episode.standoff", "episode.approach_gain",
    "episode.servo_lateral_tol", "episode.servo_depth_tol", "episode.servo_tilt_tol_deg",
    "episode.descend_speed", "episode.overtravel", "episode.grasp_dwell",
    "episode.lift_height", "episode.lift_speed", "episode.verify_time",
    *(f"episode.timeout_{p}" for p in ("look", "detect", "track", "approach", "servo",
                                       "descend", "grasp", "lift", "verify"))])
@pytest.mark.parametrize("value", ["1e300", "-1e-300", "nan"])
def test_scene_keys_refuse_implausible_values_naming_the_range(key: str, value: str) -> None:
    with pytest.raises(ConfigError, match=rf"{key} = .* out of range; allowed: \S+ to \S+"):
        load_scene("paper", [f"{key}={value}"])

"""Scene configs: shipped scenes load, overrides apply, every bad input gives one clear error."""

from __future__ import annotations

from pathlib import Path

import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.config.loader import available_scenes, known_keys, load_scene, parse_override
from stackpick_sim.exceptions import ConfigError


@pytest.mark.parametrize("name", available_scenes())
def test_every_shipped_scene_loads(name: str) -> None:
    cfg = load_scene(name)
    assert cfg.name == name
    lo, hi = cfg.objects.count
    assert 1 <= lo <= hi


def test_paper_scene_is_the_papers_setting() -> None:
    cfg = load_scene("paper")
    assert (cfg.camera.width, cfg.camera.height) == (320, 240)
    assert cfg.objects.count == (3, 5)
    assert len(cfg.object_types) == 2  # the paper used two cylinder kinds


def test_harder_variant_extends_paper_and_is_harder() -> None:
    paper, hard = load_scene("paper"), load_scene("cluttered")
    assert hard.objects.count[1] > paper.objects.count[1]
    assert hard.objects.max_tilt_deg > paper.objects.max_tilt_deg
    assert hard.camera.noise_std > paper.camera.noise_std
    assert hard.conveyor.speed > paper.conveyor.speed
    assert hard.object_types == paper.object_types  # inherited through `extends`


def test_overrides_of_the_documented_keys() -> None:
    cfg = load_scene("paper", [
        "conveyor.speed=0.2", "objects.count=[4,6]", "camera.noise_std=3",
        "objects.max_tilt_deg=30", "camera.width=640", "camera.height=480",
        "lights.intensity=0.5", "object_types.large.radius=0.03"])
    assert cfg.conveyor.speed == 0.2
    assert cfg.objects.count == (4, 6)
    assert cfg.camera.noise_std == 3.0
    assert cfg.objects.max_tilt_deg == 30.0
    assert (cfg.camera.width, cfg.camera.height) == (640, 480)
    assert cfg.lights.intensity == 0.5
    assert cfg.object_types["large"].radius == 0.03
    assert cfg.object_types["large"].height == load_scene("paper").object_types["large"].height


def test_later_override_wins() -> None:
    assert load_scene("paper", ["conveyor.speed=0.2", "conveyor.speed=0.3"]).conveyor.speed == 0.3


def test_scene_by_path(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('extends = "paper"\n[conveyor]\nspeed = 0.05\n')
    cfg = load_scene(str(path))
    assert cfg.name == "mine" and cfg.conveyor.speed == 0.05


@pytest.mark.parametrize(("override", "message"), [
    ("conveyer.speed=0.2", "unknown scene key 'conveyer.speed'; known keys: name, "),
    ("camera.width='wide'", "camera.width = 'wide' has the wrong type; expected integer"),
    ("camera.width=3.5", "expected integer"),
    ("conveyor.speed=true", "expected number"),
    ("objects.count=[3]", "objects.count = [3] has the wrong type; expected a list of 2 integer"),
    ("objects.count=[0,3]", "objects.count = [0, 3] is out of range"),
    ("objects.count=[3,40]", "at most 10 objects"),
    ("object_types.large.radius=-0.01", "object_types.large.radius = -0.01 is out of range"),
    ("conveyor.speed=-1", "conveyor.speed = -1.0 is out of range"),
    ("camera.noise_std=nan", "camera.noise_std = nan is out of range"),
    ("objects.types=['huge']", "objects.types names unknown type(s) ['huge']"),
    ("objects.max_face_height=0.25", "objects.max_face_height = 0.25 is out of range; allowed: "
     "above the lowest object's height (0.025 m) and at least 0.1 m below "
     "camera.look_height (0.3 m)"),
    ("episode.lift_retreat=-0.01", "episode.lift_retreat = -0.01 is out of range; allowed: "
     "0 to 0.3 m"),
    ("conveyor.speed", "is not of the form key=value"),
    ("conveyor.speed=0.2.3", "the value is not a TOML value; expected number"),
])
def test_bad_override_gives_one_clear_error(override: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_scene("paper", [override])
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_unknown_key_lists_every_known_key() -> None:
    with pytest.raises(ConfigError) as err:
        load_scene("paper", ["lights.colour=1"])
    for key in known_keys():
        assert key in str(err.value)


def test_unquoted_string_value_is_taken_as_a_string() -> None:
    assert parse_override("description=a quick test") == ("description", "a quick test")


def test_missing_and_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"unknown scene .nope.; known scenes: .*paper"):
        load_scene("nope")
    with pytest.raises(ConfigError, match="does not exist"):
        load_scene(str(tmp_path / "absent.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("[conveyor\nspeed = 0.1\n")
    with pytest.raises(ConfigError, match=r"malformed TOML in .*bad\.toml"):
        load_scene(str(bad))
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("[belt]\nspeed = 0.1\n")
    with pytest.raises(ConfigError, match="unknown scene key 'belt'"):
        load_scene(str(unknown))


def test_extends_cycle_is_reported(tmp_path: Path) -> None:
    (tmp_path / "a.toml").write_text('extends = "b.toml"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\n')
    with pytest.raises(ConfigError, match="extends"):
        load_scene(str(tmp_path / "a.toml"))


@pytest.mark.parametrize("argv", [
    ["render", "--scene", "nope", "--out", "x"],
    ["render", "--set", "conveyer.speed=1", "--out", "x"],
    ["dataset", "--seeds", "5:2", "--out", "x"],
])
def test_cli_bad_input_is_one_line_and_exit_2(argv: list[str], tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    argv = [a if a != "x" else str(tmp_path / "out") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err and "Traceback" not in err


def test_choice_keys_accept_only_their_choices() -> None:
    assert load_scene("paper", ["episode.detector=oracle"]).episode.detector == "oracle"
    with pytest.raises(ConfigError, match=r"episode.detector = 'magic' is out of range; "
                                          r"allowed: ours, oracle, rht, findellipses"):
        load_scene("paper", ["episode.detector=magic"])
    with pytest.raises(ConfigError, match=r"episode.estimator = 'magic' .* allowed: belt, image"):
        load_scene("paper", ["episode.estimator=magic"])

"""The seams: stages by name (built-ins, module:attr, unknown names), ground truth kept out of
the control path, unexpected exceptions recorded as ``error``, the steppable episode."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes import run_episode
from stackpick_sim.episodes.audit import auditing
from stackpick_sim.episodes.episode import EpisodeRun
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.pipeline import Controller, Detections, Detector, Estimator, Frame, Hints
from stackpick_sim.registry import BUILTINS, KINDS, PluginError, known, load
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.stacks import generate_scene

#: A paper seed whose pile settles at the first attempts and whose pick succeeds (ours).
SEED = 1
REPO = Path(__file__).resolve().parents[1]


class BrokenDetector:
    """A plug-in with a bug: it raises on the third frame."""

    name = "broken"
    needs_image = False
    exact = False

    def __init__(self, cfg: Any) -> None:
        self.calls = 0

    def detect(self, frame: Frame, hints: Hints) -> Detections:
        self.calls += 1
        if self.calls == 3:
            raise IndexError("list index out of range")
        return Detections(reason="nothing yet")


@pytest.mark.parametrize("kind", KINDS)
def test_builtins_load_and_match_their_protocol(kind: str) -> None:
    cfg = load_scene("paper")
    for name in BUILTINS[kind]:
        factory = load(kind, name)  # type: ignore[arg-type]
        assert callable(factory)
        assert name in known(kind)  # type: ignore[arg-type]
    est = load("estimator", "belt")(cfg, generate_intrinsics(), False)
    assert isinstance(est, Estimator) and est.name == "belt"
    assert isinstance(load("controller", "ibvs")(cfg), Controller)
    assert isinstance(load("detector", "ours")(cfg), Detector)


def generate_intrinsics() -> Any:
    from stackpick_sim.geometry import CameraIntrinsics

    cam = load_scene("paper").camera
    return CameraIntrinsics.from_fovy(cam.fovy_deg, cam.width, cam.height)


def test_unknown_names_say_what_is_known() -> None:
    with pytest.raises(PluginError, match=r"unknown detector 'hogh'; known: ours, oracle, rht, "
                                          r"findellipses"):
        load("detector", "hogh")
    with pytest.raises(PluginError, match=r"cannot load controller 'nosuch.module:X'"):
        load("controller", "nosuch.module:X")
    with pytest.raises(ConfigError, match=r"episode.controller = 'pid' is out of range"):
        load_scene("paper", ["episode.controller=pid"])


@pytest.mark.parametrize("argv", [["run", "--detector", "hogh"],
                                  ["run", "--estimator", "nosuch:Thing"],
                                  ["sweep", "--param", "conveyor.speed=0.1", "--controller",
                                   "pid"]])
def test_cli_rejects_unknown_stages_in_one_line(argv: list[str], tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "--out", str(tmp_path / "out"), "--seeds", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "known:" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "results.jsonl").exists()


class GuardedObjects(tuple):  # type: ignore[type-arg]
    """The cell's objects, readable only by the audit, the physics (the belt) and the cup's
    contact sense; anything else reading them fails the episode."""

    ALLOWED = ("stackpick_sim.sim.", "stackpick_sim.episodes.outcome")

    def __iter__(self) -> Iterator[Any]:
        caller = sys._getframe(1).f_globals.get("__name__", "")
        if not auditing() and not caller.startswith(self.ALLOWED):
            raise AssertionError(f"ground truth read by {caller}")
        return super().__iter__()

    def __getitem__(self, i: Any) -> Any:
        if not auditing():
            raise AssertionError("ground truth read outside the audit")
        return super().__getitem__(i)


def test_truth_stays_out_of_the_control_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """An ``ours`` episode on a cell whose object list and segmentation raise outside the
    audit still succeeds; the audit did read them (the guard was live)."""
    reads = {"segmentation": 0}
    original = WristCamera.segmentation

    def guarded(self: WristCamera) -> Any:
        if not auditing():
            raise AssertionError("segmentation read outside the audit")
        reads["segmentation"] += 1
        return original(self)

    monkeypatch.setattr(WristCamera, "segmentation", guarded)
    scene = generate_scene(load_scene("paper"), SEED)
    object.__setattr__(scene.cell, "objects", GuardedObjects(scene.cell.objects))
    with pytest.raises(AssertionError):
        list(scene.cell.objects)  # from here, a test module: refused
    rec = run_episode(scene)
    assert rec.success, (rec.failure, rec.failure_detail)
    assert reads["segmentation"] > 0 and rec.top_objects and rec.target_object is not None


def test_a_plugin_exception_is_an_error_record_not_a_pick_failure() -> None:
    cfg = load_scene("paper", [f"episode.detector={__name__}:BrokenDetector"])
    run = EpisodeRun(cfg)
    run.reset(SEED)
    steps = 0
    while run.step():
        steps += 1
    rec = run.finish()
    assert rec.failure == "error" and not rec.success
    assert rec.failure_detail == "IndexError: list index out of range"
    assert "in detect" in run.traceback and "raise IndexError" in run.traceback
    assert rec.detector == f"{__name__}:BrokenDetector" and rec.controller == "ibvs"
    assert 0 < steps < 20 and not run.step()  # ended at the third frame; stays ended


def test_steppable_episode_is_run_episode() -> None:
    """reset(seed) + step() builds the same pile and ends in the same record as run_episode."""
    cfg = load_scene("paper", ["episode.detector=oracle"])
    run = EpisodeRun(cfg)
    ep = run.reset(SEED)
    ticks = 0
    while run.step():
        ticks += 1
    stepped = run.finish().as_dict()
    direct = run_episode(generate_scene(cfg, SEED)).as_dict()
    for key in ("wall_s", "wall_breakdown_s", "scene_build_wall_s"):
        stepped.pop(key), direct.pop(key)
    assert stepped == direct and stepped["success"]
    assert ticks == round(stepped["sim_time_s"] / ep.scene.cell.cfg.episode.control_period)
    assert np.isfinite(ep.scene.cell.data.qpos).all()


def test_a_baseline_detector_drives_an_episode() -> None:
    """``findellipses`` (a peer ellipse detector with our top rule and pose) in closed loop."""
    rec = run_episode(generate_scene(load_scene("paper", ["episode.detector=findellipses"]),
                                     SEED))
    assert rec.detector == "findellipses" and rec.failure != "error", rec.failure_detail
    assert rec.measurements_fused >= 3 and "approach" in rec.phases

"""Pick episodes: an oracle pick succeeds, records are complete and deterministic, failures
end with the right reason, physics trouble is a failed episode, the CLI writes its files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes import FAILURES, PHASES, EpisodeHooks, TickInfo, run_episode
from stackpick_sim.episodes.record import WALL_CLOCK_KEYS
from stackpick_sim.episodes.summary import wilson_interval
from stackpick_sim.runs import RunSpec, run_batch
from stackpick_sim.sim.stacks import generate_scene

#: A seed whose pile settles at the first attempts (keeps the tests fast).
SEED = 1
ORACLE = ("episode.detector=oracle",)
#: The fields every episode's record must carry.
REQUIRED = ("seed", "scene", "success", "failure", "picked_object", "top_objects",
            "lift_height_m", "detection", "prediction_error_px", "prediction_error_mm",
            "cycle_time_s", "phases", "wall_s")


def _record(overrides: tuple[str, ...] = ORACLE, seed: int = SEED,
            hooks: EpisodeHooks | None = None) -> dict:
    scene = generate_scene(load_scene("paper", overrides), seed)
    return run_episode(scene, hooks).as_dict()


def _strip(rec: dict) -> dict:
    return {k: v for k, v in rec.items() if k not in WALL_CLOCK_KEYS}


@pytest.fixture(scope="module")
def oracle_record() -> dict:
    return _record()


def test_oracle_episode_succeeds_and_record_is_complete(oracle_record: dict) -> None:
    rec = oracle_record
    assert all(k in rec for k in REQUIRED)
    assert set(rec["detection"]) >= {"center_error_px", "theta_x_error_deg",
                                     "theta_y_error_deg"}
    assert rec["success"] and rec["failure"] is None, rec["failure_detail"]
    assert rec["picked_object"] in rec["top_objects"]
    assert rec["lift_height_m"] >= 0.05
    assert list(rec["phases"]) == list(PHASES)  # every phase entered, in order
    assert rec["cycle_time_s"] == pytest.approx(sum(rec["phases"][p] for p in PHASES[:-1]),
                                                abs=1e-6)
    assert rec["detection"]["center_error_px"] < 1e-6  # the oracle is exact at detection
    assert rec["prediction_error_mm"] < 5.0  # within the suction lip's tolerance
    # Frames come at the camera rate throughout; those after the grasp are not processed.
    assert rec["frames"] >= round(rec["sim_time_s"] * 30) - 1
    assert 0 < rec["frames_processed"] < rec["frames"]
    json.dumps(rec)  # JSON-serialisable


def test_image_frame_tracker_picks_with_the_camera_moving() -> None:
    """The paper's image-frame Kalman variant, its state carried through each camera move:
    it keeps fusing through approach, servo and descent and the pick succeeds."""
    rec = _record((*ORACLE, "episode.tracker_frame=image"))
    assert rec["tracker_frame"] == "image"
    assert rec["success"] and rec["failure"] is None, rec["failure_detail"]
    assert rec["measurements_fused"] >= rec["frames_processed"] - 2  # nothing gated out
    assert rec["prediction_error_mm"] < 5.0  # within the suction lip's tolerance


def test_oracle_tracks_a_face_the_image_border_cuts() -> None:
    """0.3 m/s belt, seed 5092: the pile's one top face is leaving the look view as the first
    frame is taken; the oracle, like our detector, must keep tracking it while the border
    cuts it (it once waited for a whole face that never came: no_detection)."""
    scene = generate_scene(load_scene("fast_belt", ORACLE), 5092)
    rec = run_episode(scene).as_dict()
    assert rec["success"] and rec["failure"] is None, rec["failure_detail"]


def test_same_seed_same_record(oracle_record: dict) -> None:
    assert _strip(_record()) == _strip(oracle_record)


@pytest.mark.parametrize(("override", "reason"), [
    ("episode.timeout_detect=0", "no_detection"),
    ("episode.timeout_approach=0", "timeout"),
])
def test_impossible_timeout_gives_its_reason(override: str, reason: str) -> None:
    rec = _record((*ORACLE, override))
    assert not rec["success"]
    assert rec["failure"] == reason
    assert rec["failure"] in FAILURES


def test_nan_in_the_state_is_unstable_sim_not_a_crash() -> None:
    def inject(info: TickInfo) -> None:
        if info.phase == "approach":
            data = info.episode.scene.cell.data
            data.qvel[info.episode.scene.cell.arm_dof_adr[1]] = math.nan

    rec = _record(hooks=EpisodeHooks(on_tick=inject))
    assert rec["failure"] == "unstable_sim"
    assert not rec["success"]


def test_wilson_interval_known_values() -> None:
    lo, hi = wilson_interval(98, 100)  # Wilson 1927 / standard tables: 0.9300 .. 0.9945
    assert lo == pytest.approx(0.9300, abs=5e-4)
    assert hi == pytest.approx(0.9945, abs=5e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_records_do_not_depend_on_workers(tmp_path: Path) -> None:
    spec = RunSpec(scene="paper", overrides=ORACLE)
    one = run_batch(spec, [3, SEED], workers=1)
    two = run_batch(spec, [SEED, 3], workers=2)
    assert [r.seed for r in one] == [SEED, 3]
    assert [_strip(r.as_dict()) for r in one] == [_strip(r.as_dict()) for r in two]


def test_cli_run_writes_results_and_replay_writes_video(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    assert main(["run", "--scene", "paper", "--seeds", str(SEED), "--detector", "oracle",
                 "--out", str(out), "--quiet"]) == 0
    lines = (out / "results.jsonl").read_text().splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["seed"] == SEED
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == 1 and len(summary["success_ci95"]) == 2
    assert "Table 1" in (out / "summary.md").read_text()
    ep = out / "episodes" / str(SEED)
    assert (ep / "scene.xml").read_text().startswith("<mujoco")
    final = np.load(ep / "final_qpos.npy")
    video = tmp_path / "replay.mp4"
    assert main(["replay", str(out), str(SEED), "--video", str(video)]) == 0
    assert video.stat().st_size > 10_000
    report = capsys.readouterr().out
    assert "final max |dq| 0" in report  # the replay ends in the recorded state
    assert final.shape[0] > 7


def test_public_names_exist() -> None:
    import stackpick_sim.episodes as episodes

    assert all(hasattr(episodes, name) for name in episodes.__all__)

"""Replay re-runs an episode with the stages its record names, and stops with one line when
one of them does not load here."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.runs.replay import recorded_stages


def _run_dir(tmp_path: Path, detector: str) -> Path:
    (tmp_path / "run.json").write_text(json.dumps({"scene": "paper", "overrides": []}))
    rec = EpisodeRecord(seed=4, scene="paper", detector=detector, estimator="belt",
                        controller="ibvs", tracker_frame="belt", belt_speed=0.1,
                        failure="timeout")
    (tmp_path / "results.jsonl").write_text(json.dumps(rec.as_dict()) + "\n")
    return tmp_path


def test_replay_takes_the_recorded_stages() -> None:
    rec = EpisodeRecord(seed=4, scene="paper", detector="oracle", estimator="belt",
                        controller="ibvs", tracker_frame="belt", belt_speed=0.1)
    assert recorded_stages(rec) == ["episode.detector=oracle", "episode.estimator=belt",
                                    "episode.controller=ibvs"]
    older = EpisodeRecord(seed=4, scene="paper", detector="ours", tracker_frame="belt",
                          belt_speed=0.1)  # a record without estimator and controller names
    assert recorded_stages(older) == ["episode.detector=ours"]


def test_replay_stops_in_one_line_on_a_stage_it_cannot_load(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _run_dir(tmp_path, "nosuch_pkg.detect:Mine")
    assert main(["replay", str(out), "4", "--video", str(tmp_path / "v.mp4")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "cannot replay seed 4" in err and "nosuch_pkg.detect:Mine" in err

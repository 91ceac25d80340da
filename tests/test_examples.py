"""The examples run: the Hough plug-in detector through `stackpick run` (records identical for
one and two workers), the Gymnasium policies."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.episodes.record import WALL_CLOCK_KEYS

REPO = Path(__file__).resolve().parents[1]
HOUGH = "examples.hough_detector:HoughDetector"


def _records(out: Path) -> dict[int, dict]:
    recs = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    return {r["seed"]: {k: v for k, v in r.items() if k not in WALL_CLOCK_KEYS} for r in recs}


def test_hough_plugin_runs_in_workers_from_the_repository_root(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    for workers in (1, 2):
        assert main(["run", "--scene", "paper", "--seeds", "0:2", "--detector", HOUGH,
                     "--workers", str(workers), "--quiet", "--out",
                     str(tmp_path / f"w{workers}")]) == 0
    one, two = _records(tmp_path / "w1"), _records(tmp_path / "w2")
    assert one == two and sorted(one) == [0, 1]
    for rec in one.values():
        assert rec["detector"] == HOUGH and rec["stage_versions"] == {"detector": "1.0"}
        assert rec["failure"] != "error", rec["failure_detail"]
    assert any(rec["success"] for rec in one.values())


def test_gym_policy_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("gymnasium")
    module = runpy.run_path(str(REPO / "examples" / "gym_policy.py"))
    assert module["main"](["--seeds", "1:2", "--step", "tick"]) == 0
    out = capsys.readouterr().out
    assert "reference seed 1: reward 1" in out and "random    seed 1: reward 0" in out


def test_bench_detect_takes_a_plugin_detector(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(REPO)
    assert main(["bench-detect", "--scene", "paper", "--seeds", "1:3", "--quiet", "--methods",
                 f"ours,{HOUGH}", "--out", str(tmp_path)]) == 0
    methods = json.loads((tmp_path / "results.json").read_text())["methods"]
    assert list(methods) == ["ours", HOUGH]
    assert main(["bench-detect", "--scene", "paper", "--seeds", "1", "--methods", "hogh",
                 "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown detector 'hogh'" in err and "edgedrawing" in err

"""The run/sweep/report/check commands: resume, lock, refusal to overwrite, a sweep with
its report and plots, the regression gate's exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.runs import RunLock

ORACLE = ["--scene", "paper", "--detector", "oracle", "--quiet", "--workers", "2"]


def _seeds(out: Path) -> list[int]:
    return [json.loads(x)["seed"] for x in (out / "results.jsonl").read_text().splitlines()]


def test_run_resume_adds_only_missing_seeds_and_refuses_to_overwrite(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert main(["run", *ORACLE, "--seeds", "3", "--out", str(out)]) == 0
    first = (out / "results.jsonl").read_text()
    (out / "results.jsonl").write_text('{"seed": 1}\n' + first)  # a stub is not a record
    assert main(["run", *ORACLE, "--seeds", "1,3", "--out", str(out), "--resume"]) == 0
    assert _seeds(out) == [1, 3]
    assert first.strip() in (out / "results.jsonl").read_text()  # seed 3 was not re-run
    io = capsys.readouterr()
    assert "ran 1 episodes (1 already recorded)" in io.out
    assert "dropped 1 record (seed 1): missing field 'scene'" in io.err
    assert main(["run", *ORACLE, "--seeds", "1", "--out", str(out), "--resume"]) == 2
    assert "seeds outside --seeds: 3" in capsys.readouterr().err
    assert main(["run", *ORACLE, "--seeds", "1", "--out", str(out)]) == 2
    assert "pass --resume" in capsys.readouterr().err
    assert main(["run", *ORACLE, "--seeds", "1", "--out", str(out), "--resume",
                 "--set", "conveyor.speed=0.2"]) == 2
    assert "--resume must use the same" in capsys.readouterr().err


def test_run_on_a_locked_directory_says_who_holds_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with RunLock(tmp_path):
        assert main(["run", *ORACLE, "--seeds", "1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "being written by another stackpick run" in err and "pid" in err


def test_sweep_then_report_then_check(tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sweep"
    assert main(["sweep", *ORACLE, "--param", "conveyor.speed=0.1,0.2", "--seeds", "1",
                 "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| conveyor.speed | episodes | success | 95 % Wilson CI |" in table
    rows = json.loads((out / "sweep_summary.json").read_text())
    assert [r["settings"]["conveyor.speed"] for r in rows] == ["0.1", "0.2"]
    cell = out / "cells" / "conveyor.speed=0.2"
    assert json.loads((cell / "results.jsonl").read_text())["belt_speed"] == 0.2
    assert main(["report", str(out)]) == 0
    report = (out / "report.md").read_text()
    for png in ("success_vs_param.png", "failure_reasons.png", "errors.png",
                "cycle_time.png"):
        data = (out / png).read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 2_000 and f"({png})" in report
    assert "Table 1" in report and "Table 2" in report
    assert main(["check", str(cell), "--baseline", str(cell / "summary.json")]) == 0
    assert "check: PASS" in capsys.readouterr().out
    strong = tmp_path / "strong.json"
    strong.write_text(json.dumps({"successes": 40, "episodes": 40}))
    failing = tmp_path / "failing"
    assert main(["run", *ORACLE, "--seeds", "1,3", "--set", "episode.timeout_approach=0",
                 "--out", str(failing)]) == 0
    assert main(["check", str(failing), "--baseline", str(strong)]) == 1
    assert "check: FAIL" in capsys.readouterr().out


def test_sweep_with_an_unknown_key_names_the_known_ones(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", *ORACLE, "--param", "conveyer.speed=0.1", "--seeds", "1",
                 "--out", str(tmp_path / "s")]) == 2
    assert "conveyer.speed" in capsys.readouterr().err

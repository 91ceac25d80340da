"""Bad run directories, records and baselines: each ends in a result or one clear line and
exit code 2, never a traceback, a silently kept bad record or a made-up number."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from runs_fakes import fake_record, fake_task

from stackpick_sim.cli.main import main
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs import InlineExecutor, RunJob, RunSpec, read_records, run_dirs
from stackpick_sim.runs.check import fisher_less

SPEC = RunSpec(scene="paper", overrides=("episode.detector=oracle",))
SEEDS = list(range(6))


def _run(out: Path, seeds: list[int] = SEEDS, *, resume: bool = False) -> None:
    run_dirs([RunJob(key="k", spec=SPEC, seeds=seeds, out=out)],
             InlineExecutor(task_fn=fake_task), resume=resume, show_progress=False)


def _lines(out: Path) -> list[str]:
    return (out / "results.jsonl").read_text().splitlines()


def _write_lines(out: Path, lines: list[str]) -> None:
    (out / "results.jsonl").write_text("".join(line + "\n" for line in lines))


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    return err


# --- resume keeps only valid records of the run's seeds -------------------------------------

def test_resume_drops_a_stub_record_says_so_and_runs_its_seed_again(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _run(tmp_path)
    lines = _lines(tmp_path)
    lines[2] = json.dumps({"seed": 2})
    _write_lines(tmp_path, lines)
    _run(tmp_path, resume=True)
    records, _, _ = read_records(tmp_path / "results.jsonl")
    assert sorted(records) == SEEDS
    assert records[2] == fake_record(2)
    err = capsys.readouterr().err
    assert "dropped 1 record" in err and "seed 2" in err
    assert json.dumps({"seed": 2}) in (tmp_path / "run.log").read_text()  # kept for audit


@pytest.mark.parametrize("bad", [
    {"seed": -3},  # a negative seed
    {"seed": True},  # a boolean is not a seed
    {"success": "maybe"},  # not a boolean
    {"failure": "gremlins"},  # not a failure reason
    {"success": True, "failure": "dropped"},  # a success has no failure reason
    {"surprise": 1},  # not a field of the schema
])
def test_resume_drops_records_that_break_the_schema(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], bad: dict) -> None:
    _run(tmp_path)
    lines = _lines(tmp_path)
    lines[3] = json.dumps({**json.loads(lines[3]), **bad})
    _write_lines(tmp_path, lines)
    _run(tmp_path, resume=True)
    records, _, _ = read_records(tmp_path / "results.jsonl")
    assert sorted(records) == SEEDS
    assert all(records[s] == fake_record(s) for s in SEEDS)
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "dropped 1 record" in err


def test_resume_refuses_records_of_a_newer_schema(tmp_path: Path) -> None:
    _run(tmp_path)
    lines = _lines(tmp_path)
    lines[3] = json.dumps({**json.loads(lines[3]), "schema_version": 999})
    _write_lines(tmp_path, lines)
    with pytest.raises(StackpickError, match="newer"):
        _run(tmp_path, resume=True)


def test_resume_refuses_records_of_seeds_outside_the_run(tmp_path: Path) -> None:
    _run(tmp_path, list(range(7)))
    with pytest.raises(StackpickError, match="seeds outside"):
        _run(tmp_path, SEEDS, resume=True)
    assert len(_lines(tmp_path)) == 7  # nothing recorded was thrown away


@pytest.mark.parametrize("text", ["{not json", "{}", "[1, 2]", '{"scene": 3}',
                                  '{"scene": "paper", "overrides": [1]}', "\udcff"])
def test_resume_with_a_corrupt_run_json_is_one_clear_error(tmp_path: Path, text: str) -> None:
    _run(tmp_path)
    (tmp_path / "run.json").write_bytes(text.encode("utf-8", "surrogateescape"))
    with pytest.raises(StackpickError, match=r"run\.json"):
        _run(tmp_path, resume=True)


# --- replay checks its inputs before it runs anything --------------------------------------

def _replay_dir(tmp_path: Path) -> Path:
    """A run directory of two recorded seeds with audit files, built without episodes."""
    out = tmp_path / "run"
    _run(out, [1, 2])
    for seed in (1, 2):
        d = out / "episodes" / str(seed)
        np.save(d / "initial_qpos.npy", np.zeros(7))
        np.save(d / "final_qpos.npy", np.zeros(7))
    return out


def _replay(out: Path, seed: int, tmp_path: Path) -> int:
    return main(["replay", str(out), str(seed), "--video", str(tmp_path / "v.mp4")])


def test_replay_of_a_seed_the_run_never_had(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = _replay_dir(tmp_path)
    assert _replay(out, 9, tmp_path) == 2
    assert "seed 9" in _one_error_line(capsys)


@pytest.mark.parametrize("name", ["initial_qpos.npy", "final_qpos.npy"])
def test_replay_without_its_audit_files(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        name: str) -> None:
    out = _replay_dir(tmp_path)
    (out / "episodes" / "1" / name).unlink()
    assert _replay(out, 1, tmp_path) == 2
    assert name in _one_error_line(capsys)


@pytest.mark.parametrize("data", [
    b"", b"\x93NUMPY garbage", "pickle", "object", "2d",
    # a header whose text cannot be tokenised (numpy raises tokenize.TokenError)
    b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': (7,), }" + b" " * 60,
])
def test_replay_with_a_corrupt_initial_state(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str],
                                             data: bytes | str) -> None:
    out = _replay_dir(tmp_path)
    path = out / "episodes" / "1" / "initial_qpos.npy"
    if data == "pickle":
        buf = io.BytesIO()
        np.save(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        path.write_bytes(buf.getvalue())
    elif data == "object":
        np.save(path, np.array(["x", "y"]))
    elif data == "2d":
        np.save(path, np.zeros((2, 3)))
    else:
        assert isinstance(data, bytes)
        path.write_bytes(data)
    assert _replay(out, 1, tmp_path) == 2
    assert "initial_qpos.npy" in _one_error_line(capsys)


@pytest.mark.parametrize("text", [
    "{not json", "[]",
    # a cell name that would leave the sweep directory
    json.dumps({"scene": "paper", "overrides": [], "params": {"a": ["1"]}, "seeds": [0],
                "cells": {"..": ["a=1"]}})])
def test_report_of_a_sweep_with_a_corrupt_sweep_json(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str) -> None:
    (tmp_path / "sweep.json").write_text(text)
    assert main(["report", str(tmp_path)]) == 2
    assert "sweep.json" in _one_error_line(capsys)


@pytest.mark.parametrize("text", ["{not json", "{}", "[1, 2]"])
def test_replay_with_a_corrupt_run_json(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        text: str) -> None:
    out = _replay_dir(tmp_path)
    (out / "run.json").write_text(text)
    assert _replay(out, 1, tmp_path) == 2
    assert "run.json" in _one_error_line(capsys)


def test_replay_with_run_json_edited_to_another_scene(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _replay_dir(tmp_path)
    (out / "run.json").write_text(json.dumps({"scene": "cluttered", "overrides": []}))
    assert _replay(out, 1, tmp_path) == 2
    assert "cluttered" in _one_error_line(capsys)


def test_replay_of_a_seed_whose_scene_could_not_be_built(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _replay_dir(tmp_path)
    _write_lines(out, [_lines(out)[0], json.dumps({"seed": 2, "scene": "paper",
                                                   "error": "no pile"})])
    assert _replay(out, 2, tmp_path) == 2
    assert "no pile" in _one_error_line(capsys)


# --- check refuses bad baselines with one line ---------------------------------------------

GOOD = {"episodes": 40, "successes": 38, "detection": {"center_error_px": {"median": 1.0}}}


def _baseline_cases() -> list[tuple[str, bytes]]:
    def js(value: object) -> bytes:
        return json.dumps(value).encode()

    return [
        ("null", b"null"), ("number", b"42"), ("string", js("summary")),
        ("successes string", js({**GOOD, "successes": "x"})),
        ("successes null", js({**GOOD, "successes": None})),
        ("fractional", js({**GOOD, "successes": 1.5})),
        ("boolean", js({**GOOD, "episodes": True, "successes": True})),
        ("more successes than episodes", js({**GOOD, "successes": 41})),
        ("no episodes", js({**GOOD, "episodes": 0, "successes": 0})),
        ("median string", js({**GOOD, "detection": {"center_error_px": {"median": "1"}}})),
        ("median list", js({**GOOD, "detection": {"center_error_px": {"median": [1]}}})),
        ("median nan", b'{"episodes": 4, "successes": 4, "cycle_time_s": {"median": NaN}}'),
        ("detection list", js({**GOOD, "detection": [1]})),
        ("binary", bytes(range(256))),
        ("utf-16", json.dumps(GOOD).encode("utf-16")),
        ("deep array", b"[" * 100_000 + b"]" * 100_000),
    ]


@pytest.mark.parametrize(("name", "data"), _baseline_cases(),
                         ids=[n for n, _ in _baseline_cases()])
def test_check_refuses_a_bad_baseline_with_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, data: bytes) -> None:
    current = tmp_path / "current.json"
    current.write_text(json.dumps(GOOD))
    baseline = tmp_path / "baseline.json"
    baseline.write_bytes(data)
    assert main(["check", str(current), "--baseline", str(baseline)]) == 2
    assert "baseline.json" in _one_error_line(capsys)


def test_check_refuses_a_run_directory_holding_a_stub_record(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _run(tmp_path / "base")
    lines = _lines(tmp_path / "base")
    lines[1] = json.dumps({"seed": 1})
    _write_lines(tmp_path / "base", lines)
    current = tmp_path / "current.json"
    current.write_text(json.dumps(GOOD))
    assert main(["check", str(current), "--baseline", str(tmp_path / "base")]) == 2
    assert "line 2" in _one_error_line(capsys)


@pytest.mark.parametrize("tolerance", ["inf", "nan", "-0.1"])
def test_check_refuses_a_tolerance_that_is_not_a_finite_share(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], tolerance: str) -> None:
    current = tmp_path / "current.json"
    current.write_text(json.dumps(GOOD))
    assert main(["check", str(current), "--baseline", str(current),
                 f"--tolerance={tolerance}"]) == 2
    assert "tolerance" in _one_error_line(capsys)


def test_fisher_on_a_hundred_thousand_episodes_matches_the_normal_approximation() -> None:
    # 90.0 % vs 90.3 % of 100,000 each: z = -2.24 by the pooled two-proportion z-test.
    k1, k2, n = 90_000, 90_300, 100_000
    pooled = (k1 + k2) / (2 * n)
    z = (k1 / n - k2 / n) / math.sqrt(pooled * (1 - pooled) * 2 / n)
    normal = 0.5 * math.erfc(-z / math.sqrt(2))
    assert fisher_less(k1, n, k2, n) == pytest.approx(normal, rel=0.05)

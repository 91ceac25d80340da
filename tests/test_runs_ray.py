"""The Ray backend against a local Ray instance started here: the same records as the local
backend for the same seeds; a crashing or raising task is a failed record, not a crash."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
import ray
from runs_fakes import CRASH_SEED, RAISE_SEED, fake_record, fake_task

from stackpick_sim.episodes.record import WALL_CLOCK_KEYS, EpisodeRecord, Record
from stackpick_sim.runs import RunJob, RunSpec, read_records, run_batch, run_dirs
from stackpick_sim.runs.ray_backend import RayExecutor

SPEC = RunSpec(scene="paper", overrides=("episode.detector=oracle",))
#: CPUs of the test's Ray instance (the machine has 2 cores).
RAY_CPUS = 2


@pytest.fixture(scope="module")
def local_ray() -> Iterator[None]:
    here = str(Path(__file__).parent)
    path = os.pathsep.join([here, os.environ.get("PYTHONPATH", "")])
    ray.init(num_cpus=RAY_CPUS, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": path, "MUJOCO_GL": "egl"}})
    yield
    ray.shutdown()


def _strip(rec: Record) -> dict:
    return {k: v for k, v in rec.as_dict().items() if k not in WALL_CLOCK_KEYS}


def test_ray_records_equal_local_records(local_ray: None) -> None:
    on_ray = run_batch(SPEC, [1, 3], backend="ray")
    local = run_batch(SPEC, [1, 3], workers=2)
    assert [r.seed for r in on_ray] == [1, 3]
    assert [_strip(r) for r in on_ray] == [_strip(r) for r in local]


def test_ray_crash_and_exception_are_failed_records(local_ray: None, tmp_path: Path) -> None:
    seeds = [1, CRASH_SEED, RAISE_SEED, 2]
    job = RunJob(key="k", spec=SPEC, seeds=seeds, out=tmp_path)
    run_dirs([job], RayExecutor(task_fn=fake_task), show_progress=False)
    records, _, _ = read_records(tmp_path / "results.jsonl")
    assert sorted(records) == sorted(seeds)
    assert records[CRASH_SEED].failure == "error"
    assert records[RAISE_SEED].failure == "error"
    assert records[1] == fake_record(1) and records[2] == fake_record(2)
    assert "scripted failure" in (tmp_path / "run.log").read_text()


def test_a_plugin_detector_loads_in_ray_workers(local_ray: None,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """`examples.hough_detector:HoughDetector` from the repository root: each Ray worker
    imports it (the driver's working directory travels with the task); same records as the
    local workers."""
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    spec = RunSpec(scene="paper",
                   overrides=("episode.detector=examples.hough_detector:HoughDetector",))
    on_ray = run_batch(spec, [2], backend="ray")
    local = run_batch(spec, [2], workers=1)
    rec = on_ray[0]
    assert isinstance(rec, EpisodeRecord)
    assert rec.detector == "examples.hough_detector:HoughDetector"
    assert rec.failure != "error", rec.failure_detail
    assert [_strip(r) for r in on_ray] == [_strip(r) for r in local]

"""Executors: crashes, hangs and exceptions become failed records and the run goes on;
records do not depend on workers or backend; a killed run resumes to one record per seed."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from runs_fakes import CRASH_SEED, HANG_SEED, RAISE_SEED, fake_record, fake_task

from stackpick_sim.episodes.record import WALL_CLOCK_KEYS, Record
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs import LocalExecutor, RunJob, RunSpec, read_records, run_batch, run_dirs
from stackpick_sim.runs.local import InlineExecutor
from stackpick_sim.runs.tasks import EpisodeTask, TaskResult

SPEC = RunSpec(scene="paper", overrides=("episode.detector=oracle",))
#: Episode time-out of the hang test, s: long enough for a worker to start on a busy machine.
HANG_TIMEOUT_S = 20.0
#: Seeds of the kill/resume driver: none of the scripted crash/hang/raise seeds.
KILL_SEEDS = list(range(20, 60))
#: Kill/resume trials of the fast fake run (benchmarks/bench_runs.py kill does 20 real ones).
KILL_TRIALS = 3


def _strip(rec: Record) -> dict:
    return {k: v for k, v in rec.as_dict().items() if k not in WALL_CLOCK_KEYS}


def test_crash_hang_and_exception_are_failed_records_and_the_run_goes_on(tmp_path: Path) -> None:
    seeds = [1, 2, CRASH_SEED, HANG_SEED, RAISE_SEED, 16, 17]
    job = RunJob(key="k", spec=SPEC, seeds=seeds, out=tmp_path)
    ex = LocalExecutor(2, episode_timeout=HANG_TIMEOUT_S, task_fn=fake_task)
    stats = run_dirs([job], ex, show_progress=False)
    records, _, _ = read_records(tmp_path / "results.jsonl")
    assert sorted(records) == seeds and stats.ran == len(seeds)
    assert records[CRASH_SEED].failure == "error"
    assert "SIGKILL" in records[CRASH_SEED].failure_detail
    assert records[HANG_SEED].failure == "timeout"
    assert records[RAISE_SEED].failure == "error"
    for s in (1, 2, 16, 17):
        assert records[s] == fake_record(s)
    log = (tmp_path / "run.log").read_text()
    assert "RuntimeError: scripted failure" in log and "Traceback" in log
    assert "exceeded --episode-timeout" in log
    assert (tmp_path / "episodes" / "16" / "note.txt").read_text() == "seed 16"
    assert stats.summaries["k"]["failures"]["error"] == 2


def test_records_identical_across_workers_and_inline() -> None:
    inline = run_batch(SPEC, [1, 3], backend="inline")
    one = run_batch(SPEC, [3, 1], workers=1)
    two = run_batch(SPEC, [1, 3], workers=2)
    assert [r.seed for r in inline] == [1, 3]
    assert [_strip(r) for r in inline] == [_strip(r) for r in one] == [_strip(r) for r in two]


DRIVER = """
import sys
from pathlib import Path
from runs_fakes import fake_task
from stackpick_sim.runs import LocalExecutor, RunJob, RunSpec, run_dirs
job = RunJob(key="k", spec=RunSpec(scene="paper"), seeds=range(20, 60), out=Path(sys.argv[1]))
run_dirs([job], LocalExecutor(2, task_fn=fake_task), resume=True, show_progress=False)
"""


def test_sigkill_at_random_moments_then_resume_gives_one_record_per_seed(
        tmp_path: Path) -> None:
    rng = random.Random(7)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent),
                                                        *sys.path])}
    for trial in range(KILL_TRIALS):
        out = tmp_path / f"t{trial}"
        proc = subprocess.Popen([sys.executable, "-c", DRIVER, str(out)], env=env,
                                start_new_session=True)
        time.sleep(rng.uniform(2.0, 4.0))  # worker start-up ~1-3 s, then 40 x 0.05 s / 2
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        killed_at = len(read_records(out / "results.jsonl")[0])
        subprocess.run([sys.executable, "-c", DRIVER, str(out)], env=env, check=True)
        lines = (out / "results.jsonl").read_text().splitlines()
        seeds = [json.loads(x)["seed"] for x in lines]
        assert seeds == KILL_SEEDS, f"trial {trial}, killed after {killed_at} records"


def test_bad_worker_count_and_timeout_say_what_is_allowed() -> None:
    with pytest.raises(Exception, match="--workers must be >= 1; got 0"):
        LocalExecutor(0)
    with pytest.raises(Exception, match="--episode-timeout must be > 0 s; got -1"):
        LocalExecutor(1, episode_timeout=-1)


#: A finished episode whose own phase ran past its sim-time limit: not to be run again.
PHASE_TIMEOUT_SEED = 4


def _flaky_then_fixed(broken: bool):
    def task_fn(task: EpisodeTask) -> TaskResult:
        if task.seed == RAISE_SEED and broken:
            raise RuntimeError("scripted failure")
        if task.seed == PHASE_TIMEOUT_SEED:
            rec = replace(fake_record(task.seed), success=False, failure="timeout",
                          failed_phase="descend")
            return TaskResult(task=task, record=rec)
        return TaskResult(task=task, record=fake_record(task.seed))
    return task_fn


def test_retry_unfinished_runs_only_crashed_episodes_again(tmp_path: Path) -> None:
    seeds = [1, 3, PHASE_TIMEOUT_SEED, RAISE_SEED]
    job = RunJob(key="k", spec=SPEC, seeds=seeds, out=tmp_path)
    run_dirs([job], InlineExecutor(task_fn=_flaky_then_fixed(True)), show_progress=False)
    first, _, _ = read_records(tmp_path / "results.jsonl")
    assert first[RAISE_SEED].failure == "error"
    # a plain resume keeps the error record ...
    stats = run_dirs([job], InlineExecutor(task_fn=_flaky_then_fixed(False)), resume=True,
                     show_progress=False)
    assert stats.ran == 0
    # ... --retry-unfinished runs that seed again, and only that one
    stats = run_dirs([job], InlineExecutor(task_fn=_flaky_then_fixed(False)), resume=True,
                     retry_unfinished=True, show_progress=False)
    records, _, _ = read_records(tmp_path / "results.jsonl")
    assert stats.ran == 1 and stats.skipped == 3
    assert sorted(records) == seeds
    assert records[RAISE_SEED] == fake_record(RAISE_SEED)
    assert records[PHASE_TIMEOUT_SEED].failure == "timeout"
    assert {s: records[s] for s in (1, 3)} == {s: first[s] for s in (1, 3)}
    assert f"retry: dropped 1 unfinished episodes to run again: seeds {RAISE_SEED}" in \
        (tmp_path / "run.log").read_text()


def test_retry_unfinished_needs_resume(tmp_path: Path) -> None:
    job = RunJob(key="k", spec=SPEC, seeds=[1], out=tmp_path)
    with pytest.raises(StackpickError, match="--retry-unfinished needs --resume"):
        run_dirs([job], InlineExecutor(task_fn=_flaky_then_fixed(False)),
                 retry_unfinished=True, show_progress=False)

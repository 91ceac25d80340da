"""Runs at scale: batches, local or Ray workers, a durable journal with resume, a lock per
directory, parameter sweeps, replays, reports and the CI regression check.

This package builds on :mod:`stackpick_sim.episodes` (the episode, its record and summary),
which never imports it.
"""

from stackpick_sim.runs.batch import run_batch, run_seed, write_outputs
from stackpick_sim.runs.journal import Journal, JournalError, read_records
from stackpick_sim.runs.local import InlineExecutor, LocalExecutor
from stackpick_sim.runs.lock import LockError, RunLock
from stackpick_sim.runs.rundir import RunDir
from stackpick_sim.runs.runner import BACKENDS, RunJob, RunStats, make_executor, run_dirs
from stackpick_sim.runs.spec import RunSpec, episode_dir
from stackpick_sim.runs.tasks import EpisodeTask, TaskResult, failure_record, run_task

__all__ = [
    "BACKENDS",
    "EpisodeTask",
    "InlineExecutor",
    "Journal",
    "JournalError",
    "LocalExecutor",
    "LockError",
    "RunDir",
    "RunJob",
    "RunLock",
    "RunSpec",
    "RunStats",
    "TaskResult",
    "episode_dir",
    "failure_record",
    "make_executor",
    "read_records",
    "run_batch",
    "run_dirs",
    "run_seed",
    "run_task",
    "write_outputs",
]

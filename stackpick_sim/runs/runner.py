"""Drive a set of run directories through one executor: stream, journal, summarise.

:func:`run_dirs` is what ``stackpick run`` and ``stackpick sweep`` do: open (lock) every
directory, skip the seeds already recorded there (``resume``), hand the rest to the
executor as one stream of tasks, write each result the moment it arrives, and at the end
order each journal and write its summaries. A run interrupted by Ctrl-C or an error still
leaves every finished record on disk.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.record import Record, episodes_of
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.local import InlineExecutor, LocalExecutor
from stackpick_sim.runs.progress import Progress
from stackpick_sim.runs.rundir import RunDir
from stackpick_sim.runs.spec import RunSpec
from stackpick_sim.runs.tasks import EpisodeTask, TaskFn, TaskResult, run_task

Backend = Literal["local", "ray", "inline"]
#: The executors: local processes, a Ray cluster, or this process (tests, debugging).
BACKENDS: tuple[str, ...] = ("local", "ray", "inline")


class Executor(Protocol):
    """Runs tasks somewhere and yields their results as they finish."""

    def map(self, tasks: Sequence[EpisodeTask]) -> Iterator[TaskResult]: ...

    def close(self) -> None: ...


def default_workers() -> int:
    """All the cores this process may use."""
    return len(os.sched_getaffinity(0))


def make_executor(backend: str, *, workers: int | None = None, address: str | None = None,
                  episode_timeout: float | None = None, task_fn: TaskFn = run_task) -> Executor:
    """The executor for ``backend`` (one of :data:`BACKENDS`)."""
    if backend == "local":
        return LocalExecutor(workers or default_workers(), episode_timeout=episode_timeout,
                             task_fn=task_fn)
    if backend == "ray":
        from stackpick_sim.runs.ray_backend import RayExecutor

        return RayExecutor(address=address, episode_timeout=episode_timeout, task_fn=task_fn,
                           num_cpus=workers)
    if backend == "inline":
        return InlineExecutor(task_fn=task_fn)
    raise StackpickError(f"unknown backend {backend!r}; known: {', '.join(BACKENDS)}")


@dataclass(frozen=True, kw_only=True)
class RunJob:
    """Seeds of one spec, written to ``out`` (``key`` tells the results apart in a sweep)."""

    key: str
    spec: RunSpec
    seeds: Sequence[int]
    out: Path


@dataclass(frozen=True, kw_only=True)
class RunStats:
    """What one call of :func:`run_dirs` did."""

    ran: int
    """Episodes run now."""
    skipped: int
    """Seeds skipped because already recorded (resume)."""
    wall_s: float
    summaries: dict[str, dict[str, Any]]
    """Summary of each job by key (every record of its directory)."""

    @property
    def episodes_per_s(self) -> float:
        """Throughput of this call, episodes per wall-clock second."""
        return self.ran / self.wall_s if self.wall_s > 0 else 0.0


def _open_dirs(jobs: Sequence[RunJob], dirs: dict[str, RunDir], *, resume: bool,
               retry_unfinished: bool) -> None:
    """Open (lock) each job's directory into ``dirs``; on resume, check and clean its records:
    refuse seeds outside the job's, say what invalid records were dropped, drop the
    unfinished ones with ``retry_unfinished``."""
    for job in jobs:
        load_scene(job.spec.scene, job.spec.overrides)  # fail early, here, on bad config
    for job in jobs:
        d = dirs[job.key] = RunDir(job.out, job.spec, resume=resume)
        d.refuse_foreign(list(job.seeds))
        for note in d.drop_notes():
            print(note, file=sys.stderr)
        if retry_unfinished:
            d.discard_unfinished(list(job.seeds))


def _progress(dirs: dict[str, RunDir], todo: int, enabled: bool) -> Progress:
    done = [r for d in dirs.values() for r in d.journal.records.values()]
    episodes = episodes_of(done)
    return Progress(todo + len(done), done=len(done), episodes=len(episodes),
                    successes=sum(r.success for r in episodes), enabled=enabled)


def run_dirs(jobs: Sequence[RunJob], executor: Executor, *, resume: bool = False,
             retry_unfinished: bool = False, show_progress: bool = True,
             on_record: Callable[[Record, Progress], None] | None = None) -> RunStats:
    """Run every job through ``executor`` (closed at the end); see the module docstring.

    With ``retry_unfinished`` (needs ``resume``), recorded episodes that did not finish
    (reason ``error`` or ``timeout`` from a worker crash or the wall-clock limit) run again.
    """
    dirs: dict[str, RunDir] = {}
    try:
        if retry_unfinished and not resume:
            raise StackpickError("--retry-unfinished needs --resume (it runs again recorded "
                                 "episodes that did not finish)")
        _open_dirs(jobs, dirs, resume=resume, retry_unfinished=retry_unfinished)
        tasks = [EpisodeTask(spec=job.spec, seed=s, key=job.key)
                 for job in jobs for s in dirs[job.key].missing(list(job.seeds))]
        skipped = sum(len(d.journal.records) for d in dirs.values())
        progress = _progress(dirs, len(tasks), show_progress)
        for d in dirs.values():
            d.log(f"start: {len(d.journal.records)} recorded, backend "
                  f"{type(executor).__name__}, pid {os.getpid()}")
        t0 = time.perf_counter()
        ran = 0
        try:
            for result in executor.map(tasks):
                dirs[result.task.key].add(result)
                ran += 1
                progress.update(result.record)
                if on_record is not None:
                    on_record(result.record, progress)
        finally:
            progress.close()
        wall = time.perf_counter() - t0
        summaries = {}
        for key, d in dirs.items():
            d.log(f"end: ran {ran} episodes in {wall:.1f} s")
            summaries[key] = d.finish()
        return RunStats(ran=ran, skipped=skipped, wall_s=wall, summaries=summaries)
    finally:
        executor.close()
        for d in dirs.values():
            d.close()

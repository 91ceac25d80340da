"""Run episodes for many seeds from Python: records in seed order, optionally a run directory.

The machinery (worker processes or Ray, the durable journal, resume, the lock) is
:func:`stackpick_sim.runs.runner.run_dirs`; the output directory layout is in
:mod:`stackpick_sim.runs.rundir`. Records do not depend on the number of workers or the
backend (except their wall times); ``results.jsonl`` ends in seed order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from stackpick_sim.episodes.record import Record
from stackpick_sim.episodes.schema import record_to_json
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.runs.journal import read_records
from stackpick_sim.runs.rundir import write_summaries
from stackpick_sim.runs.runner import RunJob, make_executor, run_dirs
from stackpick_sim.runs.spec import RunSpec
from stackpick_sim.runs.tasks import EpisodeTask, run_task


def run_seed(spec: RunSpec, seed: int) -> Record:
    """One episode (pile + pick) in this process, as a record (no files written)."""
    return run_task(EpisodeTask(spec=spec, seed=seed)).record


def run_batch(spec: RunSpec, seeds: Sequence[int], *, workers: int = 1, out: Path | None = None,
              progress: Callable[[Record], None] | None = None,
              backend: str = "local", address: str | None = None, resume: bool = False,
              episode_timeout: float | None = None,
              show_progress: bool = False) -> list[Record]:
    """Records of ``seeds`` in seed order; with ``out``, also every file of the layout.

    ``backend``: ``local`` (``workers`` processes), ``ray`` (``address``, see
    :mod:`stackpick_sim.runs.ray_backend`) or ``inline`` (this process). ``resume`` keeps
    the records already in ``out`` and runs only the missing seeds.
    """
    if workers < 1:
        raise EpisodeError(f"workers must be >= 1; got {workers}")
    executor = make_executor(backend, workers=workers, address=address,
                             episode_timeout=episode_timeout)
    if out is None:
        try:
            tasks = [EpisodeTask(spec=spec, seed=s) for s in sorted(set(seeds))]
            records = {r.task.seed: r.record for r in executor.map(tasks)}
        finally:
            executor.close()
        ordered = [records[s] for s in sorted(records)]
        if progress is not None:
            for rec in ordered:
                progress(rec)
        return ordered

    def hook(rec: Record, _bar: object) -> None:
        if progress is not None:
            progress(rec)

    job = RunJob(key="", spec=spec, seeds=seeds, out=out)
    run_dirs([job], executor, resume=resume, show_progress=show_progress, on_record=hook)
    records_by_seed, _, _ = read_records(out / "results.jsonl")
    return [records_by_seed[s] for s in sorted(records_by_seed)]


def write_outputs(out: Path, records: Sequence[Record]) -> dict[str, Any]:
    """Write results.jsonl (seed order), summary.json and summary.md; returns the summary."""
    ordered = sorted(records, key=lambda r: r.seed)
    with (out / "results.jsonl").open("w") as fh:
        for rec in ordered:
            fh.write(record_to_json(rec) + "\n")
    return write_summaries(out, ordered)

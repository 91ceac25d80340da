"""Run episodes for many seeds and write their records and audit files.

The machinery (worker processes or Ray, the durable journal, resume, the lock) lives in
:mod:`stackpick_sim.runs`; this module keeps the batch entry point and the names replay
and older callers import. The output directory layout is in
:mod:`stackpick_sim.runs.rundir`. Records do not depend on the number of workers or the
backend (except their wall times); ``results.jsonl`` ends in seed order.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.runs.spec import RunSpec, episode_dir

# stackpick_sim.runs imports the episode modules, and this package's __init__ imports this
# module: the rest of stackpick_sim.runs is imported inside the functions to break the cycle.

__all__ = ["RunSpec", "episode_dir", "run_batch", "run_seed", "write_outputs"]


def run_seed(spec: RunSpec, seed: int) -> dict[str, Any]:
    """One episode (pile + pick) in this process, as a record dict (no files written)."""
    from stackpick_sim.runs.tasks import EpisodeTask, run_task

    return run_task(EpisodeTask(spec=spec, seed=seed)).record


def run_batch(spec: RunSpec, seeds: Sequence[int], *, workers: int = 1, out: Path | None = None,
              progress: Callable[[dict[str, Any]], None] | None = None,
              backend: str = "local", address: str | None = None, resume: bool = False,
              episode_timeout: float | None = None,
              show_progress: bool = False) -> list[dict[str, Any]]:
    """Records of ``seeds`` in seed order; with ``out``, also every file of the layout.

    ``backend``: ``local`` (``workers`` processes), ``ray`` (``address``, see
    :mod:`stackpick_sim.runs.ray_backend`) or ``inline`` (this process). ``resume`` keeps
    the records already in ``out`` and runs only the missing seeds.
    """
    from stackpick_sim.runs.journal import read_records
    from stackpick_sim.runs.runner import RunJob, make_executor, run_dirs
    from stackpick_sim.runs.tasks import EpisodeTask

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

    def hook(rec: dict[str, Any], _bar: object) -> None:
        if progress is not None:
            progress(rec)

    job = RunJob(key="", spec=spec, seeds=seeds, out=out)
    run_dirs([job], executor, resume=resume, show_progress=show_progress, on_record=hook)
    records_by_seed, _, _ = read_records(out / "results.jsonl")
    return [records_by_seed[s] for s in sorted(records_by_seed)]


def write_outputs(out: Path, records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Write results.jsonl (seed order), summary.json and summary.md; returns the summary."""
    from stackpick_sim.runs.rundir import write_summaries

    ordered = sorted(records, key=lambda r: int(r["seed"]))
    with (out / "results.jsonl").open("w") as fh:
        for rec in ordered:
            fh.write(json.dumps(rec, sort_keys=True) + "\n")
    return write_summaries(out, list(ordered))

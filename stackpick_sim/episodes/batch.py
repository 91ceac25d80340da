"""Run episodes for many seeds, in parallel if asked, and write their records and audit files.

Output directory layout::

    DIR/run.json                 scene name/path and overrides (what replay re-runs)
    DIR/results.jsonl            one EpisodeRecord.as_dict() per line, in seed order
    DIR/summary.json, summary.md (stackpick_sim.episodes.summary)
    DIR/episodes/<seed>/scene.xml        the compiled scene (MJCF)
    DIR/episodes/<seed>/initial_qpos.npy the settled pile, (nq,) float64
    DIR/episodes/<seed>/final_qpos.npy   the state after verify, (nq,) float64

Workers are processes of the ``spawn`` context (MuJoCo and EGL contexts do not survive a
fork), one episode per task; results are collected in seed order, so the files do not
depend on the number of workers.
"""

from __future__ import annotations

import json
import multiprocessing
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.episode import run_episode
from stackpick_sim.episodes.summary import summarize, summary_markdown
from stackpick_sim.exceptions import EpisodeError, SceneGenerationError
from stackpick_sim.sim.stacks import generate_scene


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """What to run: a scene (name or .toml path) with ``--set`` overrides."""

    scene: str
    overrides: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (``run.json``)."""
        return {"scene": self.scene, "overrides": list(self.overrides)}

    @classmethod
    def from_dir(cls, out: Path) -> RunSpec:
        """The spec a batch in ``out`` was run with (its ``run.json``)."""
        path = out / "run.json"
        if not path.is_file():
            raise EpisodeError(f"{out} has no run.json; is it the --out of 'stackpick run'?")
        raw = json.loads(path.read_text())
        return cls(scene=str(raw["scene"]), overrides=tuple(raw["overrides"]))


def episode_dir(out: Path, seed: int) -> Path:
    """Where the audit files of ``seed`` go."""
    return out / "episodes" / str(seed)


def run_seed(spec: RunSpec, seed: int, out: Path | None) -> dict[str, Any]:
    """One episode (pile + pick) as a record dict; writes its audit files under ``out``."""
    cfg = load_scene(spec.scene, spec.overrides)
    try:
        scene = generate_scene(cfg, seed)
    except SceneGenerationError as exc:
        return {"seed": seed, "scene": cfg.name, "error": str(exc)}
    initial = scene.cell.data.qpos.copy()
    record = run_episode(scene)
    if out is not None:
        d = episode_dir(out, seed)
        d.mkdir(parents=True, exist_ok=True)
        (d / "scene.xml").write_text(scene.cell.spec_xml)
        np.save(d / "initial_qpos.npy", initial)
        np.save(d / "final_qpos.npy", scene.cell.data.qpos.copy())
    return record.as_dict()


def _task(args: tuple[RunSpec, int, str | None]) -> dict[str, Any]:
    spec, seed, out = args
    return run_seed(spec, seed, Path(out) if out is not None else None)


def run_batch(spec: RunSpec, seeds: Sequence[int], *, workers: int = 1, out: Path | None = None,
              progress: Callable[[dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """Records of ``seeds`` in seed order; with ``out``, also every file of the layout above."""
    if workers < 1:
        raise EpisodeError(f"workers must be >= 1; got {workers}")
    load_scene(spec.scene, spec.overrides)  # fail early, in this process, on a bad config
    ordered = sorted(set(seeds))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "run.json").write_text(json.dumps(spec.as_dict(), indent=1))
    tasks = [(spec, s, str(out) if out is not None else None) for s in ordered]
    records: list[dict[str, Any]] = []
    results: Iterable[dict[str, Any]]
    if workers == 1:
        results = map(_task, tasks)
        for rec in results:
            records.append(rec)
            if progress is not None:
                progress(rec)
    else:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            for rec in pool.imap(_task, tasks, chunksize=1):
                records.append(rec)
                if progress is not None:
                    progress(rec)
    if out is not None:
        write_outputs(out, records)
    return records


def write_outputs(out: Path, records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Write results.jsonl, summary.json and summary.md; returns the summary."""
    with (out / "results.jsonl").open("w") as fh:
        for rec in records:
            fh.write(json.dumps(rec, sort_keys=True) + "\n")
    summary = summarize(records)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "summary.md").write_text(summary_markdown(summary))
    return summary

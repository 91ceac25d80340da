"""One unit of work: an episode of one seed, run anywhere, returned with its audit files.

A worker (a local process or a Ray task) calls :func:`safe_call` on an :class:`EpisodeTask`
and sends back a :class:`TaskResult`: the record dict and the audit files as bytes. Only the
driver writes to the run directory, so the workers need no shared file system and a run
directory has one writer.

An exception inside an episode becomes a failed record with reason ``error`` and the
traceback in :attr:`TaskResult.log`; the run goes on.

The pipeline stages are named in the spec's overrides and loaded here, in the worker
(:mod:`stackpick_sim.registry`); ``module:attr`` stages are imported with the driver's
working directory on the import path (:attr:`EpisodeTask.import_paths`).
"""

from __future__ import annotations

import io
import os
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.episode import EpisodeRun, estimator_name
from stackpick_sim.episodes.record import ERROR_REASON, EpisodeRecord, Record, SceneErrorRecord
from stackpick_sim.exceptions import SceneGenerationError
from stackpick_sim.runs.spec import RunSpec
from stackpick_sim.sim.renderer_pool import enable_renderer_reuse
from stackpick_sim.sim.stacks import generate_scene

#: Failure reason of an episode that exceeded the wall-clock limit.
TIMEOUT_REASON = "timeout"


@dataclass(frozen=True, kw_only=True)
class EpisodeTask:
    """Run ``spec`` on ``seed``; ``key`` names the run directory it belongs to (sweeps)."""

    spec: RunSpec
    seed: int
    key: str = ""
    import_paths: tuple[str, ...] = field(default_factory=lambda: (os.getcwd(),))
    """Directories appended to the worker's import path (default: the driver's working
    directory, so that ``examples.x:Y`` stages load in every worker as in the driver)."""


@dataclass(kw_only=True)
class TaskResult:
    """A finished task: its record, audit files (name -> bytes) and log text."""

    task: EpisodeTask
    record: Record
    audit: dict[str, bytes] = field(default_factory=dict)
    log: str = ""
    worker: str = ""
    """Where it ran: ``host:pid``."""


#: What a worker calls; must be a picklable module-level function.
TaskFn = Callable[[EpisodeTask], TaskResult]


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()


def run_task(task: EpisodeTask) -> TaskResult:
    """Generate the pile of ``task.seed`` and run its episode (the default task function).

    Audit files: ``scene.xml`` (compiled scene), ``initial_qpos.npy`` (the settled pile) and
    ``final_qpos.npy`` (after verify), (nq,) float64 each.
    """
    for path in task.import_paths:
        if path not in sys.path:
            sys.path.append(path)
    cfg = load_scene(task.spec.scene, task.spec.overrides)
    try:
        scene = generate_scene(cfg, task.seed)
    except SceneGenerationError as exc:
        return TaskResult(task=task, record=SceneErrorRecord(seed=task.seed, scene=cfg.name,
                                                             error=str(exc)))
    initial = scene.cell.data.qpos.copy()
    run = EpisodeRun(cfg)
    run.start(scene)
    while run.step():
        pass
    record = run.finish()
    audit = {"scene.xml": scene.cell.spec_xml.encode(), "initial_qpos.npy": _npy(initial),
             "final_qpos.npy": _npy(scene.cell.data.qpos.copy())}
    log = f"{record.failure_detail}\n{run.traceback}" if run.traceback else ""
    return TaskResult(task=task, record=record, audit=audit, log=log)


def failure_record(task: EpisodeTask, reason: str, detail: str) -> EpisodeRecord:
    """A complete record (the EpisodeRecord schema) of an episode that did not finish."""
    try:
        cfg = load_scene(task.spec.scene, task.spec.overrides)
        rec = EpisodeRecord(seed=task.seed, scene=cfg.name, detector=cfg.episode.detector,
                            estimator=estimator_name(cfg), controller=cfg.episode.controller,
                            tracker_frame=cfg.episode.tracker_frame,
                            belt_speed=cfg.conveyor.speed)
    except Exception:  # the config itself is broken: still one record for the seed
        rec = EpisodeRecord(seed=task.seed, scene=task.spec.scene, detector="",
                            tracker_frame="", belt_speed=0.0)
    rec.failure = reason
    rec.failure_detail = detail
    return rec


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f"{os.uname().nodename}:{os.getpid()}"


def safe_call(fn: TaskFn, task: EpisodeTask) -> TaskResult:
    """``fn(task)``, or a failed record (reason ``error``, traceback in the log) if it raises."""
    try:
        result = fn(task)
    except Exception as exc:
        result = TaskResult(task=task, record=failure_record(
            task, ERROR_REASON, f"{type(exc).__name__}: {exc}"), log=traceback.format_exc())
    result.worker = worker_name()
    return result


def init_worker() -> None:
    """Per-process setup of a worker: renderers are built once and reused."""
    enable_renderer_reuse()

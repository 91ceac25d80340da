"""One unit of work: an episode of one seed, run anywhere, returned with its audit files.

A worker (a local process or a Ray task) calls :func:`safe_call` on an :class:`EpisodeTask`
and sends back a :class:`TaskResult`: the record dict and the audit files as bytes. Only the
driver writes to the run directory, so the workers need no shared file system and a run
directory has one writer.

An exception inside an episode becomes a failed record with reason ``error`` and the
traceback in :attr:`TaskResult.log`; the run goes on.
"""

from __future__ import annotations

import io
import os
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.episode import run_episode
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
    cfg = load_scene(task.spec.scene, task.spec.overrides)
    try:
        scene = generate_scene(cfg, task.seed)
    except SceneGenerationError as exc:
        return TaskResult(task=task, record=SceneErrorRecord(seed=task.seed, scene=cfg.name,
                                                             error=str(exc)))
    initial = scene.cell.data.qpos.copy()
    record = run_episode(scene)
    audit = {"scene.xml": scene.cell.spec_xml.encode(), "initial_qpos.npy": _npy(initial),
             "final_qpos.npy": _npy(scene.cell.data.qpos.copy())}
    return TaskResult(task=task, record=record, audit=audit)


def failure_record(task: EpisodeTask, reason: str, detail: str) -> EpisodeRecord:
    """A complete record (the EpisodeRecord schema) of an episode that did not finish."""
    try:
        cfg = load_scene(task.spec.scene, task.spec.overrides)
        rec = EpisodeRecord(seed=task.seed, scene=cfg.name, detector=cfg.episode.detector,
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

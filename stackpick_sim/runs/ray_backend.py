"""Episodes as Ray tasks, on a local Ray instance or a cluster (``--backend ray``).

Needs the optional extra ``stackpick-sim[ray]``. ``address=None`` starts a private local
instance (as many CPUs as the machine); ``"auto"`` joins the cluster this machine belongs
to; ``"ray://HEAD:10001"`` connects a Ray client to a remote head node. Every node must have
stackpick-sim installed (same version) and working EGL; the records and audit files come
back to the driver, which alone writes the run directory, so nodes need no shared disk.

At most as many tasks are in flight as the cluster has CPUs, so a task's wall-clock time-out
counts from when it starts rather than from when it was queued. A task whose worker dies
becomes a failed record (``error``, Ray's message in the log); one past the time-out is
cancelled with ``force=True`` (its worker process is killed) and recorded as ``timeout``.
Records are those of the local backend for the same seeds: each task runs the same
deterministic function in a fresh or reused Ray worker process.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from typing import Any

from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.tasks import (
    ERROR_REASON,
    TIMEOUT_REASON,
    EpisodeTask,
    TaskFn,
    TaskResult,
    failure_record,
    init_worker,
    run_task,
    safe_call,
)

#: Seconds between checks of the time-outs while no task finishes.
POLL_S = 1.0


def _ray_task(fn: TaskFn, task: EpisodeTask) -> TaskResult:
    init_worker()
    return safe_call(fn, task)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise StackpickError("--backend ray needs Ray; install it with "
                             "pip install 'stackpick-sim[ray]'") from None
    return ray


class RayExecutor:
    """Run tasks on Ray; iterate :meth:`map` for results in completion order."""

    def __init__(self, *, address: str | None = None, episode_timeout: float | None = None,
                 task_fn: TaskFn = run_task, num_cpus: int | None = None) -> None:
        self._ray = ray = _import_ray()
        self.episode_timeout = episode_timeout
        self.task_fn = task_fn
        self._owns = not ray.is_initialized()
        if self._owns:
            kwargs: dict[str, Any] = {"address": address, "include_dashboard": False,
                                      "log_to_driver": False}
            if address is None and num_cpus is not None:
                kwargs["num_cpus"] = num_cpus
            try:
                ray.init(**kwargs)
            except Exception as exc:  # ConnectionError, ValueError, ... from Ray
                raise StackpickError(f"cannot start or join Ray at address {address!r}: "
                                     f"{exc}") from None
        self._remote = ray.remote(max_retries=0)(_ray_task)
        self.slots = max(1, int(ray.cluster_resources().get("CPU", 1)))

    def map(self, tasks: Sequence[EpisodeTask]) -> Iterator[TaskResult]:
        """Run ``tasks``; yields one result per task as each finishes."""
        ray = self._ray
        queue = list(reversed(tasks))
        running: dict[Any, tuple[EpisodeTask, float]] = {}
        try:
            while queue or running:
                while queue and len(running) < self.slots:
                    task = queue.pop()
                    running[self._remote.remote(self.task_fn, task)] = (task, time.monotonic())
                ready, _ = ray.wait(list(running), num_returns=1, timeout=POLL_S)
                for ref in ready:
                    task, _start = running.pop(ref)
                    try:
                        yield ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        detail = f"Ray task failed: {type(exc).__name__}"
                        yield TaskResult(task=task, record=failure_record(task, ERROR_REASON,
                                                                          detail),
                                         log=f"seed {task.seed}: {exc}\n", worker="ray")
                if self.episode_timeout is None:
                    continue
                now = time.monotonic()
                for ref, (task, start) in list(running.items()):
                    if now - start >= self.episode_timeout:
                        ray.cancel(ref, force=True)
                        del running[ref]
                        detail = (f"episode exceeded --episode-timeout "
                                  f"{self.episode_timeout:g} s (wall); Ray task cancelled")
                        yield TaskResult(task=task, record=failure_record(task, TIMEOUT_REASON,
                                                                          detail),
                                         log=f"seed {task.seed}: {detail}\n", worker="ray")
        finally:
            for ref in running:
                ray.cancel(ref, force=True)

    def close(self) -> None:
        """Shut down the Ray instance if this executor started it."""
        if self._owns and self._ray.is_initialized():
            self._ray.shutdown()

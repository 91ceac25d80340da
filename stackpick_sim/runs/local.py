"""Episodes in local worker processes, each kept for many episodes, with crash and hang care.

Workers are ``spawn`` processes (MuJoCo's EGL contexts do not survive a fork); each one
imports the package and builds its renderers once (:func:`~stackpick_sim.runs.tasks.
init_worker`), then runs one task at a time sent over its own pipe. The driver waits on the
pipes and the process sentinels together, so it sees at once when

* a worker answers: the result is yielded;
* a worker dies (a segfault, the kernel's out-of-memory killer, a stray SIGKILL): the task
  becomes a failed record with reason ``error`` and the worker is replaced;
* a task runs past ``episode_timeout`` s: the worker is killed, the task becomes a failed
  record with reason ``timeout`` and the worker is replaced.

Workers ignore SIGINT (Ctrl-C reaches the driver, which stops them) and exit when the
driver goes away (end of file on their pipe).
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess

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

#: Seconds a worker gets to exit after the driver says stop, before it is killed.
STOP_GRACE_S = 5.0


def _worker_main(conn: Connection, fn: TaskFn) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    init_worker()
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            conn.send(safe_call(fn, task))
        except (BrokenPipeError, OSError):
            return


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        hint = " (the out-of-memory killer or a kill)" if name == "SIGKILL" else ""
        return f"killed by {name}{hint}"
    return f"exit code {exitcode}"


@dataclass(kw_only=True)
class _Slot:
    proc: BaseProcess | None = None
    conn: Connection | None = None
    task: EpisodeTask | None = None
    deadline: float = float("inf")


class LocalExecutor:
    """``workers`` local processes; iterate :meth:`map` for results in completion order."""

    def __init__(self, workers: int, *, episode_timeout: float | None = None,
                 task_fn: TaskFn = run_task) -> None:
        if workers < 1:
            raise StackpickError(f"--workers must be >= 1; got {workers}")
        if episode_timeout is not None and episode_timeout <= 0:
            raise StackpickError(f"--episode-timeout must be > 0 s; got {episode_timeout}")
        self.workers = workers
        self.episode_timeout = episode_timeout
        self.task_fn = task_fn
        self._ctx = multiprocessing.get_context("spawn")
        self._slots: list[_Slot] = []
        self.restarts = 0
        """Workers replaced after a crash or a time-out."""

    def _start(self, slot: _Slot) -> None:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_main, args=(child, self.task_fn), daemon=True,
                                 name="stackpick-worker")
        proc.start()
        child.close()
        slot.proc, slot.conn = proc, parent

    def _assign(self, slot: _Slot, task: EpisodeTask) -> None:
        if slot.proc is None or not slot.proc.is_alive():
            self._start(slot)
        assert slot.conn is not None
        slot.conn.send(task)
        slot.task = task
        slot.deadline = (time.monotonic() + self.episode_timeout
                         if self.episode_timeout is not None else float("inf"))

    def _discard(self, slot: _Slot) -> None:
        if slot.proc is not None:
            if slot.proc.is_alive():
                slot.proc.kill()
            slot.proc.join()
        if slot.conn is not None:
            slot.conn.close()
        slot.proc, slot.conn, slot.task = None, None, None
        self.restarts += 1

    def _collect(self, slot: _Slot, now: float) -> TaskResult | None:
        """The slot's result if it has one, a failure if its worker died or timed out."""
        task, conn, proc = slot.task, slot.conn, slot.proc
        assert task is not None and conn is not None and proc is not None
        if conn.poll():
            try:
                result: TaskResult = conn.recv()
                slot.task = None
                return result
            except (EOFError, OSError):
                pass  # died while answering: a crash
        if not proc.is_alive() or conn.closed:
            proc.join()
            detail = f"worker process {proc.pid} died ({_death(proc.exitcode)}) during the episode"
            self._discard(slot)
            return TaskResult(task=task, record=failure_record(task, ERROR_REASON, detail),
                              log=f"seed {task.seed}: {detail}\n", worker=f"local:{proc.pid}")
        if now >= slot.deadline:
            detail = (f"episode exceeded --episode-timeout {self.episode_timeout:g} s (wall); "
                      f"worker process {proc.pid} killed")
            self._discard(slot)
            return TaskResult(task=task, record=failure_record(task, TIMEOUT_REASON, detail),
                              log=f"seed {task.seed}: {detail}\n", worker=f"local:{proc.pid}")
        return None

    def map(self, tasks: Sequence[EpisodeTask]) -> Iterator[TaskResult]:
        """Run ``tasks``; yields one result per task as each finishes."""
        queue = deque(tasks)
        self._slots = [_Slot() for _ in range(min(self.workers, len(queue)))]
        try:
            while True:
                for slot in self._slots:
                    if slot.task is None and queue:
                        self._assign(slot, queue.popleft())
                busy = [s for s in self._slots if s.task is not None]
                if not busy:
                    return
                self._wait(busy)
                now = time.monotonic()
                for s in busy:
                    result = self._collect(s, now)
                    if result is not None:
                        yield result
        finally:
            self.close()

    @staticmethod
    def _wait(busy: Sequence[_Slot]) -> None:
        """Block until a busy worker sends, dies, or reaches its episode deadline."""
        timeout = max(0.0, min(s.deadline for s in busy) - time.monotonic())
        handles: list[Connection | int] = []
        for s in busy:
            assert s.conn is not None and s.proc is not None
            handles += [s.conn, s.proc.sentinel]
        wait(handles, None if timeout == float("inf") else timeout)

    def close(self) -> None:
        """Stop every worker (politely, then by force)."""
        for slot in self._slots:
            if slot.conn is not None and slot.task is None:
                try:
                    slot.conn.send(None)
                except OSError:
                    pass
        deadline = time.monotonic() + STOP_GRACE_S
        for slot in self._slots:
            if slot.proc is not None:
                if slot.task is not None:
                    slot.proc.kill()  # in flight when the run stopped
                slot.proc.join(max(0.0, deadline - time.monotonic()))
                if slot.proc.is_alive():
                    slot.proc.kill()
                    slot.proc.join()
            if slot.conn is not None:
                slot.conn.close()
        self._slots = []


class InlineExecutor:
    """Tasks in this process, one after another (tests, debugging); no time-out or isolation."""

    def __init__(self, *, task_fn: TaskFn = run_task) -> None:
        self.task_fn = task_fn

    def map(self, tasks: Sequence[EpisodeTask]) -> Iterator[TaskResult]:
        """Run ``tasks`` in order (renderer reuse stays as this process has it)."""
        for task in tasks:
            yield safe_call(self.task_fn, task)

    def close(self) -> None:
        """Nothing to stop."""

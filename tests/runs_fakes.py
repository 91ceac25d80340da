"""Cheap stand-ins for the episode task, importable by spawned worker processes."""

from __future__ import annotations

import os
import signal
import time

from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.runs.tasks import EpisodeTask, TaskResult

#: Seeds with a scripted misbehaviour.
CRASH_SEED, HANG_SEED, RAISE_SEED = 13, 14, 15
#: Seconds each fake episode takes (the kill/resume test kills runs mid-way).
FAKE_EPISODE_S = 0.05


def fake_record(seed: int) -> EpisodeRecord:
    """A complete record whose outcome is a function of the seed."""
    return EpisodeRecord(seed=seed, scene="paper", detector="oracle", tracker_frame="belt",
                         belt_speed=0.1, success=seed % 3 != 0,
                         failure=None if seed % 3 else "missed_grasp")


def fake_task(task: EpisodeTask) -> TaskResult:
    """Crash, hang or raise on the scripted seeds; else a quick record and an audit file."""
    if task.seed == CRASH_SEED:
        os.kill(os.getpid(), signal.SIGKILL)
    if task.seed == HANG_SEED:
        time.sleep(3600)
    if task.seed == RAISE_SEED:
        raise RuntimeError("scripted failure")
    time.sleep(FAKE_EPISODE_S)
    return TaskResult(task=task, record=fake_record(task.seed),
                      audit={"note.txt": f"seed {task.seed}".encode()})

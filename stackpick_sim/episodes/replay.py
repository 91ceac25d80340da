"""Replay one recorded episode and write a video: wrist camera with detections | overview.

The batch stores the scene and overrides (``run.json``) and the states before and after the
episode; the replay regenerates the pile from the seed, checks it against the stored start
state, runs the episode again (deterministic), and compares the end state too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.batch import RunSpec, episode_dir
from stackpick_sim.episodes.episode import EpisodeHooks, TickInfo, run_episode
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.video import H264Writer, ReplayFilm, frame_size
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.journal import RESULTS_FILE, read_records
from stackpick_sim.sim.stacks import generate_scene

#: One video frame every this many control ticks (10 ms each by default: ~33 frames per
#: second of sim time, played at that rate: real time).
TICKS_PER_FRAME = 3


@dataclass(frozen=True, kw_only=True)
class ReplayResult:
    """The re-run's record, the video's frame count and the state differences (rad or m)."""

    record: EpisodeRecord
    frames: int
    initial_diff: float
    final_diff: float


def replay_episode(out_dir: Path, seed: int, video: Path,
                   show_truth: bool = False) -> ReplayResult:
    """Re-run ``seed`` of the batch in ``out_dir`` and write ``video`` (H.264, see
    :mod:`stackpick_sim.episodes.video`); ``show_truth`` draws the true top faces too."""
    spec = RunSpec.from_dir(out_dir)
    scene = generate_scene(load_scene(spec.scene, spec.overrides), seed)
    cell = scene.cell
    stored = episode_dir(out_dir, seed)
    initial_diff = _diff(stored / "initial_qpos.npy", cell.data.qpos)
    fps = 1.0 / (TICKS_PER_FRAME * cell.cfg.episode.control_period)
    ticks = [0]
    with H264Writer(video, frame_size(), fps) as writer:
        film = ReplayFilm(cell, writer, seed=seed, recorded=_recorded(out_dir, seed),
                          show_truth=show_truth)

        def on_tick(info: TickInfo) -> None:
            film.on_tick(info, draw=ticks[0] % TICKS_PER_FRAME == 0)
            ticks[0] += 1

        try:
            record = run_episode(scene, EpisodeHooks(on_tick=on_tick, keep_images=True))
            film.finish(record, fps)
        finally:
            film.close()
    return ReplayResult(record=record, frames=writer.frames, initial_diff=initial_diff,
                        final_diff=_diff(stored / "final_qpos.npy", cell.data.qpos))


def _recorded(out_dir: Path, seed: int) -> dict[str, Any] | None:
    """The run's record of ``seed`` (its outcome goes in the video's banner), if readable."""
    try:
        records, _, _ = read_records(out_dir / RESULTS_FILE)
    except (OSError, ValueError, StackpickError):
        return None
    return records.get(seed)


def _diff(path: Path, qpos: NDArray[np.float64]) -> float:
    if not path.is_file():
        return float("nan")
    saved = np.load(path)
    return float(np.max(np.abs(saved - qpos))) if saved.shape == qpos.shape else float("inf")

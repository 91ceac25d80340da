"""Replay one recorded episode and write a video: wrist camera with detections | overview.

A run stores the scene and overrides and the states before and after each episode
(:func:`stackpick_sim.runs.replay.load_replay_source` reads and checks them into a
:class:`ReplaySource`, with the detector, estimator and controller the record names); the
replay regenerates the pile from the seed, compares it with the stored start state, runs the
episode again (deterministic), and compares the end state too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.episode import EpisodeHooks, TickInfo, run_episode
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.video import H264Writer, ReplayFilm, frame_size
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.sim.stacks import generate_scene

#: One video frame every this many control ticks (10 ms each by default: ~33 frames per
#: second of sim time, played at that rate: real time).
TICKS_PER_FRAME = 3


@dataclass(frozen=True, kw_only=True)
class ReplaySource:
    """A recorded episode to replay: its scene, seed, record and states (qpos, (nq,) each)."""

    cfg: SceneConfig
    seed: int
    record: EpisodeRecord
    initial_qpos: NDArray[np.float64]
    final_qpos: NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class ReplayResult:
    """The re-run's record, the video's frame count and the state differences (rad or m)."""

    record: EpisodeRecord
    frames: int
    initial_diff: float
    final_diff: float


def replay_episode(source: ReplaySource, video: Path,
                   show_truth: bool = False) -> ReplayResult:
    """Re-run the episode of ``source`` and write ``video`` (H.264, see
    :mod:`stackpick_sim.episodes.video`); ``show_truth`` draws the true top faces too."""
    scene = generate_scene(source.cfg, source.seed)
    cell = scene.cell
    if source.initial_qpos.shape != cell.data.qpos.shape:
        raise EpisodeError(f"seed {source.seed}: the recorded state has "
                           f"{source.initial_qpos.size} joint values, the scene "
                           f"{source.cfg.name!r} has {cell.data.qpos.size}: the run was "
                           "recorded with another scene or overrides")
    initial_diff = _diff(source.initial_qpos, cell.data.qpos)
    fps = 1.0 / (TICKS_PER_FRAME * cell.cfg.episode.control_period)
    ticks = [0]
    with H264Writer(video, frame_size(), fps) as writer:
        film = ReplayFilm(cell, writer, seed=source.seed, recorded=source.record,
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
                        final_diff=_diff(source.final_qpos, cell.data.qpos))


def _diff(saved: NDArray[np.float64], qpos: NDArray[np.float64]) -> float:
    return float(np.max(np.abs(saved - qpos)))

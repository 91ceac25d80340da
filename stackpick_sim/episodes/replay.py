"""Replay one recorded episode and write a video: wrist camera with detections | overview.

The batch stores the scene and overrides (``run.json``) and the states before and after the
episode; the replay regenerates the pile from the seed, checks it against the stored start
state, runs the episode again (deterministic) with the detector, estimator and controller
its record names, and compares the end state too. A stage that cannot be loaded here (a
plug-in not installed) stops the replay with one line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.batch import RunSpec, episode_dir
from stackpick_sim.episodes.episode import EpisodeHooks, TickInfo, estimator_name, run_episode
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.sensing import Observation
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.overlay import OTHER_COLOUR, TOP_COLOUR, draw_ellipse, draw_label, draw_marker
from stackpick_sim.registry import KINDS, PluginError, load
from stackpick_sim.sim.camera import make_renderer
from stackpick_sim.sim.stacks import generate_scene

#: One video frame every this many control ticks (10 ms each by default: ~33 frames per
#: second of sim time, played at that rate: real time).
TICKS_PER_FRAME = 3
#: Both views are shown at this size, px (width, height): twice the wrist camera's.
VIEW_SIZE = (640, 480)
#: FourCC of MPEG-4 part 2, which opencv-contrib-python-headless writes without extra codecs.
MP4V: int = cv2.VideoWriter.fourcc(*"mp4v")
#: Colour of the tracker's estimate, BGR.
ESTIMATE_COLOUR = (255, 80, 255)


@dataclass(frozen=True, kw_only=True)
class ReplayResult:
    """The re-run's record, the video's frame count and the state differences (rad or m)."""

    record: EpisodeRecord
    frames: int
    initial_diff: float
    final_diff: float


def wrist_view(obs: Observation | None, info: TickInfo) -> NDArray[np.uint8]:
    """The wrist frame of ``obs`` (BGR, VIEW_SIZE) with its candidates, the tracker's estimate
    and the time and phase of ``info`` drawn on it (black before the first frame)."""
    w, h = VIEW_SIZE
    if obs is None or obs.image is None:
        return np.zeros((h, w, 3), np.uint8)
    k = w / obs.image.shape[1]
    out: NDArray[np.uint8] = np.ascontiguousarray(
        cv2.resize(cv2.cvtColor(obs.image, cv2.COLOR_RGB2BGR), VIEW_SIZE,
                   interpolation=cv2.INTER_NEAREST), dtype=np.uint8)
    for cand in obs.candidates:
        if cand.ellipse is None:
            continue
        e = cand.ellipse
        scaled = type(e)(cx=(e.cx + 0.5) * k - 0.5, cy=(e.cy + 0.5) * k - 0.5, a=e.a * k,
                         b=e.b * k, angle_deg=e.angle_deg)
        draw_ellipse(out, scaled, TOP_COLOUR if cand.is_top else OTHER_COLOUR, 2)
    est = info.episode.estimator
    if est.initialised:
        state = est.state(obs.capture_time, obs.world_T_cam)
        r, p = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        c = r.T @ (state.centre - p)
        if c[2] > 1e-3:
            u, v = info.episode.scene.cell.intrinsics.project(c)[0]
            draw_marker(out, ((u + 0.5) * k - 0.5, (v + 0.5) * k - 0.5), ESTIMATE_COLOUR, 14)
    draw_label(out, f"t={info.time:.2f} s  {info.phase}", (8, 18), (255, 255, 255))
    return out


def replay_episode(out_dir: Path, seed: int, video: Path) -> ReplayResult:
    """Re-run ``seed`` of the batch in ``out_dir`` and write ``video`` (mp4v)."""
    spec = RunSpec.from_dir(out_dir)
    overrides = (*spec.overrides, *recorded_stages(out_dir, seed))
    cfg = load_scene(spec.scene, overrides)
    for kind in KINDS:
        name = estimator_name(cfg) if kind == "estimator" else getattr(cfg.episode, kind)
        try:
            load(kind, name)
        except PluginError as exc:
            raise PluginError(f"cannot replay seed {seed} of {out_dir}: its {kind} "
                              f"{name!r} does not load here ({exc})") from None
    scene = generate_scene(cfg, seed)
    cell = scene.cell
    stored = episode_dir(out_dir, seed)
    initial_diff = _diff(stored / "initial_qpos.npy", cell.data.qpos)
    overview = make_renderer(cell.model, VIEW_SIZE[1], VIEW_SIZE[0])
    writer = cv2.VideoWriter(str(video), MP4V,
                             1.0 / (TICKS_PER_FRAME * cell.cfg.episode.control_period),
                             (2 * VIEW_SIZE[0], VIEW_SIZE[1]))
    if not writer.isOpened():
        overview.close()
        raise EpisodeError(f"cannot open {video} for writing an mp4v video")
    latest: list[Observation | None] = [None]
    ticks = [0]
    frames = [0]

    def on_tick(info: TickInfo) -> None:
        for obs in info.observations:
            latest[0] = obs
        ticks[0] += 1
        if (ticks[0] - 1) % TICKS_PER_FRAME:
            return
        overview.update_scene(cell.data, camera="overview")
        right = cv2.cvtColor(overview.render(), cv2.COLOR_RGB2BGR)
        writer.write(np.hstack([wrist_view(latest[0], info), right]))
        frames[0] += 1

    try:
        record = run_episode(scene, EpisodeHooks(on_tick=on_tick, keep_images=True))
    finally:
        writer.release()
        overview.close()
    return ReplayResult(record=record, frames=frames[0], initial_diff=initial_diff,
                        final_diff=_diff(stored / "final_qpos.npy", cell.data.qpos))


def recorded_stages(out_dir: Path, seed: int) -> list[str]:
    """``--set`` overrides naming the stages the record of ``seed`` ran with (none when the
    record or its names are missing: the run's own overrides then decide)."""
    path = out_dir / "results.jsonl"
    if not path.is_file():
        return []
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(rec, dict) and rec.get("seed") == seed:
            return [f"episode.{k}={rec[k]}" for k in KINDS if isinstance(rec.get(k), str)
                    and rec[k]]
    return []


def _diff(path: Path, qpos: NDArray[np.float64]) -> float:
    if not path.is_file():
        return float("nan")
    saved = np.load(path)
    return float(np.max(np.abs(saved - qpos))) if saved.shape == qpos.shape else float("inf")

"""Replay an episode of a run directory: read and check what the run recorded, then re-run it.

Everything is checked before the pile is built, each problem one line: ``run.json`` (a run
description), the seed (recorded, and an episode rather than a scene error), the scene
(the one the seed was recorded with) and the audit states (``initial_qpos.npy`` and
``final_qpos.npy``: present, plain float arrays of one length, finite).
"""

from __future__ import annotations

from pathlib import Path
from tokenize import TokenError

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.episode import estimator_name
from stackpick_sim.episodes.record import EpisodeRecord, SceneErrorRecord
from stackpick_sim.episodes.replay import ReplayResult, ReplaySource, replay_episode
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.registry import KINDS, PluginError, load
from stackpick_sim.runs.journal import RESULTS_FILE, read_records
from stackpick_sim.runs.spec import RunSpec, episode_dir, seed_ranges

#: The audit states a replay compares against.
STATE_FILES = ("initial_qpos.npy", "final_qpos.npy")
#: What np.load raises on a damaged .npy: bad magic, header or data, or a pickle refused
#: (its header parser raises tokenize's and eval's errors on mangled text).
NPY_ERRORS = (ValueError, OSError, EOFError, SyntaxError, TypeError, KeyError, TokenError)


def _recorded(out_dir: Path, seed: int) -> EpisodeRecord:
    path = out_dir / RESULTS_FILE
    if not path.is_file():
        raise EpisodeError(f"{out_dir} has no {RESULTS_FILE}; is it the --out of "
                           "'stackpick run'?")
    records, _, _ = read_records(path)
    rec = records.get(seed)
    if rec is None:
        known = seed_ranges(sorted(records)) or "none"
        raise EpisodeError(f"seed {seed} is not recorded in {path} (recorded seeds: {known})")
    if isinstance(rec, SceneErrorRecord):
        raise EpisodeError(f"seed {seed} has no episode to replay: its pile could not be "
                           f"built ({rec.error})")
    return rec


def load_state(path: Path) -> NDArray[np.float64]:
    """A stored (nq,) float64 state; never unpickles, never reads more than the file holds."""
    if not path.is_file():
        raise EpisodeError(f"{path} is missing: replay compares the re-run with the "
                           "recorded states")
    try:
        data = np.load(path, mmap_mode="r", allow_pickle=False)
    except NPY_ERRORS as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise EpisodeError(f"{path} is not a stored state: {first}") from None
    if (not isinstance(data, np.ndarray) or data.dtype != np.float64 or data.ndim != 1
            or data.size == 0):
        raise EpisodeError(f"{path} is not a stored state: expected a 1-D float64 array")
    state: NDArray[np.float64] = np.array(data)
    if not np.isfinite(state).all():
        raise EpisodeError(f"{path} is not a stored state: it holds NaN or infinite values")
    return state


def recorded_stages(record: EpisodeRecord) -> list[str]:
    """``--set`` overrides naming the detector, estimator and controller ``record`` ran with
    (none for a name the record leaves empty: the run's own overrides then decide)."""
    return [f"episode.{kind}={getattr(record, kind)}" for kind in KINDS
            if getattr(record, kind)]


def check_stages_load(cfg: SceneConfig, context: str) -> None:
    """PluginError (one line, starting with ``context``) when a stage ``cfg`` names does not
    load here (a plug-in that is not installed)."""
    for kind in KINDS:
        name = estimator_name(cfg) if kind == "estimator" else getattr(cfg.episode, kind)
        try:
            load(kind, name)
        except PluginError as exc:
            raise PluginError(f"{context}: its {kind} {name!r} does not load here "
                              f"({exc})") from None


def load_replay_source(out_dir: Path, seed: int) -> ReplaySource:
    """What ``stackpick replay DIR SEED`` re-runs, every input checked (EpisodeError or
    RunFileError, one line, otherwise)."""
    spec = RunSpec.from_dir(out_dir)
    record = _recorded(out_dir, seed)
    cfg = load_scene(spec.scene, (*spec.overrides, *recorded_stages(record)))
    check_stages_load(cfg, f"cannot replay seed {seed} of {out_dir}")
    if cfg.name != record.scene:
        raise EpisodeError(f"{out_dir}/run.json names scene {cfg.name!r}, but seed {seed} was "
                           f"recorded on scene {record.scene!r}: run.json does not describe "
                           "this run")
    initial, final = (load_state(episode_dir(out_dir, seed) / name) for name in STATE_FILES)
    if initial.shape != final.shape:
        raise EpisodeError(f"{episode_dir(out_dir, seed)}: the initial and final states have "
                           f"{initial.size} and {final.size} values; they must match")
    return ReplaySource(cfg=cfg, seed=seed, record=record, initial_qpos=initial,
                        final_qpos=final)


def replay_run(out_dir: Path, seed: int, video: Path, show_truth: bool = False) -> ReplayResult:
    """Re-run ``seed`` of the run in ``out_dir`` and write ``video`` (H.264); ``show_truth``
    draws the true top faces too."""
    return replay_episode(load_replay_source(out_dir, seed), video, show_truth=show_truth)

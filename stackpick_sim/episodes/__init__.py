"""Pick episodes: the phase machine, its records, summaries and replays.

Running many episodes (batches, run directories, workers) is :mod:`stackpick_sim.runs`,
which depends on this package and never the reverse.
"""

from stackpick_sim.episodes.episode import EpisodeHooks, EpisodeRun, TickInfo, run_episode
from stackpick_sim.episodes.record import (
    FAILURES,
    MIN_LIFT_M,
    PHASES,
    SCHEMA_VERSION,
    EpisodeRecord,
    Record,
    SceneErrorRecord,
)
from stackpick_sim.episodes.replay import ReplayResult, ReplaySource, replay_episode
from stackpick_sim.episodes.schema import RecordError, record_from_json, record_to_json
from stackpick_sim.episodes.summary import summarize, summary_markdown, wilson_interval
from stackpick_sim.exceptions import EpisodeError

__all__ = [
    "FAILURES",
    "MIN_LIFT_M",
    "PHASES",
    "SCHEMA_VERSION",
    "EpisodeError",
    "EpisodeHooks",
    "EpisodeRecord",
    "EpisodeRun",
    "Record",
    "RecordError",
    "ReplayResult",
    "ReplaySource",
    "SceneErrorRecord",
    "TickInfo",
    "record_from_json",
    "record_to_json",
    "replay_episode",
    "run_episode",
    "summarize",
    "summary_markdown",
    "wilson_interval",
]

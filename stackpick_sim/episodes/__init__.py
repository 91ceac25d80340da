"""Pick episodes: the phase machine, its records, batches, summaries and replays."""

from stackpick_sim.episodes.batch import RunSpec, run_batch, write_outputs
from stackpick_sim.episodes.episode import EpisodeHooks, EpisodeRun, TickInfo, run_episode
from stackpick_sim.episodes.record import FAILURES, MIN_LIFT_M, PHASES, EpisodeRecord
from stackpick_sim.episodes.replay import ReplayResult, replay_episode
from stackpick_sim.episodes.summary import summarize, summary_markdown, wilson_interval
from stackpick_sim.exceptions import EpisodeError

__all__ = [
    "FAILURES",
    "MIN_LIFT_M",
    "PHASES",
    "EpisodeError",
    "EpisodeHooks",
    "EpisodeRecord",
    "EpisodeRun",
    "ReplayResult",
    "RunSpec",
    "TickInfo",
    "replay_episode",
    "run_batch",
    "run_episode",
    "summarize",
    "summary_markdown",
    "wilson_interval",
    "write_outputs",
]

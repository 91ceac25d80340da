"""summary.md: a batch without failures says so, and the title gives the belt speeds."""

from __future__ import annotations

from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.summary import summarize, summary_markdown


def _record(seed: int, success: bool, speed: float = 0.1) -> EpisodeRecord:
    return EpisodeRecord(seed=seed, scene="paper", detector="ours", tracker_frame="belt",
                         belt_speed=speed, success=success,
                         failure=None if success else "timeout",
                         failure_detail="" if success else "approach took too long")


def test_a_batch_without_failures_has_no_empty_failure_table() -> None:
    text = summary_markdown(summarize([_record(s, True) for s in range(3)]))
    assert "No failures." in text and "| failure | count |" not in text


def test_failures_are_tabled_by_reason() -> None:
    text = summary_markdown(summarize([_record(0, True), _record(1, False)]))
    assert "| failure | count |" in text and "| timeout | 1 |" in text


def test_the_title_gives_one_belt_speed_as_a_number() -> None:
    text = summary_markdown(summarize([_record(s, True) for s in range(2)]))
    assert text.splitlines()[0].endswith("belt 0.1 m/s")


def test_speeds_drawn_per_seed_are_given_as_a_range() -> None:
    records = [_record(s, True, speed=0.05 + 0.01 * s) for s in range(10)]
    title = summary_markdown(summarize(records)).splitlines()[0]
    assert title.endswith("belt 0.05-0.14 m/s (drawn per seed)")

"""A run directory: its lock, ``run.json``, journal, log, audit files and summaries.

Layout::

    DIR/run.json                 scene name/path and overrides (what resume and replay use)
    DIR/results.jsonl            one record per line (the journal; docs/records.md)
    DIR/run.log                  run starts and ends, repairs, tracebacks of failed workers
    DIR/summary.json, summary.md (stackpick_sim.episodes.summary), written at the end
    DIR/episodes/<seed>/scene.xml, initial_qpos.npy, final_qpos.npy (audit, replay)
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from stackpick_sim.episodes.record import EpisodeRecord, Record
from stackpick_sim.episodes.summary import summarize, summary_markdown
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.files import write_bytes, write_text
from stackpick_sim.runs.journal import Journal
from stackpick_sim.runs.lock import RunLock
from stackpick_sim.runs.spec import RUN_FILE, RunSpec, episode_dir, seed_ranges
from stackpick_sim.runs.tasks import TaskResult

#: The log file of a run directory.
LOG_FILE = "run.log"


def write_summaries(out: Path, records: list[Record]) -> dict[str, Any]:
    """Write summary.json and summary.md for ``records``; returns the summary."""
    summary = summarize(records)
    write_text(out / "summary.json", json.dumps(summary, indent=1))
    write_text(out / "summary.md", summary_markdown(summary))
    return summary


class RunDir:
    """One locked run directory, open for results (close it with :meth:`finish`/:meth:`close`)."""

    def __init__(self, path: Path, spec: RunSpec, *, resume: bool) -> None:
        self.path = path
        self.spec = spec
        self.lock = RunLock(path)
        try:
            self._check_spec(resume)
            self.journal = Journal(path, resume=resume)
        except BaseException:
            self.lock.release()
            raise
        write_text(path / RUN_FILE, json.dumps(spec.as_dict(), indent=1))
        if self.journal.repair_note:
            self.log(f"repaired: {self.journal.repair_note}")
        for d in self.journal.dropped:
            self.log(f"dropped line {d.line} of {self.journal.path.name} ({d.reason}): "
                     f"{d.text}")

    def drop_notes(self) -> list[str]:
        """One line per class of record dropped on resume: what, how many, which seeds."""
        by_reason: dict[str, list[int | None]] = {}
        for d in self.journal.dropped:
            by_reason.setdefault(d.reason, []).append(d.seed)
        notes = []
        for reason, seeds in by_reason.items():
            known = sorted(s for s in seeds if s is not None)
            which = f"seed {seed_ranges(known)}" if known else "no valid seed"
            notes.append(f"{self.journal.path}: dropped {len(seeds)} record"
                         f"{'s' if len(seeds) > 1 else ''} ({which}): {reason}; kept in "
                         f"{LOG_FILE}, missing seeds run again")
        return notes

    def refuse_foreign(self, seeds: list[int]) -> None:
        """Refuse records of seeds outside ``seeds``: the summary would count them."""
        foreign = sorted(set(self.journal.records) - set(seeds))
        if foreign:
            raise StackpickError(
                f"{self.journal.path} holds records of seeds outside --seeds: "
                f"{seed_ranges(foreign)}; resume with --seeds covering every recorded seed "
                f"({seed_ranges(sorted(self.journal.records))}), or choose another --out")

    def _check_spec(self, resume: bool) -> None:
        path = self.path / RUN_FILE
        if not (resume and path.is_file()):
            return
        done = RunSpec.from_dir(self.path)
        if done != self.spec:
            raise StackpickError(
                f"{self.path} was run with scene {done.scene!r} and overrides "
                f"{list(done.overrides)}; --resume must use the same, got scene "
                f"{self.spec.scene!r} and overrides {list(self.spec.overrides)}")

    def discard_unfinished(self, seeds: list[int]) -> list[int]:
        """Drop the records of ``seeds`` whose episode did not finish (a worker crash, the
        wall-clock limit), so that they run again; returns those seeds."""
        wanted = set(seeds)
        redo = sorted(s for s, r in self.journal.records.items()
                      if s in wanted and isinstance(r, EpisodeRecord) and r.unfinished)
        if redo:
            self.journal.discard(set(redo))
            self.log(f"retry: dropped {len(redo)} unfinished episodes to run again: "
                     f"seeds {', '.join(map(str, redo))}")
        return redo

    def missing(self, seeds: list[int]) -> list[int]:
        """The seeds of ``seeds`` without a record yet, in order, once each."""
        return [s for s in sorted(set(seeds)) if s not in self.journal]

    def log(self, text: str) -> None:
        """Append a time-stamped entry to run.log."""
        stamp = time.strftime("%Y-%m-%d %H:%M:%S")
        with (self.path / LOG_FILE).open("a", encoding="utf-8") as fh:
            fh.write(f"{stamp} {text.rstrip()}\n")

    def add(self, result: TaskResult) -> None:
        """Write the audit files of ``result``, then its record (the commit point)."""
        if result.audit:
            d = episode_dir(self.path, result.task.seed)
            d.mkdir(parents=True, exist_ok=True)
            for name, data in result.audit.items():
                write_bytes(d / name, data)
        if result.log:
            self.log(f"seed {result.task.seed} on {result.worker}:\n{result.log}")
        self.journal.append(result.record)

    def finish(self) -> dict[str, Any]:
        """Put results.jsonl in seed order, write the summaries, release the lock."""
        try:
            self.journal.compact()
            return write_summaries(self.path, self.journal.ordered())
        finally:
            self.close()

    def close(self) -> None:
        """Close the journal and release the lock (idempotent)."""
        self.journal.close()
        self.lock.release()

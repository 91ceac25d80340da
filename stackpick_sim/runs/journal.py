"""``results.jsonl``: an append-only journal of episode records, durable line by line.

Each record is written as one JSON line, flushed and ``fsync``-ed as its episode ends, so a
run killed at any moment loses only the episodes in flight. Opening with ``resume=True``
reads the records already there (one per seed) and repairs a torn last line (a power cut in
the middle of a write: no final newline, unparsable, or trailing NUL bytes) by truncating
the file after its last complete record. At the end of a run :meth:`Journal.compact`
rewrites the file in seed order (atomically: temp file, fsync, rename), so the file does
not depend on the order in which workers finished.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import IO, Any

from stackpick_sim.exceptions import StackpickError

#: The journal's file name inside a run directory.
RESULTS_FILE = "results.jsonl"


class JournalError(StackpickError):
    """A results.jsonl cannot be continued (a corrupt line other than the last, ...)."""


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_records(path: Path) -> tuple[dict[int, dict[str, Any]], int, str | None]:
    """Records by seed, the byte length of the intact part, and a note if the tail was torn.

    Raises JournalError for an unparsable line that is not the last one, or a seed twice.
    """
    data = path.read_bytes() if path.exists() else b""
    records: dict[int, dict[str, Any]] = {}
    good = 0
    note = None
    lines = data.split(b"\n")
    for i, line in enumerate(lines):
        last = i == len(lines) - 1
        if last and not line:
            break  # the file ends with a newline
        try:
            if last:
                raise ValueError("no final newline")
            rec = json.loads(line)
            seed = int(rec["seed"])
        except (ValueError, KeyError, TypeError) as exc:
            tail = all(not x.strip(b"\0") for x in lines[i + 1:])
            if not tail:
                raise JournalError(
                    f"{path}: line {i + 1} is not a record ({exc}) and more records follow "
                    "it; only a torn last line can be repaired") from None
            note = (f"{path}: dropped a torn last line ({len(data) - good} bytes, "
                    f"line {i + 1}): {exc}")
            break
        if seed in records:
            raise JournalError(f"{path}: seed {seed} is recorded twice (line {i + 1})")
        records[seed] = rec
        good += len(line) + 1
    return records, good, note


class Journal:
    """The results.jsonl of one run directory, open for appending."""

    def __init__(self, directory: Path, *, resume: bool) -> None:
        self.path = directory / RESULTS_FILE
        self.records, good, self.repair_note = read_records(self.path)
        if self.records and not resume:
            raise JournalError(f"{directory} already holds {len(self.records)} records in "
                               f"{RESULTS_FILE}; pass --resume to add the missing seeds, or "
                               "choose another --out")
        if self.path.exists() and self.path.stat().st_size != good:
            if not resume:
                raise JournalError(f"{self.path} ends with a torn line; pass --resume to "
                                   "repair it and continue")
            os.truncate(self.path, good)
        self._fh: IO[str] | None = self.path.open("a", encoding="utf-8")
        os.fsync(self._fh.fileno())
        _fsync_dir(directory)

    def __contains__(self, seed: int) -> bool:
        return seed in self.records

    def append(self, record: dict[str, Any]) -> None:
        """Write ``record`` as one line and make it durable before returning."""
        if self._fh is None:
            raise JournalError(f"{self.path} is closed")
        seed = int(record["seed"])
        if seed in self.records:
            raise JournalError(f"{self.path}: seed {seed} is already recorded")
        self._fh.write(json.dumps(record, sort_keys=True) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.records[seed] = record

    def ordered(self) -> list[dict[str, Any]]:
        """The records in seed order."""
        return [self.records[s] for s in sorted(self.records)]

    def discard(self, seeds: set[int]) -> None:
        """Forget the records of ``seeds`` (rewriting the file atomically), so that they are
        run again; the journal stays open for appending."""
        if not seeds & self.records.keys():
            return
        for seed in seeds:
            self.records.pop(seed, None)
        self.compact()
        self._fh = self.path.open("a", encoding="utf-8")

    def compact(self) -> None:
        """Rewrite the file in seed order, atomically (and close it)."""
        self.close()
        tmp = self.path.with_suffix(".jsonl.tmp")
        with tmp.open("w", encoding="utf-8") as fh:
            for rec in self.ordered():
                fh.write(json.dumps(rec, sort_keys=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        _fsync_dir(self.path.parent)

    def close(self) -> None:
        """Close the file (records stay readable through :attr:`records`)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

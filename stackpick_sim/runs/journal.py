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
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from stackpick_sim.episodes.record import Record
from stackpick_sim.episodes.schema import (
    NewerSchemaError,
    NotJSONError,
    RecordError,
    record_from_json,
    record_to_json,
)
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


@dataclass(frozen=True, kw_only=True)
class Dropped:
    """A line of results.jsonl that is JSON but not a record of the schema."""

    line: int
    """1-based line number."""
    seed: int | None
    """Its seed if it names a valid one (that seed runs again), else None."""
    reason: str
    """The class of problem (:class:`~stackpick_sim.episodes.schema.RecordError`)."""
    text: str


@dataclass(kw_only=True)
class Contents:
    """What a results.jsonl holds."""

    records: dict[int, Record] = field(default_factory=dict)
    intact: int = 0
    """Byte length of the part to keep (up to the last complete line)."""
    torn_note: str | None = None
    """What was cut off the end, if anything."""
    dropped: list[Dropped] = field(default_factory=list)


def _seed_of(line: bytes) -> int | None:
    try:
        seed = json.loads(line).get("seed")
    except (ValueError, RecursionError, AttributeError):
        return None
    return seed if isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0 else None


def _dropped(path: Path, number: int, line: bytes, exc: RecordError,
             drop_invalid: bool) -> Dropped:
    """The line to drop, or JournalError when it may not be dropped."""
    if not drop_invalid or isinstance(exc, NotJSONError):
        hint = ("only a torn last line can be repaired" if isinstance(exc, NotJSONError)
                else "'stackpick run --resume' drops such lines and runs their seeds again")
        raise JournalError(f"{path}: line {number} is not a record ({exc}); {hint}")
    return Dropped(line=number, seed=_seed_of(line), reason=str(exc),
                   text=line.decode("utf-8", "replace"))


def scan(path: Path, *, drop_invalid: bool = False) -> Contents:
    """Read ``path`` (missing: empty). A torn last line is left out (see ``torn_note``).

    Raises JournalError for a line that is not JSON and is not the last one, a seed twice,
    a record of a newer schema, and (unless ``drop_invalid``) a JSON line that breaks the
    record schema; with ``drop_invalid`` those are listed in ``dropped``.
    """
    data = path.read_bytes() if path.exists() else b""
    out = Contents()
    lines = data.split(b"\n")
    for i, line in enumerate(lines):
        last = i == len(lines) - 1
        if last and not line:
            break  # the file ends with a newline
        try:
            if last:
                raise NotJSONError("no final newline")
            rec = record_from_json(line)
        except NewerSchemaError as exc:
            raise JournalError(f"{path}: line {i + 1}: {exc}; read it with the stackpick-sim "
                               "that wrote it") from None
        except RecordError as exc:
            if isinstance(exc, NotJSONError) and all(not x.strip(b"\0") for x in lines[i + 1:]):
                out.torn_note = (f"{path}: dropped a torn last line ({len(data) - out.intact} "
                                 f"bytes, line {i + 1}): {exc}")
                break
            out.dropped.append(_dropped(path, i + 1, line, exc, drop_invalid))
        else:
            if rec.seed in out.records:
                raise JournalError(f"{path}: seed {rec.seed} is recorded twice (line {i + 1})")
            out.records[rec.seed] = rec
        out.intact += len(line) + 1
    return out


def read_records(path: Path) -> tuple[dict[int, Record], int, str | None]:
    """Records by seed, the byte length of the intact part, and a note if the tail was torn.

    Raises JournalError for a line that is not a record, unless it is a torn last line.
    """
    contents = scan(path)
    return contents.records, contents.intact, contents.torn_note


class Journal:
    """The results.jsonl of one run directory, open for appending."""

    def __init__(self, directory: Path, *, resume: bool) -> None:
        self.path = directory / RESULTS_FILE
        contents = scan(self.path, drop_invalid=resume)
        self.records, good, self.repair_note = (contents.records, contents.intact,
                                                contents.torn_note)
        self.dropped = contents.dropped
        """Lines that broke the record schema, dropped on resume (the file is rewritten)."""
        if (self.records or self.dropped) and not resume:
            raise JournalError(f"{directory} already holds {len(self.records)} records in "
                               f"{RESULTS_FILE}; pass --resume to add the missing seeds, or "
                               "choose another --out")
        if self.path.exists() and self.path.stat().st_size != good:
            if not resume:
                raise JournalError(f"{self.path} ends with a torn line; pass --resume to "
                                   "repair it and continue")
            os.truncate(self.path, good)
        self._fh: IO[str] | None = None
        if self.dropped:
            self.compact()
        self._fh = self.path.open("a", encoding="utf-8")
        os.fsync(self._fh.fileno())
        _fsync_dir(directory)

    def __contains__(self, seed: int) -> bool:
        return seed in self.records

    def append(self, record: Record) -> None:
        """Write ``record`` as one line and make it durable before returning."""
        if self._fh is None:
            raise JournalError(f"{self.path} is closed")
        if record.seed in self.records:
            raise JournalError(f"{self.path}: seed {record.seed} is already recorded")
        self._fh.write(record_to_json(record) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.records[record.seed] = record

    def ordered(self) -> list[Record]:
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
                fh.write(record_to_json(rec) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        _fsync_dir(self.path.parent)

    def close(self) -> None:
        """Close the file (records stay readable through :attr:`records`)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

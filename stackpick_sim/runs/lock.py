"""One writer per run directory: an exclusive ``flock`` on ``DIR/.stackpick.lock``.

The kernel drops the lock when its process dies, however it dies (SIGKILL included), so a
killed run never leaves a stale lock behind. The file holds the owner's pid and command
line, for the message the second run gets.
"""

from __future__ import annotations

import fcntl
import os
import sys
from pathlib import Path
from typing import IO

from stackpick_sim.exceptions import StackpickError

#: The lock file's name inside a run directory.
LOCK_FILE = ".stackpick.lock"


class LockError(StackpickError):
    """Another process is writing the same run directory."""


class RunLock:
    """Hold the lock of ``directory`` (created if needed) until :meth:`release`."""

    def __init__(self, directory: Path) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        self.path = directory / LOCK_FILE
        fh: IO[str] = self.path.open("a+", encoding="utf-8")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            owner = fh.read().strip() or "unknown process"
            fh.close()
            raise LockError(f"{directory} is being written by another stackpick run "
                            f"({owner}); two runs never write one directory at once: wait "
                            "for it to end or choose another --out") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()}: {' '.join(sys.argv)}\n")
        fh.flush()
        self._fh: IO[str] | None = fh

    def release(self) -> None:
        """Give the lock up."""
        if self._fh is not None:
            fcntl.flock(self._fh.fileno(), fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

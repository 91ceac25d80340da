"""Checked, atomic file writes: a file is either written whole or not at all.

Every output file of the command line (images, ground truth, indexes) goes through
:func:`write_bytes` / :func:`write_text`: the data are written to a temporary name in the
target's directory, flushed to the disk (``fsync``) and renamed over the target, so a full
disk or an interrupted run never leaves a truncated or empty file under the real name. Any
failure raises one :class:`~stackpick_sim.exceptions.OutputError` naming the file.
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

from stackpick_sim.exceptions import OutputError


def shown(path: str | os.PathLike[str]) -> str:
    """A path as printable text: bytes that are not UTF-8 appear as ``\\xNN`` escapes."""
    return os.fspath(path).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def _refuse_non_regular(path: Path) -> None:
    """OutputError if ``path`` exists and is not a regular file (a directory, a device...)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise OutputError(f"cannot write '{shown(path)}': {exc.strerror}") from None
    if stat.S_ISDIR(mode):
        raise OutputError(f"cannot write '{shown(path)}': it is a directory")
    if not stat.S_ISREG(mode):
        raise OutputError(f"cannot write '{shown(path)}': it exists and is not a regular file")


def write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary name, fsync, rename).

    A symbolic link is followed (its target is replaced). Raises OutputError naming the file
    if it cannot be written whole: no such directory, no permission, a full disk, a target
    that is a directory or a device.
    """
    target = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    _refuse_non_regular(target)
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except OSError as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OutputError(f"cannot write '{shown(path)}': {exc.strerror or exc}") from None


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` as UTF-8 to ``path`` atomically; see :func:`write_bytes`."""
    write_bytes(path, text.encode("utf-8"))

"""What the C libraries underneath would print or log on their own.

* OpenCV's codecs and libpng/libjpeg/libtiff write warnings and errors straight to the
  process's stderr (``libpng error: Not enough image data``, ``[ WARN] ... findDecoder``).
  :func:`captured_stderr` takes them for the duration of a call, so that the command line
  prints its own one line, which quotes the library's reason.
* MuJoCo's default warning handler prints to stdout and appends to ``MUJOCO_LOG.TXT`` in
  the working directory. :func:`route_mujoco_warnings` sends its warnings to the
  ``stackpick_sim.mujoco`` logger instead (shown on stderr unless logging is configured
  otherwise). MuJoCo still counts them in ``MjData.warning``, which is what the episodes
  read to call a physics state unstable.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

#: The logger MuJoCo's warnings go to.
MUJOCO_LOGGER = logging.getLogger("stackpick_sim.mujoco")

_lock = threading.Lock()


@contextlib.contextmanager
def captured_stderr() -> Iterator[list[str]]:
    """Redirect file descriptor 2 to a temporary file; on exit the list holds its lines.

    For calls into C code only (Python's own ``sys.stderr`` is flushed first and is not
    affected otherwise); one thread at a time.
    """
    lines: list[str] = []
    with _lock, tempfile.TemporaryFile() as sink:
        sys.stderr.flush()
        saved = os.dup(2)
        try:
            os.dup2(sink.fileno(), 2)
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read(64 * 1024).decode("utf-8", "replace")
            lines.extend(line.strip() for line in text.splitlines() if line.strip())


def _log_mujoco_warning(message: str) -> None:
    MUJOCO_LOGGER.warning("MuJoCo: %s", message.strip())


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to :data:`MUJOCO_LOGGER` (no ``MUJOCO_LOG.TXT``); idempotent.

    A handler someone else installed is kept.
    """
    import mujoco

    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_log_mujoco_warning)

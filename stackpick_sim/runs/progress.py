"""The progress bar of a run: done/total, ETA, episodes/s and the running success rate."""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

from stackpick_sim.episodes.record import EpisodeRecord, Record


class Progress:
    """A tqdm bar on stderr (``enabled=False``: silent); :meth:`update` per finished record."""

    def __init__(self, total: int, *, done: int = 0, successes: int = 0, episodes: int = 0,
                 enabled: bool = True, desc: str = "episodes") -> None:
        self.successes = successes
        self.episodes = episodes
        self._start = time.monotonic()
        self._ran = 0
        self._bar = tqdm(total=total, initial=done, desc=desc, unit="ep", file=sys.stderr,
                         disable=not enabled, dynamic_ncols=True, smoothing=0.05)

    def update(self, record: Record) -> None:
        """Count ``record`` and refresh the bar."""
        self._ran += 1
        if isinstance(record, EpisodeRecord):  # scene generation failures are not episodes
            self.episodes += 1
            self.successes += record.success
        # tqdm shows s/ep below one episode per second: episodes/s is stated here too.
        rate = self._ran / max(time.monotonic() - self._start, 1e-9)
        share = (f", success {100 * self.successes / self.episodes:.1f} % of {self.episodes}"
                 if self.episodes else "")
        self._bar.set_postfix_str(f"{rate:.3f} ep/s{share}", refresh=False)
        self._bar.update(1)

    def write(self, line: str) -> None:
        """Print ``line`` above the bar."""
        self._bar.write(line, file=sys.stderr)

    def close(self) -> None:
        """Leave the final bar on screen."""
        self._bar.close()

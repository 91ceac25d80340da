"""What a run executes: a scene with overrides (``RunSpec``) and where its files go."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stackpick_sim.exceptions import EpisodeError

#: The file of a run directory that names its scene and overrides (what replay re-runs).
RUN_FILE = "run.json"


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """What to run: a scene (name or .toml path) with ``--set`` overrides."""

    scene: str
    overrides: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (``run.json``)."""
        return {"scene": self.scene, "overrides": list(self.overrides)}

    @classmethod
    def from_dir(cls, out: Path) -> RunSpec:
        """The spec a batch in ``out`` was run with (its ``run.json``)."""
        path = out / RUN_FILE
        if not path.is_file():
            raise EpisodeError(f"{out} has no {RUN_FILE}; is it the --out of 'stackpick run'?")
        raw = json.loads(path.read_text())
        return cls(scene=str(raw["scene"]), overrides=tuple(raw["overrides"]))


def episode_dir(out: Path, seed: int) -> Path:
    """Where the audit files of ``seed`` go: ``out/episodes/<seed>/``."""
    return out / "episodes" / str(seed)

"""What a run executes: a scene with overrides (``RunSpec``) and where its files go."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.jsonfile import read_json

#: The file of a run directory that names its scene and overrides (what replay re-runs).
RUN_FILE = "run.json"


class RunFileError(StackpickError):
    """A run directory's run.json is missing or is not what ``stackpick run`` writes."""


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
        """The spec a batch in ``out`` was run with (its ``run.json``), checked."""
        path = out / RUN_FILE
        if not path.is_file():
            raise RunFileError(f"{out} has no {RUN_FILE}; is it the --out of 'stackpick run'?")
        raw = read_json(path, "a run description", RunFileError)
        if not isinstance(raw, dict) or set(raw) != {f.name for f in fields(cls)}:
            raise RunFileError(f"{path} is not a run description: it should be an object with "
                               '"scene" and "overrides" and nothing else')
        scene, overrides = raw["scene"], raw["overrides"]
        if not isinstance(scene, str) or not scene:
            raise RunFileError(f'{path}: "scene" must be a scene name or path; got {scene!r}')
        if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
            raise RunFileError(f'{path}: "overrides" must be a list of KEY=VALUE strings')
        return cls(scene=scene, overrides=tuple(overrides))


def episode_dir(out: Path, seed: int) -> Path:
    """Where the audit files of ``seed`` go: ``out/episodes/<seed>/``."""
    return out / "episodes" / str(seed)


def seed_ranges(seeds: Sequence[int]) -> str:
    """Sorted seeds as ranges: [0, 1, 2, 5] -> ``"0-2, 5"``."""
    runs: list[list[int]] = []
    for s in seeds:
        if runs and s == runs[-1][-1] + 1:
            runs[-1].append(s)
        else:
            runs.append([s])
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)

"""Parameter sweeps: a grid of scene overrides, one run directory per cell.

``--param KEY=V1,V2,...`` (repeatable; several give their product) adds ``--set KEY=V`` to
the scene for each value; values are TOML like ``--set`` (commas inside brackets belong to
the value: ``objects.count=[3,5],[5,7]``). Layout::

    DIR/sweep.json            scene, overrides, params, seeds, cells (name -> overrides)
    DIR/sweep.md, sweep_summary.json   success rate and 95 % Wilson interval per cell
    DIR/cells/<name>/         a run directory (stackpick_sim.runs.rundir) per cell
"""

from __future__ import annotations

import itertools
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stackpick_sim.exceptions import ConfigError, StackpickError
from stackpick_sim.files import write_text
from stackpick_sim.runs.jsonfile import read_json
from stackpick_sim.runs.runner import RunJob
from stackpick_sim.runs.spec import RunSpec

#: The sweep's description file.
SWEEP_FILE = "sweep.json"
#: Characters kept in a cell's directory name; others become '_'.
_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]")


@dataclass(frozen=True, kw_only=True)
class Param:
    """One swept key and its values (TOML text, as given)."""

    key: str
    values: tuple[str, ...]


def split_values(text: str) -> list[str]:
    """Split at the commas outside brackets and quotes: ``"[3,5],[5,7]"`` -> two values."""
    out, depth, quote, cur = [], 0, "", ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
            continue
        cur += ch
    out.append(cur.strip())
    return out


def parse_param(text: str) -> Param:
    """``"conveyor.speed=0.05,0.1"`` -> Param(key="conveyor.speed", values=("0.05", "0.1"))."""
    key, sep, rest = text.partition("=")
    values = split_values(rest) if sep else []
    if not key.strip() or not values or any(not v for v in values):
        raise ConfigError(f"--param {text!r} is not KEY=V1,V2,...; e.g. "
                          "--param conveyor.speed=0.05,0.1,0.2")
    return Param(key=key.strip(), values=tuple(values))


@dataclass(frozen=True, kw_only=True)
class Cell:
    """One point of the grid: its directory name and its (key, value) settings."""

    name: str
    settings: tuple[tuple[str, str], ...]

    @property
    def overrides(self) -> tuple[str, ...]:
        """The ``--set`` strings of this cell."""
        return tuple(f"{k}={v}" for k, v in self.settings)


def grid(params: list[Param]) -> list[Cell]:
    """The product of the params' values, first param slowest."""
    keys = [p.key for p in params]
    if len(set(keys)) != len(keys):
        raise ConfigError(f"--param keys must differ; got {keys}")
    cells = []
    for combo in itertools.product(*(p.values for p in params)):
        settings = tuple(zip(keys, combo, strict=True))
        name = "__".join(_UNSAFE.sub("_", f"{k}={v}") for k, v in settings)
        cells.append(Cell(name=name, settings=settings))
    return cells


def sweep_jobs(out: Path, scene: str, overrides: tuple[str, ...], params: list[Param],
               seeds: list[int], *, resume: bool) -> list[RunJob]:
    """The cells' run jobs; writes (or, resuming, checks) ``out/sweep.json``."""
    cells = grid(params)
    desc: dict[str, Any] = {
        "scene": scene, "overrides": list(overrides),
        "params": {p.key: list(p.values) for p in params}, "seeds": seeds,
        "cells": {c.name: list(c.overrides) for c in cells}}
    path = out / SWEEP_FILE
    if path.is_file():
        old = load_sweep(out)
        same = {k: old.get(k) for k in ("scene", "overrides", "params")} == {
            k: desc[k] for k in ("scene", "overrides", "params")}
        if not resume:
            raise StackpickError(f"{out} already holds a sweep; pass --resume to continue "
                                 "it, or choose another --out")
        if not same:
            raise StackpickError(f"{out} holds a sweep of scene {old.get('scene')!r}, "
                                 f"overrides {old.get('overrides')}, params "
                                 f"{old.get('params')}; --resume must use the same")
        desc["seeds"] = sorted(set(old["seeds"]) | set(seeds))
    out.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(desc, indent=1))
    # Every cell runs the sweep's seeds so far: a resume with new seeds extends the sweep.
    return [RunJob(key=c.name, spec=RunSpec(scene=scene, overrides=(*overrides, *c.overrides)),
                   seeds=desc["seeds"], out=out / "cells" / c.name) for c in cells]


def load_sweep(out: Path) -> dict[str, Any]:
    """The ``sweep.json`` of a sweep directory."""
    path = out / SWEEP_FILE
    if not path.is_file():
        raise StackpickError(f"{out} has no {SWEEP_FILE}; is it the --out of 'stackpick sweep'?")
    return _check_sweep(read_json(path, "a sweep description"), path)


def _strings(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


def _cells_ok(cells: object, keys: list[str]) -> bool:
    """Cell names that are plain directory names, each with one KEY=VALUE per swept key."""
    return isinstance(cells, dict) and all(
        not _UNSAFE.search(name) and name not in ("", ".", "..") and _strings(settings)
        and [o.partition("=")[0] for o in settings] == keys
        for name, settings in cells.items())


def _check_sweep(data: object, path: Path) -> dict[str, Any]:
    """``data`` if it is what :func:`sweep_jobs` writes, else StackpickError naming ``path``."""
    if not isinstance(data, dict) or set(data) != {"scene", "overrides", "params", "seeds",
                                                   "cells"}:
        raise StackpickError(f"{path} is not a sweep description (an object with scene, "
                             "overrides, params, seeds and cells)")
    params = data["params"]
    seeds = data["seeds"]
    ok = (isinstance(data["scene"], str) and _strings(data["overrides"])
          and isinstance(params, dict) and all(_strings(v) for v in params.values())
          and isinstance(seeds, list)
          and all(type(s) is int and s >= 0 for s in seeds)
          and _cells_ok(data["cells"], list(params) if isinstance(params, dict) else []))
    if not ok:
        raise StackpickError(f"{path}: a field does not hold what 'stackpick sweep' writes "
                             "(scene: a string; overrides: strings; params: key -> value "
                             "strings; seeds: integers >= 0; cells: directory name -> "
                             "KEY=VALUE per param)")
    return data


def cell_rows(desc: dict[str, Any], summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Per cell: its settings, episodes, successes, rate and 95 % interval."""
    rows = []
    for name in desc["cells"]:
        s = summaries[name]
        settings = dict(o.split("=", 1) for o in desc["cells"][name])
        rows.append({"cell": name, "settings": settings, "episodes": s["episodes"],
                     "successes": s["successes"], "success_rate": s["success_rate"],
                     "success_ci95": s["success_ci95"], "failures": s["failures"]})
    return rows


def sweep_markdown(desc: dict[str, Any], rows: list[dict[str, Any]]) -> str:
    """The per-cell table of ``sweep.md``."""
    keys = list(desc["params"])
    lines = [f"# Sweep: scene {desc['scene']}, overrides {desc['overrides'] or 'none'}", "",
             "| " + " | ".join(keys) + " | episodes | success | 95 % Wilson CI |",
             "|" + "---|" * (len(keys) + 3)]
    for r in rows:
        rate = f"{100 * r['success_rate']:.1f} %" if r["episodes"] else "n/a"
        lo, hi = r["success_ci95"]
        lines.append("| " + " | ".join(r["settings"][k] for k in keys)
                     + f" | {r['episodes']} | {r['successes']} ({rate}) | "
                     f"{100 * lo:.1f}-{100 * hi:.1f} % |")
    return "\n".join(lines) + "\n"

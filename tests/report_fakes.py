"""Run and sweep directories made of hand-written records, for the report's tests."""

from __future__ import annotations

import json
from pathlib import Path

from stackpick_sim.episodes.record import EpisodeRecord, PoseErrors

#: A failure detail longer than a line, to check that reports keep it whole.
LONG_DETAIL = ("the target toppled while lifting: it rose 4.1 mm of the 100 mm asked, then "
               "slid off the cup at t = 2.31 s with the seal broken on its rim")


def record(seed: int, success: bool, theta_err: float = 0.2, failure: str = "timeout",
           detail: str = LONG_DETAIL) -> EpisodeRecord:
    """A complete episode record with a detection whose theta_x error is ``theta_err``."""
    det = PoseErrors(estimated=(160.0, 120.0, 10.0 + theta_err, 5.0),
                     actual=(160.3, 120.1, 10.0, 5.1))
    rec = EpisodeRecord(seed=seed, scene="paper", detector="ours", tracker_frame="belt",
                        belt_speed=0.1, success=success,
                        failure=None if success else failure,
                        failure_detail="" if success else detail, detection=det,
                        prediction_error_mm=0.5 + 0.01 * seed,
                        cycle_time_s=1.5 + 0.01 * seed if success else None)
    return rec


def write_run(out: Path, records: list[EpisodeRecord]) -> Path:
    """A run directory with ``records`` (``results.jsonl``, ``run.json``)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "run.json").write_text(json.dumps({"scene": "paper", "overrides": []}))
    (out / "results.jsonl").write_text("".join(json.dumps(r.as_dict()) + "\n" for r in records))
    return out


def write_sweep(out: Path, cells: dict[str, list[EpisodeRecord]], key: str) -> Path:
    """A sweep directory of one swept ``key``: cell name ``key=value`` -> its records."""
    out.mkdir(parents=True, exist_ok=True)
    values = [name.split("=", 1)[1] for name in cells]
    seeds = sorted({r.seed for rs in cells.values() for r in rs})
    desc = {"scene": "paper", "overrides": [], "params": {key: values}, "seeds": seeds,
            "cells": {name: [name] for name in cells}}
    (out / "sweep.json").write_text(json.dumps(desc))
    for name, records in cells.items():
        write_run(out / "cells" / name, records)
    return out

"""Batch statistics: success rate with a Wilson interval, failures, the paper's tables.

Input: the records of ``results.jsonl`` (:data:`~stackpick_sim.episodes.record.Record`), seed
order.
Table 1 (paper): the detected pose vs. the true pose of the first three episodes; Table 2:
the Kalman estimate at the pick moment vs. the true pose. Poses are the paper's
(x px, y px, theta_x deg, theta_y deg) in the look view: the image plane of the wrist camera
at the look pose, whose x and y may lie outside its frame once the belt has carried the face
on by the pick moment.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from stackpick_sim.episodes.record import (
    FAILURES,
    RUNNER_FAILURES,
    EpisodeRecord,
    Record,
    SceneErrorRecord,
    episodes_of,
)

#: Two-sided 95 % normal quantile for the Wilson score interval.
Z_95 = 1.959963984540054
#: Rows of the paper's tables.
TABLE_ROWS = 3


def wilson_interval(successes: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (Wilson 1927); (0, 1) when n = 0."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def _stats(values: Sequence[float | None]) -> dict[str, float | int | None]:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return {"n": 0, "median": None, "mean": None, "p95": None, "max": None}
    return {"n": int(v.size), "median": float(np.median(v)), "mean": float(v.mean()),
            "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def _outcomes(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Successes, their rate with its 95 % interval, and the count of each failure."""
    n = len(episodes)
    wins = sum(1 for r in episodes if r.success)
    lo, hi = wilson_interval(wins, n)
    failures = Counter(r.failure for r in episodes if r.failure)
    return {
        "successes": wins,
        "success_rate": wins / n if n else None,
        "success_ci95": [lo, hi],
        "failures": {reason: failures.get(reason, 0)
                     for reason in (*FAILURES, *RUNNER_FAILURES)},
    }


def _errors(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Statistics of the first detection's errors and of the pick-time prediction's."""
    detections = [r.detection for r in episodes]
    return {
        "detection": {key: _stats([None if d is None else getattr(d, key) for d in detections])
                      for key in ("center_error_px", "theta_x_error_deg", "theta_y_error_deg")},
        "prediction_error_px": _stats([r.prediction_error_px for r in episodes]),
        "prediction_error_mm": _stats([r.prediction_error_mm for r in episodes]),
    }


def _times(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Statistics of the successful picks' cycle times and of the episodes' wall times."""
    breakdown_keys = sorted({k for r in episodes for k in r.wall_breakdown_s})
    return {
        "cycle_time_s": _stats([r.cycle_time_s for r in episodes if r.success]),
        "wall_s": _stats([r.wall_s for r in episodes]),
        "scene_build_wall_s": _stats([r.scene_build_wall_s for r in episodes]),
        "wall_breakdown_s": {k: _stats([r.wall_breakdown_s.get(k) for r in episodes])
                             for k in breakdown_keys},
    }


def _tables(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """The first rows of the paper's Table 1 (detection) and Table 2 (pick estimate)."""
    return {
        "table1": [{"seed": r.seed, **r.detection.as_dict()} for r in episodes
                   if r.detection is not None][:TABLE_ROWS],
        "table2": [{"seed": r.seed, **r.pick_estimate.as_dict()} for r in episodes
                   if r.pick_estimate is not None][:TABLE_ROWS],
    }


def summarize(records: Sequence[Record]) -> dict[str, Any]:
    """The summary as a JSON-friendly dict (the content of ``summary.json``)."""
    episodes = episodes_of(records)
    return {
        "episodes": len(episodes),
        "scene_errors": [{"seed": r.seed, "error": r.error} for r in records
                         if isinstance(r, SceneErrorRecord)],
        "scenes": sorted({r.scene for r in episodes}),
        "detector": sorted({r.detector for r in episodes}),
        "tracker_frame": sorted({r.tracker_frame for r in episodes}),
        "belt_speed": sorted({r.belt_speed for r in episodes}),
        **_outcomes(episodes),
        **_errors(episodes),
        **_times(episodes),
        **_tables(episodes),
    }


def _pose(p: Sequence[float]) -> str:
    return f"({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}, {p[3]:.1f})"


def _err(row: dict[str, Any]) -> str:
    e, a = row["estimated"], row["actual"]
    return "(" + ", ".join(f"{abs(x - y):.2f}" for x, y in zip(e, a, strict=True)) + ")"


def _fmt(s: dict[str, Any], unit: str, scale: float = 1.0) -> str:
    if not s["n"]:
        return "n/a"
    return (f"median {s['median'] * scale:.3g} {unit}, p95 {s['p95'] * scale:.3g}, "
            f"max {s['max'] * scale:.3g} (n={s['n']})")


def _speeds(speeds: list[float]) -> str:
    """The belt speeds of a batch, m/s: each one, or their range when drawn per seed."""
    if len(speeds) > 3:
        return f"{min(speeds):g}-{max(speeds):g} m/s (drawn per seed)"
    return ", ".join(f"{v:g}" for v in speeds) + " m/s"


def _failure_table(failures: dict[str, int]) -> list[str]:
    """Markdown lines: a table of the failure reasons that occurred, or a line saying none."""
    rows = [f"| {k} | {v} |" for k, v in failures.items() if v]
    return ["| failure | count |", "|---|---|", *rows] if rows else ["No failures."]


def summary_markdown(s: dict[str, Any]) -> str:
    """Human-readable ``summary.md``."""
    n = s["episodes"]
    lines = [
        f"# Episodes: scene {', '.join(s['scenes'])}, detector {', '.join(s['detector'])}, "
        f"tracker {', '.join(s['tracker_frame'])}, belt {_speeds(s['belt_speed'])}",
        "",
        f"**Success: {s['successes']}/{n}"
        + (f" = {100 * s['success_rate']:.1f} %" if n else "")
        + f"** (95 % Wilson CI {100 * s['success_ci95'][0]:.1f}-"
        f"{100 * s['success_ci95'][1]:.1f} %)",
        "",
        *_failure_table(s["failures"]),
        "",
    ]
    if s["scene_errors"]:
        lines += [f"Scene generation failed for seeds "
                  f"{[e['seed'] for e in s['scene_errors']]} (not counted).", ""]
    lines += ["## Table 1: measured vs. actual pose at detection (x px, y px, theta_x deg, "
              "theta_y deg, look view)", "", "| seed | measured | actual | error |",
              "|---|---|---|---|"]
    lines += [f"| {r['seed']} | {_pose(r['estimated'])} | {_pose(r['actual'])} | {_err(r)} |"
              for r in s["table1"]]
    lines += ["", "## Table 2: Kalman-estimated vs. actual pose at the pick moment "
              "(look view's image plane: x, y may lie outside the frame)", "",
              "| seed | estimated | actual | error |", "|---|---|---|---|"]
    lines += [f"| {r['seed']} | {_pose(r['estimated'])} | {_pose(r['actual'])} | {_err(r)} |"
              for r in s["table2"]]
    d = s["detection"]
    lines += ["", "## Errors and times", "",
              f"- detection centre error: {_fmt(d['center_error_px'], 'px')}",
              f"- detection theta_x error: {_fmt(d['theta_x_error_deg'], 'deg')}",
              f"- detection theta_y error: {_fmt(d['theta_y_error_deg'], 'deg')}",
              f"- prediction error at pick: {_fmt(s['prediction_error_px'], 'px')}",
              f"- prediction error at pick: {_fmt(s['prediction_error_mm'], 'mm')}",
              f"- cycle time (successes, first image to lift): {_fmt(s['cycle_time_s'], 's')}",
              f"- wall time per episode (pile excluded): {_fmt(s['wall_s'], 's')}",
              f"- pile generation wall time: {_fmt(s['scene_build_wall_s'], 's')}",
              "- wall time by activity (median s): " + ", ".join(
                  f"{k} {v['median']:.3f}" for k, v in s["wall_breakdown_s"].items()
                  if v["n"]), ""]
    return "\n".join(lines)

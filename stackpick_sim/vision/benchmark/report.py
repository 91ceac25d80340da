"""Aggregate per-frame scores into the benchmark's tables (markdown) and JSON.

Totals for precision and recall are summed over the data set; pose errors are over the frames
where the method found a true top object; times are per frame, with each method's median
divided by ours (measured in the same run).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.scoring import (
    COUNTED_VISIBLE_FRACTION,
    MATCH_IOU,
    FrameScore,
    MethodOutput,
)

#: Frames shown in the paper's Table 1 layout.
TABLE1_FRAMES = 3


@dataclass
class MethodRecord:
    """Everything gathered for one method over the run."""

    name: str
    scores: list[FrameScore] = field(default_factory=list)
    outputs: list[MethodOutput] = field(default_factory=list)


def _stats(values: list[float]) -> dict[str, float]:
    """mean, median, p95 of a list (NaN when empty)."""
    if not values:
        return {"mean": math.nan, "median": math.nan, "p95": math.nan, "n": 0}
    a = np.asarray(values, float)
    return {"mean": float(a.mean()), "median": float(np.median(a)),
            "p95": float(np.percentile(a, 95)), "n": len(values)}


def _detection_rates(scores: list[FrameScore]) -> dict[str, float]:
    """True and false positives, false negatives summed over the frames; precision, recall and
    F-measure of those sums (0 where undefined)."""
    tp, fp, fn = (sum(x.true_pos for x in scores), sum(x.false_pos for x in scores),
                  sum(x.false_neg for x in scores))
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"true_pos": tp, "false_pos": fp, "false_neg": fn,
            "precision": precision, "recall": recall, "f_measure": f1}


def _error_stats(found: list[FrameScore]) -> dict[str, dict[str, float]]:
    """Centre and tilt error statistics over the frames whose top was found (a missing
    error is left out)."""
    def of(name: str) -> dict[str, float]:
        return _stats([v for v in (getattr(x, name) for x in found) if v is not None])

    return {name: of(name) for name in ("centre_err_px", "theta_x_err_deg", "theta_y_err_deg")}


def _stage_medians(outputs: list[MethodOutput]) -> dict[str, float]:
    """Median time of each stage over the frames that report it, ms."""
    stages: dict[str, list[float]] = {}
    for o in outputs:
        for k, v in o.stages_ms.items():
            stages.setdefault(k, []).append(v)
    return {k: float(np.median(v)) for k, v in stages.items()}


def summarise(record: MethodRecord) -> dict[str, Any]:
    """JSON-friendly summary of one method."""
    s = record.scores
    with_top = [x for x in s if x.has_top]
    found = [x for x in with_top if x.success]
    return {
        "frames": len(s), "frames_with_top": len(with_top), "top_found": len(found),
        "top_success": len(found) / len(with_top) if with_top else math.nan,
        "failed_seeds": [x.seed for x in with_top if not x.success],
        **_detection_rates(s),
        **_error_stats(found),
        "time_ms": _stats([o.total_ms for o in record.outputs]),
        "detector_ms": _stats([o.detector_ms for o in record.outputs]),
        "stages_ms_median": _stage_medians(record.outputs),
    }


def markdown(summaries: dict[str, dict[str, Any]], title: str) -> str:
    """The results table, the error details and the per-stage timings, as markdown."""
    ref = summaries.get("ours", next(iter(summaries.values())))["time_ms"]["median"]
    lines = [f"## {title}", "",
             f"Top success: chosen ellipse has mask IoU > {MATCH_IOU} with a true top face. "
             f"P/R/F: all ellipses vs faces >= {COUNTED_VISIBLE_FRACTION:.0%} visible, IoU > "
             f"{MATCH_IOU}, one-to-one, totals summed over the frames. Times: one thread "
             "(cv2.setNumThreads(1)), detector calls only; x ours = median / ours' median.", "",
             "| method | frames | top success | P | R | F | centre err px (mean / med / p95) "
             "| theta_x err deg (mean / med / p95) | theta_y err deg (mean / med / p95) "
             "| time ms (med / p95) | x ours | detector-only ms (med) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    def trio(d: dict[str, float]) -> str:
        return f"{d['mean']:.2f} / {d['median']:.2f} / {d['p95']:.2f}"

    for name, s in summaries.items():
        t = s["time_ms"]
        lines.append(
            f"| {name} | {s['frames']} | {s['top_success']:.1%} ({s['top_found']}/"
            f"{s['frames_with_top']}) | {s['precision']:.3f} | {s['recall']:.3f} | "
            f"{s['f_measure']:.3f} | {trio(s['centre_err_px'])} | {trio(s['theta_x_err_deg'])} | "
            f"{trio(s['theta_y_err_deg'])} | {t['median']:.2f} / {t['p95']:.2f} | "
            f"{t['median'] / ref:.2f} | {s['detector_ms']['median']:.2f} |")
    lines += ["", "Median per-stage time, ms:", ""]
    for name, s in summaries.items():
        st = ", ".join(f"{k} {v:.2f}" for k, v in s["stages_ms_median"].items())
        lines.append(f"- {name}: {st}")
    return "\n".join(lines) + "\n"


def table1(frames: list[BenchFrame], record: MethodRecord) -> str:
    """The paper's Table 1 layout for the first frames: measured, actual, error."""
    lines = [f"Table 1 layout ({record.name}): pose (x px, y px, theta_x deg, theta_y deg)", "",
             "| image (seed) | measured | actual | error |", "|---|---|---|---|"]
    for frame, score, out in list(zip(frames, record.scores, record.outputs,
                                      strict=True))[:TABLE1_FRAMES]:
        truth = score.matched
        meas = "miss" if out.pose is None else "({:.1f}, {:.1f}, {:.1f}, {:.1f})".format(*out.pose)
        if truth is None or out.pose is None:
            lines.append(f"| {frame.seed} | {meas} | no match | - |")
            continue
        act = (truth.face_center_px[0], truth.face_center_px[1], truth.theta_x_deg,
               truth.theta_y_deg)
        err = tuple(abs(m - a) for m, a in zip(out.pose, act, strict=True))
        lines.append("| {} | {} | ({:.1f}, {:.1f}, {:.1f}, {:.1f}) | ({:.1f}, {:.1f}, {:.1f}, "
                     "{:.1f}) |".format(frame.seed, meas, *act, *err))
    return "\n".join(lines) + "\n"

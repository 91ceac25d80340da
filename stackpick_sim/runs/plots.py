"""The report's PNG plots (matplotlib, optional extra ``stackpick-sim[plot]``).

Each function takes records (:mod:`stackpick_sim.episodes.record`) or sweep rows and writes
one PNG.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import Any

from stackpick_sim.episodes.record import EpisodeRecord, Record, episodes_of
from stackpick_sim.exceptions import StackpickError

#: Figure resolution, dots per inch.
DPI = 110
#: Histogram bins.
BINS = 30
#: A histogram whose max exceeds this many medians gets log-spaced bins and a log x axis, so
#: that one outlier (a 100 mm miss among 1 mm ones) does not squash the rest into one bar.
LOG_SPAN = 20.0


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise StackpickError("stackpick report needs matplotlib; install it with "
                             "pip install 'stackpick-sim[plot]'") from None
    matplotlib.use("Agg")  # files only: no display needed
    import matplotlib.pyplot as plt

    return plt


def _finite(values: list[Any]) -> list[float]:
    return [float(v) for v in values if v is not None and math.isfinite(float(v))]


def _hist(ax: Any, values: list[float], colour: str) -> None:
    """Histogram of ``values`` with integer counts; log bins for heavy tails."""
    from matplotlib.ticker import MaxNLocator

    if not values:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        return
    positive = sorted(v for v in values if v > 0)
    median = positive[len(positive) // 2] if positive else 0.0
    if positive and len(positive) == len(values) and positive[-1] > LOG_SPAN * median:
        edges = [positive[0] * (positive[-1] / positive[0]) ** (i / BINS)
                 for i in range(BINS + 1)]
        ax.hist(values, bins=edges, color=colour)
        ax.set_xscale("log")
    else:
        ax.hist(values, bins=BINS, color=colour)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def success_vs_param(rows: list[dict[str, Any]], keys: list[str], path: Path) -> None:
    """Success rate against the first swept key, one line per setting of the others,
    with the 95 % Wilson intervals as error bars."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    x_key, others = keys[0], keys[1:]
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        label = ", ".join(f"{k}={r['settings'][k]}" for k in others) or "all"
        groups.setdefault(label, []).append(r)
    for label, rs in groups.items():
        rs = [r for r in rs if r["episodes"]]
        try:
            xs: list[Any] = [float(r["settings"][x_key]) for r in rs]
        except ValueError:  # not numbers: categorical axis
            xs = [r["settings"][x_key] for r in rs]
        ys = [100 * r["success_rate"] for r in rs]
        err = [[y - 100 * r["success_ci95"][0] for y, r in zip(ys, rs, strict=True)],
               [100 * r["success_ci95"][1] - y for y, r in zip(ys, rs, strict=True)]]
        ax.errorbar(xs, ys, yerr=err, marker="o", capsize=4, label=label)
    ax.set_xlabel(x_key)
    ax.set_ylabel("success rate, % (95 % Wilson interval)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    if len(groups) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def failure_reasons(records: list[Record], path: Path) -> None:
    """Horizontal bars: episodes per failure reason."""
    plt = _pyplot()
    episodes = episodes_of(records)
    counts = Counter(r.failure for r in episodes if r.failure)
    fig, ax = plt.subplots(figsize=(6.4, max(2.4, 0.8 + 0.4 * len(counts))))
    reasons = sorted(counts, key=counts.__getitem__)
    ax.barh(reasons or ["(no failures)"], [counts[r] for r in reasons] or [0], color="#c0504d")
    ax.set_xlabel("episodes")
    ax.set_title(f"failure reasons ({sum(counts.values())} of "
                 f"{len(episodes)} episodes failed)")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def error_histograms(episodes: list[EpisodeRecord], path: Path) -> None:
    """2x2 histograms: detection centre, theta_x, theta_y errors; prediction error at pick."""
    plt = _pyplot()
    found = [r.detection for r in episodes if r.detection is not None]
    panels = [
        ("detection centre error, px", _finite([d.center_error_px for d in found])),
        ("detection theta_x error, deg", _finite([d.theta_x_error_deg for d in found])),
        ("detection theta_y error, deg", _finite([d.theta_y_error_deg for d in found])),
        ("prediction error at pick, mm", _finite([r.prediction_error_mm for r in episodes])),
    ]
    fig, axes = plt.subplots(2, 2, figsize=(8.0, 6.0))
    for ax, (title, values) in zip(axes.flat, panels, strict=True):
        _hist(ax, values, "#4f81bd")
        ax.set_title(f"{title} (n={len(values)})", fontsize=9)
        ax.set_ylabel("episodes")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def cycle_times(episodes: list[EpisodeRecord], path: Path) -> None:
    """Histogram of the cycle time (first image to end of lift) of successful episodes."""
    plt = _pyplot()
    values = _finite([r.cycle_time_s for r in episodes if r.success])
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    _hist(ax, values, "#9bbb59")
    ax.set_xlabel("cycle time, s (sim time, successes)")
    ax.set_ylabel("episodes")
    ax.set_title(f"cycle time (n={len(values)})")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)

"""The report's PNG plots (matplotlib, optional extra ``stackpick-sim[plot]``).

Each ``*_figure`` function takes records (:mod:`stackpick_sim.episodes.record`) grouped by run
(one group for a run, one per cell for a sweep) or sweep rows, and returns a matplotlib
Figure; :func:`save` writes it as a PNG and closes it. Successes and failures are drawn in
their own colours everywhere, and a sweep's cells are never pooled.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stackpick_sim.episodes.record import EpisodeRecord, Record, episodes_of
from stackpick_sim.exceptions import StackpickError

#: Figure resolution, dots per inch.
DPI = 110
#: Histogram bins.
BINS = 30
#: A panel whose largest value exceeds this many medians gets a log axis (log-spaced bins),
#: so that one outlier (a 100 mm miss among 1 mm ones) does not squash the rest into one bar.
LOG_SPAN = 20.0
#: Colours of successful and failed episodes, of failure bars and of the target lines.
SUCCESS_COLOUR = "#4f81bd"
FAILURE_COLOUR = "#c0504d"
TARGET_COLOUR = "#2ca02c"

#: The error panels: (record path, axis label, acceptance target or None). The targets are the
#: pipeline's acceptance figures: p95 centre error 1.5 px, p95 tilt errors 1.5 deg,
#: prediction error at the pick 1 mm.
ERROR_PANELS: tuple[tuple[tuple[str, ...], str, float | None], ...] = (
    (("detection", "center_error_px"), "detection centre error, px", 1.5),
    (("detection", "theta_x_error_deg"), "detection theta_x error, deg", 1.5),
    (("detection", "theta_y_error_deg"), "detection theta_y error, deg", 1.5),
    (("prediction_error_mm",), "prediction error at the pick, mm", 1.0),
)

Records = Sequence[Record]


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise StackpickError("stackpick report needs matplotlib; install it with "
                             "pip install 'stackpick-sim[plot]'") from None
    matplotlib.use("Agg")  # files only: no display needed
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: Path) -> None:
    """Write ``fig`` as a PNG at :data:`DPI` and free it."""
    plt = _pyplot()
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _value(record: EpisodeRecord, keys: tuple[str, ...]) -> float | None:
    node: Any = record
    for key in keys:
        node = getattr(node, key, None)
    if node is None:
        return None
    value = float(node)
    return value if math.isfinite(value) else None


def _episodes(records: Records) -> list[EpisodeRecord]:
    """The records of episodes that ran (not the scene-generation errors)."""
    return episodes_of(records)


def _split(records: Records, keys: tuple[str, ...]) -> tuple[list[float], list[float]]:
    """Finite values at ``keys`` of (successful, failed) episodes."""
    ok: list[float] = []
    bad: list[float] = []
    for r in _episodes(records):
        v = _value(r, keys)
        if v is not None:
            (ok if r.success else bad).append(v)
    return ok, bad


def _uses_log(values: Sequence[float]) -> bool:
    positive = sorted(v for v in values if v > 0)
    if not positive or len(positive) != len(values):
        return False
    return positive[-1] > LOG_SPAN * positive[len(positive) // 2]


def hist_edges(values: Sequence[float]) -> tuple[list[float], bool]:
    """Bin edges spanning ``values`` exactly (min and max included) and whether they are
    log-spaced (heavy tail, see :data:`LOG_SPAN`); at most :data:`BINS` bins, fewer for few
    values (numpy's "auto" rule)."""
    lo, hi = min(values), max(values)
    if hi <= lo:
        pad = max(0.05 * abs(lo), 1e-3)
        return [lo - pad, hi + pad], False
    log = _uses_log(values)
    space = np.log(np.asarray(values)) if log else np.asarray(values)
    bins = min(BINS, max(5, len(np.histogram_bin_edges(space, bins="auto")) - 1))
    edges = list(np.geomspace(lo, hi, bins + 1) if log else np.linspace(lo, hi, bins + 1))
    edges[0], edges[-1] = lo, hi  # the ends exactly: no rounding may drop the extremes
    return [float(e) for e in edges], log


def _hist_panel(ax: Any, ok: list[float], bad: list[float], label: str,
                target: float | None, failures: bool = True) -> None:
    """Stacked histogram of successes and (``failures``) failures with the target line."""
    from matplotlib.ticker import MaxNLocator

    values = ok + bad
    if not values:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel(label)
        return
    edges, log = hist_edges(values)
    if failures:
        ax.hist([ok, bad], bins=edges, stacked=True, color=[SUCCESS_COLOUR, FAILURE_COLOUR],
                label=[f"successes ({len(ok)})", f"failures ({len(bad)})"])
    else:
        ax.hist(ok, bins=edges, color=SUCCESS_COLOUR, label=f"successes ({len(ok)})")
    if log:
        ax.set_xscale("log")
    if target is not None:
        ax.axvline(target, color=TARGET_COLOUR, linestyle="--", label=f"target {target:g}")
    ax.set_xlabel(label + (" (log scale)" if log else ""))
    ax.set_ylabel("episodes")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.legend(fontsize=7)


def _strip_panel(ax: Any, groups: Mapping[str, Records], keys: tuple[str, ...], label: str,
                 target: float | None) -> None:
    """One column of points per group (sweep cell): successes and failures, target line."""
    rng = np.random.default_rng(0)  # horizontal jitter only, for legibility
    everything: list[float] = []
    for i, records in enumerate(groups.values()):
        ok, bad = _split(records, keys)
        everything += ok + bad
        for values, colour, name in ((ok, SUCCESS_COLOUR, "successes"),
                                     (bad, FAILURE_COLOUR, "failures")):
            xs = i + rng.uniform(-0.2, 0.2, len(values))
            ax.scatter(xs, values, s=10, color=colour, alpha=0.7,
                       label=name if i == 0 else None)
    log = _uses_log(everything)
    if log:
        ax.set_yscale("log")
    if target is not None:
        ax.axhline(target, color=TARGET_COLOUR, linestyle="--", label=f"target {target:g}")
    ax.set_xticks(range(len(groups)), list(groups), rotation=30, ha="right", fontsize=7)
    ax.set_xlim(-0.6, len(groups) - 0.4)
    ax.set_ylabel(label + (" (log scale)" if log else ""), fontsize=8)
    if not everything:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    ax.legend(fontsize=7)


def _success_line(ax: Any, rs: Sequence[Mapping[str, Any]], x_key: str, label: str) -> None:
    """One line of the success plot: rate against ``x_key`` (numbers, else categories),
    with Wilson error bars and each cell's successes/episodes beside its point."""
    try:
        xs: list[Any] = [float(r["settings"][x_key]) for r in rs]
    except ValueError:  # not numbers: categorical axis
        xs = [r["settings"][x_key] for r in rs]
    ys = [100 * r["success_rate"] for r in rs]
    # A Wilson bound equals the rate up to rounding at 0/n and n/n: clip at 0.
    err = [[max(0.0, y - 100 * r["success_ci95"][0]) for y, r in zip(ys, rs, strict=True)],
           [max(0.0, 100 * r["success_ci95"][1] - y) for y, r in zip(ys, rs, strict=True)]]
    ax.errorbar(xs, ys, yerr=err, marker="o", capsize=4, label=label)
    for x, y, r in zip(xs, ys, rs, strict=True):
        ax.annotate(f"{r['successes']}/{r['episodes']}", (x, y), textcoords="offset points",
                    xytext=(6, 6 if y < 50 else -12), fontsize=7)


def success_vs_param_figure(rows: Sequence[Mapping[str, Any]], keys: Sequence[str]) -> Any:
    """Success rate against the first swept key, one line per setting of the others, with
    the 95 % Wilson intervals as error bars and each cell's successes/episodes beside it."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    x_key, others = keys[0], keys[1:]
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        label = ", ".join(f"{k}={r['settings'][k]}" for k in others) or "all"
        groups.setdefault(label, []).append(r)
    for label, rs in groups.items():
        _success_line(ax, [r for r in rs if r["episodes"]], x_key, label)
    ax.set_title(f"pick success vs. {x_key}")
    ax.set_xlabel(x_key)
    ax.set_ylabel("success rate, % (95 % Wilson interval)")
    ax.set_ylim(-5, 108)  # 0 % and 100 % clear of the frame
    ax.grid(alpha=0.3)
    if len(groups) > 1:
        ax.legend(fontsize=8)
    return fig


def failure_reasons_figure(groups: Mapping[str, Records]) -> Any:
    """Horizontal bars of episodes per failure reason (one bar per cell and reason in a
    sweep), integer ticks; a plain statement when nothing failed."""
    from matplotlib.ticker import MaxNLocator

    plt = _pyplot()
    bars: list[tuple[str, int]] = []
    for name, records in groups.items():
        counts = Counter(str(r.failure) for r in _episodes(records)
                         if not r.success and r.failure)
        prefix = f"{name}: " if len(groups) > 1 else ""
        bars += [(prefix + reason, n) for reason, n in sorted(counts.items(),
                                                              key=lambda kv: kv[1])]
    total = sum(len(_episodes(rs)) for rs in groups.values())
    failed = sum(n for _, n in bars)
    fig, ax = plt.subplots(figsize=(6.4, max(2.4, 0.8 + 0.35 * len(bars))))
    ax.set_title(f"failure reasons ({failed} of {total} episodes failed)")
    if not bars:
        ax.text(0.5, 0.5, f"no failures in {total} episodes", ha="center", va="center",
                transform=ax.transAxes, fontsize=12)
        ax.set_axis_off()
        return fig
    ax.barh([b[0] for b in bars], [b[1] for b in bars], color=FAILURE_COLOUR)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("episodes")
    return fig


def errors_figure(groups: Mapping[str, Records]) -> Any:
    """2x2 panels: detection centre, theta_x and theta_y errors, prediction error at the pick.

    One run: stacked histograms of successes and failures. A sweep: one column of points
    per cell. Each panel has its target line and says when its axis is logarithmic.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(9.0, 6.6))
    for ax, (keys, label, target) in zip(axes.flat, ERROR_PANELS, strict=True):
        if len(groups) == 1:
            ok, bad = _split(next(iter(groups.values())), keys)
            _hist_panel(ax, ok, bad, label, target)
            ax.set_title(f"{label.split(',')[0]} (n={len(ok) + len(bad)})", fontsize=9)
        else:
            _strip_panel(ax, groups, keys, label, target)
            ax.set_title(label.split(",")[0] + " per cell", fontsize=9)
    return fig


def cycle_time_figure(groups: Mapping[str, Records]) -> Any:
    """Cycle time (first image to the end of the lift, sim time) of successful episodes:
    a histogram for one run, one column per cell for a sweep."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    keys = ("cycle_time_s",)
    label = "cycle time, s (sim time)"
    if len(groups) == 1:
        ok, _ = _split(next(iter(groups.values())), keys)
        _hist_panel(ax, ok, [], label, None, failures=False)
        ax.set_title(f"cycle time of successful picks (n={len(ok)})")
    else:
        only_ok = {name: [r for r in _episodes(rs) if r.success] for name, rs in groups.items()}
        _strip_panel(ax, only_ok, keys, label, None)
        ax.set_title("cycle time of successful picks, per cell")
    return fig

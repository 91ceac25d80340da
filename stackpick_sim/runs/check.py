"""The regression gate: is a run's success rate significantly below a baseline's, or an
error statistic worse beyond a tolerance?

Success rate: a one-sided Fisher exact test on the 2x2 table (successes, failures) x
(current, baseline). Under H0 "both runs have the same success probability", given the
margins, the current run's successes follow a hypergeometric law; the p-value is
P(X <= observed). The gate fails when p < alpha (default 0.05). Exact for any batch size,
so a small CI batch is judged correctly (a z-test on two proportions is not valid there).
Identical rates give p >= 0.5; a batch that stops picking gives p near 0.

Error statistics: the medians of the detection centre error, theta_x and theta_y errors,
the prediction error at pick (mm) and the cycle time of successes. One regresses when
``current > baseline * (1 + tolerance) + floor``, with a relative ``tolerance`` (default
25 %) and an absolute floor per statistic (:data:`ERROR_FLOORS`) so that a statistic near
zero (the oracle's detection errors) does not fail on noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scipy.stats import hypergeom

from stackpick_sim.episodes.summary import summarize
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.journal import RESULTS_FILE, read_records
from stackpick_sim.runs.jsonfile import read_json

#: Default significance level of the one-sided test.
DEFAULT_ALPHA = 0.05
#: Default relative tolerance of an error statistic's median.
DEFAULT_TOLERANCE = 0.25
#: Absolute slack per statistic: (summary path, unit, floor).
ERROR_FLOORS: tuple[tuple[tuple[str, ...], str, float], ...] = (
    (("detection", "center_error_px"), "px", 0.5),
    (("detection", "theta_x_error_deg"), "deg", 0.5),
    (("detection", "theta_y_error_deg"), "deg", 0.5),
    (("prediction_error_mm",), "mm", 0.5),
    (("cycle_time_s",), "s", 0.05),
)


def fisher_less(k1: int, n1: int, k2: int, n2: int) -> float:
    """One-sided Fisher exact p-value that run 1's success rate is below run 2's.

    ``k`` successes of ``n`` episodes each; P(X <= k1) for X hypergeometric with the
    table's margins (population n1 + n2, k1 + k2 successes, n1 drawn), evaluated by
    scipy.stats.hypergeom in constant time whatever the counts.
    """
    if not (0 <= k1 <= n1 and 0 <= k2 <= n2):
        raise StackpickError(f"successes must lie in 0..episodes; got {k1}/{n1}, {k2}/{n2}")
    return min(1.0, float(hypergeom.cdf(k1, n1 + n2, k1 + k2, n1)))


def load_summary(path: Path) -> dict[str, Any]:
    """A summary from a run directory (its results.jsonl, else summary.json) or a JSON file,
    checked (:func:`check_summary`)."""
    if path.is_dir():
        if (path / RESULTS_FILE).is_file():
            records, _, _ = read_records(path / RESULTS_FILE)
            return check_summary(summarize([records[s] for s in sorted(records)]),
                                 path / RESULTS_FILE)
        path = path / "summary.json"
    if not path.is_file():
        raise StackpickError(f"{path} is neither a run directory nor a summary.json")
    return check_summary(read_json(path, "a summary.json"), path)


def _count(data: dict[str, Any], key: str, path: Path) -> int:
    value = data.get(key)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise StackpickError(f"{path}: {key!r} must be a whole number >= 0; got {value!r}")
    return value


def check_summary(data: object, path: Path) -> dict[str, Any]:
    """``data`` if it is a summary the gate can use: counts that are whole numbers with
    1 <= episodes and successes <= episodes, and each compared median null or a finite
    number; else StackpickError naming ``path``."""
    if not isinstance(data, dict) or "successes" not in data or "episodes" not in data:
        raise StackpickError(f"{path} is not a summary.json (an object with 'successes' and "
                             "'episodes')")
    n, k = _count(data, "episodes", path), _count(data, "successes", path)
    if n == 0:
        raise StackpickError(f"{path} holds no episodes: there is nothing to compare")
    if k > n:
        raise StackpickError(f"{path}: {k} successes of {n} episodes is impossible")
    for keys, _, _ in ERROR_FLOORS:
        _median(data, keys, path)
    return data


@dataclass(frozen=True, kw_only=True)
class CheckRow:
    """One line of the gate's table."""

    name: str
    baseline: str
    current: str
    limit: str
    ok: bool


def _median(summary: dict[str, Any], keys: tuple[str, ...], path: Path) -> float | None:
    """The median at ``keys`` (None if absent or null); StackpickError if malformed."""
    node: Any = summary
    for k in keys:
        node = node.get(k)
        if node is None:
            return None
        if not isinstance(node, dict):
            raise StackpickError(f"{path}: {'.'.join(keys[:keys.index(k) + 1])!r} must be an "
                                 f"object; got {type(node).__name__}")
    value = node.get("median")
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise StackpickError(f"{path}: the median of {'.'.join(keys)!r} must be a finite "
                             f"number or null; got {value!r}")
    return float(value)


def check(current: dict[str, Any], baseline: dict[str, Any], *, alpha: float = DEFAULT_ALPHA,
          tolerance: float = DEFAULT_TOLERANCE) -> list[CheckRow]:
    """The gate's rows; the gate passes when every row is ok."""
    if not 0 < alpha < 1:
        raise StackpickError(f"--alpha must lie in (0, 1); got {alpha}")
    if not 0 <= tolerance < math.inf:
        raise StackpickError(f"--tolerance must be a finite share >= 0; got {tolerance}")
    current = check_summary(current, Path("the current run"))
    baseline = check_summary(baseline, Path("the baseline"))
    k1, n1 = current["successes"], current["episodes"]
    k2, n2 = baseline["successes"], baseline["episodes"]
    p = fisher_less(k1, n1, k2, n2)
    rows = [CheckRow(name="success rate", baseline=f"{k2}/{n2}", current=f"{k1}/{n1}",
                     limit=f"Fisher one-sided p = {p:.3g} (fail if < {alpha:g})",
                     ok=p >= alpha)]
    for keys, unit, floor in ERROR_FLOORS:
        base = _median(baseline, keys, Path("the baseline"))
        cur = _median(current, keys, Path("the current run"))
        name = "median " + ".".join(keys)
        if base is None or cur is None:
            rows.append(CheckRow(name=name, baseline=str(base), current=str(cur),
                                 limit="not compared (missing)", ok=True))
            continue
        bound = base * (1 + tolerance) + floor
        rows.append(CheckRow(name=name, baseline=f"{base:.3f} {unit}",
                             current=f"{cur:.3f} {unit}", limit=f"<= {bound:.3f} {unit}",
                             ok=cur <= bound))
    return rows


def check_table(rows: list[CheckRow]) -> str:
    """The rows as a plain-text table."""
    head = ("check", "baseline", "current", "limit", "")
    cells = [head, *[(r.name, r.baseline, r.current, r.limit, "ok" if r.ok else "FAIL")
                     for r in rows]]
    widths = [max(len(c[i]) for c in cells) for i in range(len(head))]
    return "\n".join("  ".join(c[i].ljust(widths[i]) for i in range(len(head))).rstrip()
                     for c in cells)

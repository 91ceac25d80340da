"""``report.md`` of a run or sweep directory, with its PNG plots.

Sections: the success rate (per cell for a sweep, with 95 % Wilson intervals), the plots of
:mod:`stackpick_sim.runs.plots`, the failed seeds with the one command that replays each
as a video, and the summary (the paper's Tables 1 and 2, error and time statistics) of
each run directory.
"""

from __future__ import annotations

from pathlib import Path

from stackpick_sim.episodes.record import Record, episodes_of
from stackpick_sim.episodes.summary import summarize, summary_markdown
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs import plots
from stackpick_sim.runs.journal import RESULTS_FILE, read_records
from stackpick_sim.runs.sweep import SWEEP_FILE, cell_rows, load_sweep, sweep_markdown

#: The report's file name.
REPORT_FILE = "report.md"
#: Failed seeds listed per run directory (with their replay command).
MAX_FAILED_LISTED = 20


def _records(run_dir: Path) -> list[Record]:
    path = run_dir / RESULTS_FILE
    if not path.is_file():
        raise StackpickError(f"{run_dir} has no {RESULTS_FILE}; is it the --out of "
                             "'stackpick run' or 'stackpick sweep'?")
    records, _, _ = read_records(path)
    return [records[s] for s in sorted(records)]


def _failed(run_dir: Path, records: list[Record]) -> list[str]:
    failed = [r for r in episodes_of(records) if not r.success]
    if not failed:
        return ["No failed episodes."]
    lines = [f"{len(failed)} failed; replay one as a video (wrist camera | outside view):", "",
             "```sh"]
    lines += [f"stackpick replay {run_dir} {r.seed} --video {run_dir}/replay_{r.seed}.mp4"
              f"   # {r.failure}: {r.failure_detail[:80]}"
              for r in failed[:MAX_FAILED_LISTED]]
    lines.append("```")
    if len(failed) > MAX_FAILED_LISTED:
        lines.append(f"... and {len(failed) - MAX_FAILED_LISTED} more (see results.jsonl).")
    return lines


def write_report(directory: Path) -> Path:
    """Write ``directory/report.md`` and its PNGs; returns the report's path."""
    is_sweep = (directory / SWEEP_FILE).is_file()
    runs: dict[str, Path] = {}
    lines: list[str] = []
    if is_sweep:
        desc = load_sweep(directory)
        runs = {name: directory / "cells" / name for name in desc["cells"]}
        per_run = {n: _records(d) for n, d in runs.items()}
        rows = cell_rows(desc, {n: summarize(r) for n, r in per_run.items()})
        lines += [sweep_markdown(desc, rows)]
        plots.success_vs_param(rows, list(desc["params"]), directory / "success_vs_param.png")
        lines += ["![success rate vs. parameter](success_vs_param.png)", ""]
    else:
        runs = {"run": directory}
        per_run = {"run": _records(directory)}
    records = [r for rs in per_run.values() for r in rs]
    plots.failure_reasons(records, directory / "failure_reasons.png")
    plots.error_histograms(episodes_of(records), directory / "errors.png")
    plots.cycle_times(episodes_of(records), directory / "cycle_time.png")
    if not is_sweep:
        s = summarize(records)
        lo, hi = s["success_ci95"]
        rate = f"{100 * s['success_rate']:.1f} %" if s["episodes"] else "n/a"
        lines += [f"# Report: {directory}", "",
                  f"**Success {s['successes']}/{s['episodes']} = {rate}** "
                  f"(95 % Wilson CI {100 * lo:.1f}-{100 * hi:.1f} %)", ""]
    lines += ["## Plots (all episodes)", "", "![failure reasons](failure_reasons.png)", "",
              "![errors](errors.png)", "", "![cycle time](cycle_time.png)", ""]
    for name, run_dir in runs.items():
        rel = run_dir.relative_to(directory) if is_sweep else Path(".")
        title = f"## Cell {name}" if is_sweep else "## Failed episodes"
        lines += [title, "", *_failed(run_dir, per_run[name]), ""]
        body = summary_markdown(summarize(per_run[name]))
        lines += [line.replace("# Episodes:", f"### {rel} episodes:", 1)
                  .replace("## ", "### ") if line.startswith("#") else line
                  for line in body.splitlines()]
        lines.append("")
    path = directory / REPORT_FILE
    path.write_text("\n".join(lines) + "\n")
    return path

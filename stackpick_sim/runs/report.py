"""``report.md`` and ``report.html`` of a run or sweep directory, with their PNG plots.

Sections: the success rate (per cell for a sweep, with 95 % Wilson intervals), the plots of
:mod:`stackpick_sim.runs.plots`, the failed seeds with their reason, full detail and the one
command that replays each as a video, and the summary (the paper's Tables 1 and 2, error and
time statistics) of each run directory. :mod:`stackpick_sim.runs.html_report` renders the
same content as one self-contained web page.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stackpick_sim.episodes.record import EpisodeRecord, Record, episodes_of
from stackpick_sim.episodes.summary import summarize, summary_markdown
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.files import write_text
from stackpick_sim.runs import plots
from stackpick_sim.runs.journal import RESULTS_FILE, read_records
from stackpick_sim.runs.sweep import SWEEP_FILE, cell_rows, load_sweep, sweep_markdown

#: The report's file name.
REPORT_FILE = "report.md"
#: Failed seeds listed per run directory (with their replay command).
MAX_FAILED_LISTED = 20
#: The plots: file name -> alternative text.
PLOT_FILES = {"success_vs_param.png": "success rate vs. parameter",
              "failure_reasons.png": "failure reasons",
              "errors.png": "detection and prediction errors",
              "cycle_time.png": "cycle time"}


@dataclass(frozen=True, kw_only=True)
class RunData:
    """One run directory of the report (the run itself, or one cell of a sweep)."""

    name: str
    path: Path
    records: list[Record]
    summary: dict[str, Any]

    def failed(self) -> list[EpisodeRecord]:
        """Records of the episodes that ran and failed, in seed order."""
        return [r for r in episodes_of(self.records) if not r.success]


@dataclass(frozen=True, kw_only=True)
class ReportData:
    """Everything both reports show: the runs, and for a sweep its description and rows."""

    directory: Path
    runs: list[RunData]
    sweep: dict[str, Any] | None = None
    rows: list[dict[str, Any]] = field(default_factory=list)
    plots: list[str] = field(default_factory=list)

    @property
    def is_sweep(self) -> bool:
        """Whether the directory is a sweep's."""
        return self.sweep is not None


def _records(run_dir: Path) -> list[Record]:
    path = run_dir / RESULTS_FILE
    if not path.is_file():
        raise StackpickError(f"{run_dir} has no {RESULTS_FILE}; is it the --out of "
                             "'stackpick run' or 'stackpick sweep'?")
    records, _, _ = read_records(path)
    return [records[s] for s in sorted(records)]


def load_report_data(directory: Path) -> ReportData:
    """Read the run or sweep in ``directory``."""
    if not directory.is_dir():
        raise StackpickError(f"{directory} is not a directory")
    if not (directory / SWEEP_FILE).is_file():
        records = _records(directory)
        run = RunData(name="run", path=directory, records=records, summary=summarize(records))
        return ReportData(directory=directory, runs=[run])
    desc = load_sweep(directory)
    runs = []
    for name in desc["cells"]:
        records = _records(directory / "cells" / name)
        runs.append(RunData(name=name, path=directory / "cells" / name, records=records,
                            summary=summarize(records)))
    rows = cell_rows(desc, {r.name: r.summary for r in runs})
    return ReportData(directory=directory, runs=runs, sweep=desc, rows=rows)


def replay_command(run_dir: Path, seed: int) -> str:
    """The command that replays ``seed`` of ``run_dir`` as a video beside its records."""
    video = shlex.quote(str(video_path(run_dir, seed)))
    return f"stackpick replay {shlex.quote(str(run_dir))} {seed} --video {video}"


def video_path(run_dir: Path, seed: int) -> Path:
    """Where :func:`replay_command` writes the video of ``seed``."""
    return run_dir / f"replay_{seed}.mp4"


def _cell(text: Any) -> str:
    """``text`` as one Markdown table cell."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _failed_lines(run: RunData) -> list[str]:
    failed = run.failed()
    if not failed:
        return [f"No failed episodes ({len(run.records)} recorded)."]
    lines = [f"{len(failed)} failed; replay one as a video (wrist camera | outside view) "
             "with its command.", "", "| seed | reason | detail | replay |", "|---|---|---|---|"]
    lines += [f"| {r.seed} | {_cell(r.failure or '')} | "
              f"{_cell(r.failure_detail)} | `{replay_command(run.path, r.seed)}` |"
              for r in failed[:MAX_FAILED_LISTED]]
    if len(failed) > MAX_FAILED_LISTED:
        lines += ["", f"... and {len(failed) - MAX_FAILED_LISTED} more (see "
                  f"{run.path / RESULTS_FILE})."]
    return lines


def _summary_lines(run: RunData) -> list[str]:
    """The run's ``summary.md`` below a level-3 heading, without its success line (shown
    above); a table without rows becomes "(none)", the failure counts go when none failed."""
    body = summary_markdown(run.summary).splitlines()
    title = body[0].removeprefix("# ").removeprefix("Episodes: ")
    lines = [f"### Summary: {title}"]
    rest = [line for line in body[1:] if not line.startswith("**Success")]
    for i, line in enumerate(rest):
        after = rest[i + 2] if i + 2 < len(rest) else ""
        empty_table = line.startswith("| ") and rest[i + 1:i + 2] == [_rule(line)] and (
            not after.startswith("|"))
        if empty_table and line.startswith("| failure | count |"):
            rest[i:i + 2] = ["", ""]
        elif empty_table:
            rest[i:i + 2] = ["(none)", ""]
    for line in rest:
        if line == "" and lines[-1] == "":
            continue
        lines.append("#" + line if line.startswith("## ") else line)
    return lines


def _rule(header: str) -> str:
    """The separator line below a Markdown table's ``header``."""
    return "|" + "---|" * (header.count("|") - 1)


def write_plots(data: ReportData) -> list[str]:
    """Write the PNG plots into the report's directory; their file names."""
    groups = {run.name: run.records for run in data.runs}
    figures: dict[str, Any] = {}
    if data.sweep is not None:
        figures["success_vs_param.png"] = plots.success_vs_param_figure(
            data.rows, list(data.sweep["params"]))
    figures["failure_reasons.png"] = plots.failure_reasons_figure(groups)
    figures["errors.png"] = plots.errors_figure(groups)
    figures["cycle_time.png"] = plots.cycle_time_figure(groups)
    for name, fig in figures.items():
        plots.save(fig, data.directory / name)
    return list(figures)


def success_line(summary: dict[str, Any]) -> str:
    """``Success k/n = r %`` with its 95 % Wilson interval."""
    lo, hi = summary["success_ci95"]
    rate = f" = {100 * summary['success_rate']:.1f} %" if summary["episodes"] else ""
    return (f"Success {summary['successes']}/{summary['episodes']}{rate} "
            f"(95 % Wilson interval {100 * lo:.1f}-{100 * hi:.1f} %)")


def report_markdown(data: ReportData) -> str:
    """The text of ``report.md``."""
    lines = [f"# Report: {data.directory}", ""]
    if data.sweep is not None:
        lines += [sweep_markdown(data.sweep, data.rows).replace("# Sweep:", "## Sweep:", 1)]
    else:
        lines += [f"**{success_line(data.runs[0].summary)}**", ""]
    lines += ["## Plots", ""]
    lines += [f"![{PLOT_FILES[name]}]({name})\n" for name in data.plots]
    for run in data.runs:
        title = f"## Cell {run.name}" if data.is_sweep else "## Failed episodes"
        lines += [title, ""]
        if data.is_sweep:
            lines += [success_line(run.summary), ""]
        lines += [*_failed_lines(run), "", *_summary_lines(run), ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def write_report(directory: Path) -> ReportData:
    """Write ``directory/report.md`` and its PNGs; returns what it showed (for the page of
    :func:`stackpick_sim.runs.html_report.write_html`)."""
    data = load_report_data(directory)
    data = ReportData(directory=data.directory, runs=data.runs, sweep=data.sweep,
                      rows=data.rows, plots=write_plots(data))
    write_text(directory / REPORT_FILE, report_markdown(data))
    return data

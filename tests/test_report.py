"""``stackpick report``: report.md and its plots on runs and sweeps of known records."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from report_fakes import LONG_DETAIL, record, write_run, write_sweep

from stackpick_sim.cli.main import main
from stackpick_sim.runs import plots

pytest.importorskip("matplotlib")


def _bars(ax: Any) -> float:
    return sum(p.get_height() for p in ax.patches)


def test_a_sweep_with_a_cell_that_never_succeeds_gets_its_report(tmp_path: Path) -> None:
    # At 0/3 the Wilson lower bound is 0 up to rounding (5.6e-17): no negative error bar.
    out = write_sweep(tmp_path / "sweep", {
        "conveyor.speed=0.1": [record(s, True) for s in range(3)],
        "conveyor.speed=0.3": [record(s, False) for s in range(3)]}, "conveyor.speed")
    assert main(["report", str(out), "--no-html"]) == 0
    assert (out / "success_vs_param.png").read_bytes().startswith(b"\x89PNG")
    assert "0/3" in (out / "report.md").read_text()


def test_the_success_chart_has_a_title_and_room_above_100_percent() -> None:
    rows = [{"settings": {"conveyor.speed": v}, "episodes": 3, "successes": 3,
             "success_rate": 1.0, "success_ci95": (0.44, 1.0)} for v in ("0.1", "0.2")]
    fig = plots.success_vs_param_figure(rows, ["conveyor.speed"])
    ax = fig.axes[0]
    assert "conveyor.speed" in ax.get_title()
    assert ax.get_ylim()[1] > 100 and ax.get_ylim()[0] < 0


@pytest.mark.parametrize("outlier", [14.6, 1e3])
def test_histograms_count_every_episode_the_largest_too(outlier: float) -> None:
    records = [record(s, True, theta_err=0.05 + 0.01 * s) for s in range(40)]
    records.append(record(40, False, theta_err=outlier))
    fig = plots.errors_figure({"run": records})
    theta_x = fig.axes[1]
    assert "theta_x" in theta_x.get_xlabel()
    assert _bars(theta_x) == 41
    assert "log scale" in theta_x.get_xlabel()  # the outlier's span asks for a log axis


def test_error_panels_split_successes_from_failures_and_draw_their_target() -> None:
    records = [record(s, s % 4 != 0) for s in range(20)]
    fig = plots.errors_figure({"run": records})
    for ax in fig.axes[:4]:
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert any(t.startswith("successes (15)") for t in labels)
        assert any(t.startswith("failures (5)") for t in labels)
        assert any(t.startswith("target") for t in labels)
        assert "log scale" not in ax.get_xlabel()  # no heavy tail: a linear axis, unlabelled


def test_a_sweep_keeps_its_cells_apart_in_the_error_and_cycle_plots() -> None:
    groups = {"conveyor.speed=0.1": [record(s, True) for s in range(5)],
              "conveyor.speed=0.3": [record(s, s != 2) for s in range(5)]}
    for fig in (plots.errors_figure(groups), plots.cycle_time_figure(groups)):
        ticks = [t.get_text() for t in fig.axes[0].get_xticklabels()]
        assert ticks == list(groups)


def test_failure_reasons_without_failures_says_so_and_counts_are_whole() -> None:
    fig = plots.failure_reasons_figure({"run": [record(s, True) for s in range(4)]})
    ax = fig.axes[0]
    assert not ax.axison
    assert any("no failures in 4 episodes" in t.get_text() for t in ax.texts)
    fig = plots.failure_reasons_figure({"run": [record(0, False), record(1, True)]})
    fig.canvas.draw()
    ticks = fig.axes[0].get_xticks()
    assert len(ticks) and all(float(t).is_integer() for t in ticks)


def test_report_md_has_no_stray_heading_nor_empty_table_and_keeps_details_whole(
        tmp_path: Path) -> None:
    ok = write_run(tmp_path / "ok", [record(s, True) for s in range(3)])
    assert main(["report", str(ok), "--no-html"]) == 0
    text = (ok / "report.md").read_text()
    assert "| failure | count |" not in text
    assert "No failed episodes" in text
    assert not any(line.lstrip("#").strip().startswith(".") for line in text.splitlines()
                   if line.startswith("#"))
    bad = write_run(tmp_path / "bad", [record(0, False), record(1, True)])
    assert main(["report", str(bad), "--no-html"]) == 0
    text = (bad / "report.md").read_text()
    assert LONG_DETAIL in text
    assert f"stackpick replay {bad} 0 --video {bad}/replay_0.mp4" in text

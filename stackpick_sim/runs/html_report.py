"""``report.html``: the report of a run or sweep as one self-contained web page.

The page needs no server and no network: its style sheet and script are inline, its plots
and thumbnails are embedded as data URIs, and its only links are relative ones to files of
the directory (``report.md``, ``results.jsonl``, replay videos). It shows the success rate
with its 95 % interval (per cell for a sweep, with the success-vs-parameter chart), the
plots, each failed seed with a thumbnail of its wrist frame and its replay command or video,
and a table of every episode that sorts on a click on a column's heading.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import quote

import cv2

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.record import EpisodeRecord, SceneErrorRecord
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.files import write_text
from stackpick_sim.runs.journal import RESULTS_FILE
from stackpick_sim.runs.report import (
    MAX_FAILED_LISTED,
    PLOT_FILES,
    REPORT_FILE,
    ReportData,
    RunData,
    replay_command,
    success_line,
    video_path,
)
from stackpick_sim.runs.spec import RunSpec, episode_dir

#: The page's file name.
HTML_FILE = "report.html"
#: Width of a failed seed's thumbnail on the page, CSS px.
THUMB_WIDTH = 320
#: Failed seeds whose frame is shown (each may have to be regenerated, about a second each).
MAX_THUMBNAILS = 24

#: A look-pose frame of a seed's pile with its ground truth drawn, as PNG bytes.
FrameSource = Callable[[Path, int], bytes | None]

_STYLE = """
body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1150px;color:#222;
  padding:0 1em}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em}
.ok{color:#2f6f2f}.bad{color:#b03030}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f0f0f0}
table.sortable th{cursor:pointer;user-select:none}
table.sortable th:after{content:" \\2195";color:#999}
th.asc:after{content:" \\2191"!important;color:#222!important}
th.desc:after{content:" \\2193"!important;color:#222!important}
td.num{text-align:right;font-variant-numeric:tabular-nums}
img.plot{max-width:100%;border:1px solid #eee;margin:.3em 0}
.failures{display:flex;flex-wrap:wrap;gap:1em}
.failure{border:1px solid #ddd;padding:.5em;width:""" + str(THUMB_WIDTH) + """px;
  font-size:.85em}
.failure img{width:100%}
code{font-size:.8em;word-break:break-all}
"""

_SCRIPT = """
document.querySelectorAll('table.sortable').forEach(function (table) {
  table.querySelectorAll('th').forEach(function (th, col) {
    th.addEventListener('click', function () {
      var asc = !th.classList.contains('asc');
      table.querySelectorAll('th').forEach(function (h) { h.classList.remove('asc', 'desc'); });
      th.classList.add(asc ? 'asc' : 'desc');
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      function key(row) {
        var cell = row.cells[col];
        var v = cell.getAttribute('data-v');
        return v === null ? cell.textContent.trim() : (v === '' ? NaN : parseFloat(v));
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b), d;
        if (typeof x === 'number' || typeof y === 'number') {
          if (isNaN(x)) { return isNaN(y) ? 0 : 1; }   /* blanks last either way */
          if (isNaN(y)) { return -1; }
          d = x - y;
        } else {
          d = x < y ? -1 : (x > y ? 1 : 0);
        }
        return asc ? d : -d;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
"""

#: Numeric columns of the episode table: heading -> record path.
_NUMBERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("centre err, px", ("detection", "center_error_px")),
    ("theta_x err, deg", ("detection", "theta_x_error_deg")),
    ("theta_y err, deg", ("detection", "theta_y_error_deg")),
    ("prediction err, mm", ("prediction_error_mm",)),
    ("cycle time, s", ("cycle_time_s",)),
)


def _e(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _link(page_dir: Path, target: Path) -> str:
    """A relative URL from the page to ``target``."""
    return "/".join(quote(p) for p in Path(os.path.relpath(target, page_dir)).parts)


def _number(record: EpisodeRecord, keys: tuple[str, ...]) -> float | None:
    node: Any = record
    for key in keys:
        node = getattr(node, key, None)
    return None if node is None else float(node)


def look_frame_png(run_dir: Path, seed: int) -> bytes | None:
    """The seed's wrist frame at the look pose, where the pick's first detection is made, with
    the ground truth drawn: an image of the seed's audit files when the run kept one, or else
    regenerated from the seed and the run's scene. None when neither can be had."""
    stored = sorted(episode_dir(run_dir, seed).glob("*.png"))
    if stored:
        return stored[0].read_bytes()
    from stackpick_sim.sim.snapshot import seeded_look_frame, truth_overlay

    try:
        spec = RunSpec.from_dir(run_dir)
        _, image, truth = seeded_look_frame(load_scene(spec.scene, spec.overrides), seed)
    except StackpickError:
        return None
    ok, png = cv2.imencode(".png", truth_overlay(image, truth))
    return bytes(png) if ok else None


def _failure_cards(data: ReportData, run: RunData, frames: FrameSource,
                   budget: list[int]) -> list[str]:
    """A card per failed seed (at most MAX_FAILED_LISTED); ``budget`` holds how many more
    frames the page shows."""
    cards = []
    for r in run.failed()[:MAX_FAILED_LISTED]:
        seed = r.seed
        png = frames(run.path, seed) if budget[0] > 0 else None
        budget[0] -= 1
        thumb = (f'<img alt="seed {seed}, look-pose frame" src="{_data_uri(png)}">' if png
                 else f"<p>(no frame: <code>stackpick render</code> with this run's scene and "
                 f"<code>--seed {seed}</code> makes it)</p>")
        video = video_path(run.path, seed)
        play = (f'<a href="{_link(data.directory, video)}">video</a>' if video.is_file()
                else f"<code>{_e(replay_command(run.path, seed))}</code>")
        cell = f"cell {_e(run.name)}, " if data.is_sweep else ""
        cards.append(f'<div class="failure" id="seed-{_e(run.name)}-{seed}">{thumb}'
                     f'<p><b>{cell}seed {seed}</b>: <span class="bad">{_e(r.failure)}'
                     f'</span><br>{_e(r.failure_detail)}</p><p>{play}</p></div>')
    return cards


def _episode_rows(data: ReportData) -> list[str]:
    rows = []
    for run in data.runs:
        for r in run.records:
            seed = r.seed
            if isinstance(r, SceneErrorRecord):
                outcome, reason, detail = "no scene", "scene_error", r.error
            elif r.success:
                outcome, reason, detail = "success", "", ""
            else:
                outcome, reason, detail = "failure", r.failure or "", r.failure_detail
            cls = "ok" if outcome == "success" else "bad"
            cells = [f'<td class="num" data-v="{seed}">{seed}</td>']
            if data.is_sweep:
                cells.append(f"<td>{_e(run.name)}</td>")
            cells += [f'<td class="{cls}">{outcome}</td>', f"<td>{_e(reason)}</td>",
                      f"<td>{_e(detail)}</td>"]
            for _, keys in _NUMBERS:
                v = _number(r, keys) if isinstance(r, EpisodeRecord) else None
                cells.append(f'<td class="num" data-v="{"" if v is None else v}">'
                             f'{"" if v is None else f"{v:.3g}"}</td>')
            video = video_path(run.path, int(seed))
            cells.append(f'<td><a href="{_link(data.directory, video)}">video</a></td>'
                         if video.is_file() else "<td></td>")
            rows.append("<tr>" + "".join(cells) + "</tr>")
    return rows


def _summary(data: ReportData) -> list[str]:
    if data.sweep is None:
        s = data.runs[0].summary
        return [f'<p class="summary"><b>{_e(success_line(s))}</b></p>']
    keys = list(data.sweep["params"])
    head = "".join(f"<th>{_e(k)}</th>" for k in keys)
    out = [f'<p>Scene {_e(data.sweep["scene"])}, overrides '
           f'{_e(data.sweep["overrides"] or "none")}.</p>',
           f'<table class="sortable" id="cells"><thead><tr>{head}<th>cell</th><th>episodes</th>'
           "<th>successes</th><th>success, %</th><th>95 % interval, %</th></tr></thead><tbody>"]
    for row in data.rows:
        lo, hi = row["success_ci95"]
        rate = 100 * row["success_rate"] if row["episodes"] else None
        out.append("<tr>" + "".join(f"<td>{_e(row['settings'][k])}</td>" for k in keys)
                   + f"<td>{_e(row['cell'])}</td>"
                   f'<td class="num" data-v="{row["episodes"]}">{row["episodes"]}</td>'
                   f'<td class="num" data-v="{row["successes"]}">{row["successes"]}</td>'
                   f'<td class="num" data-v="{"" if rate is None else rate}">'
                   f'{"n/a" if rate is None else f"{rate:.1f}"}</td>'
                   f"<td>{100 * lo:.1f}-{100 * hi:.1f}</td></tr>")
    out.append("</tbody></table>")
    return out


def report_html(data: ReportData, frames: FrameSource = look_frame_png) -> str:
    """The page's HTML."""
    title = f"stackpick report: {data.directory.name or data.directory}"
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<title>{_e(title)}</title><style>{_STYLE}</style></head><body>",
             f"<h1>{_e(title)}</h1>", *_summary(data),
             f'<p>Text report: <a href="{REPORT_FILE}">{REPORT_FILE}</a>; records: '
             + ", ".join(f'<a href="{_link(data.directory, run.path / RESULTS_FILE)}">'
                         f"{_e(run.name)}</a>" for run in data.runs) + ".</p>",
             "<h2>Plots</h2>"]
    for name in data.plots:
        png = (data.directory / name).read_bytes()
        parts.append(f'<img class="plot" alt="{_e(PLOT_FILES[name])}" src="{_data_uri(png)}">')
    parts.append("<h2>Failed episodes</h2>")
    budget = [MAX_THUMBNAILS]
    cards = [c for run in data.runs for c in _failure_cards(data, run, frames, budget)]
    if cards:
        parts += ["<p>Each with its wrist camera's frame at the look pose, where the first "
                  "detection is made (ground truth drawn: green the true top objects), and "
                  "its video or the command that makes it.</p>",
                  '<div class="failures">', *cards, "</div>"]
    else:
        parts.append(f"<p>No failed episodes in "
                     f"{sum(len(r.records) for r in data.runs)} recorded.</p>")
    head = ["seed", *(["cell"] if data.is_sweep else []), "outcome", "reason", "detail",
            *(h for h, _ in _NUMBERS), "replay"]
    parts += ["<h2>Episodes</h2><p>Click a column's heading to sort by it.</p>",
              '<table class="sortable" id="episodes"><thead><tr>'
              + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr></thead><tbody>",
              *_episode_rows(data), "</tbody></table>",
              f"<script>{_SCRIPT}</script></body></html>"]
    return "\n".join(parts) + "\n"


def write_html(data: ReportData, frames: FrameSource = look_frame_png) -> Path:
    """Write ``report.html`` into the report's directory; returns its path."""
    path = data.directory / HTML_FILE
    write_text(path, report_html(data, frames))
    return path

"""``report.html``: a self-contained page, checked as text and in a headless Chromium.

The browser test needs Debian's chromium (``make test`` installs it, see the Makefile's
``browser`` target) and the ``playwright`` package, which drives that binary: no browser is
downloaded. Without them it is skipped with the reason.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from urllib.parse import unquote

import cv2
import numpy as np
import pytest
from report_fakes import LONG_DETAIL, record, write_run, write_sweep

from stackpick_sim.runs.html_report import write_html
from stackpick_sim.runs.report import write_report

pytest.importorskip("matplotlib")

#: Where Debian's chromium package puts the browser.
CHROMIUM = os.environ.get("STACKPICK_CHROMIUM", "/usr/bin/chromium")
#: Where the screenshots of the browser test go (kept after the test, to look at).
SHOTS = Path(__file__).resolve().parent.parent / "out" / "screenshots"


def _frame(_run_dir: Path, seed: int) -> bytes:
    """A stand-in thumbnail: a grey square with the seed written on it."""
    img = np.full((60, 80, 3), 90, np.uint8)
    cv2.putText(img, str(seed), (10, 40), cv2.FONT_HERSHEY_SIMPLEX, 1, (255, 255, 255))
    return bytes(cv2.imencode(".png", img)[1])


def _run(tmp_path: Path) -> Path:
    records = [record(s, s not in (2, 5), theta_err=0.1 + 0.05 * s) for s in range(8)]
    out = write_run(tmp_path / "run", records)
    (out / "replay_5.mp4").write_bytes(b"\0")  # a video made for seed 5 only
    write_html(write_report(out), _frame)
    return out


def test_the_page_is_self_contained_and_lists_every_episode(tmp_path: Path) -> None:
    out = _run(tmp_path)
    page = (out / "report.html").read_text()
    assert not re.search(r"""(src|href)=["']?(https?:|//)""", page)  # nothing fetched
    assert page.count("<tr>") == 8 + 1  # the episodes and the heading
    assert page.count('class="failure"') == 2 and LONG_DETAIL in page
    assert page.count('href="replay_5.mp4"') == 2  # the video that exists: card and table ...
    assert "stackpick replay" in page and 'href="replay_2.mp4"' not in page  # ... else the command
    assert page.count("data:image/png;base64,") == 3 + 2  # the plots and the thumbnails
    assert "Success 6/8 = 75.0 % (95 % Wilson interval" in page


def test_a_sweep_page_has_its_cells_and_chart(tmp_path: Path) -> None:
    out = write_sweep(tmp_path / "sweep", {
        "conveyor.speed=0.1": [record(s, True) for s in range(3)],
        "conveyor.speed=0.3": [record(s, s != 1) for s in range(3)]}, "conveyor.speed")
    page = write_html(write_report(out), _frame).read_text()
    assert 'id="cells"' in page and "conveyor.speed=0.3" in page
    assert 'alt="success rate vs. parameter"' in page
    assert 'href="cells/conveyor.speed%3D0.1/results.jsonl"' in page


def _browser() -> object:
    if not Path(CHROMIUM).is_file():
        pytest.skip(f"no browser at {CHROMIUM}: `make browser` installs Debian's chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("the playwright package is not installed (pip install -e '.[dev]')")
    return sync_playwright


def test_the_page_in_a_headless_browser_sorts_and_its_links_resolve(tmp_path: Path) -> None:
    sync_playwright = _browser()
    out = _run(tmp_path)
    profile = tmp_path / "profile"  # a fresh user-data-dir
    with sync_playwright() as pw:  # type: ignore[operator]
        context = pw.chromium.launch_persistent_context(
            str(profile), executable_path=CHROMIUM, headless=True,
            viewport={"width": 1200, "height": 900},
            args=["--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync"])
        try:
            page = context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto((out / "report.html").as_uri())
            assert page.title() == "stackpick report: run"
            # Every image decoded (the data URIs are whole).
            assert page.eval_on_selector_all("img", "els => els.every(e => e.naturalWidth > 0)")
            # Every link points at a file that exists beside the page.
            hrefs = page.eval_on_selector_all("a", "els => els.map(e => e.href)")
            assert len(hrefs) >= 3
            for href in hrefs:
                assert href.startswith("file://")
                assert Path(unquote(href.removeprefix("file://"))).exists(), href

            def column(n: int) -> list[str]:
                return page.eval_on_selector_all(
                    "#episodes tbody tr", f"rows => rows.map(r => r.cells[{n}].textContent)")

            assert column(0) == [str(s) for s in range(8)]
            page.click("#episodes th:nth-child(6)")  # theta_x error, ascending
            assert column(0) == [str(s) for s in range(8)]
            page.click("#episodes th:nth-child(6)")  # descending
            assert column(0) == [str(s) for s in reversed(range(8))]
            page.click("#episodes th:nth-child(2)")  # outcome, as text
            assert column(1)[:2] == ["failure", "failure"]
            page.click("#episodes th:nth-child(9)")  # cycle time: the blanks go last
            times = column(8)
            assert times[-2:] == ["", ""] and times[:6] == sorted(times[:6])
            assert not errors
            SHOTS.mkdir(parents=True, exist_ok=True)
            shot = SHOTS / "report_html.png"
            page.screenshot(path=str(shot), full_page=True)
            assert shot.stat().st_size > 10_000
        finally:
            context.close()


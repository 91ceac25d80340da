"""The README and docs say what the code does: their commands parse, their Python runs, the
scene-key table lists every key with a unit, and the product text carries no history."""

from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path
from typing import Any

import pytest

from stackpick_sim.cli.main import build_parser
from stackpick_sim.config.loader import known_keys, load_scene

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _blocks(path: Path, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", path.read_text(), flags=re.S)


def _commands(path: Path) -> list[str]:
    """Every ``stackpick ...`` or ``make ...`` line of the page's shell blocks."""
    lines = []
    for block in _blocks(path, "sh"):
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            if line.startswith(("stackpick ", "make ")):
                lines.append(line)
    return lines


def _scene_keys_module() -> Any:
    """docs/scene_keys.py, loaded from its path."""
    spec = importlib.util.spec_from_file_location("scene_keys", ROOT / "docs" / "scene_keys.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_command_shown_parses(page: Path) -> None:
    parser = build_parser()
    targets = set(re.findall(r"^([\w.-]+):", (ROOT / "Makefile").read_text(), flags=re.M))
    for line in _commands(page):
        words = shlex.split(line)
        if words[0] == "make":
            assert set(words[1:]) <= targets, line
            continue
        try:
            parser.parse_args(words[1:])
        except SystemExit as exc:  # argparse's way of refusing
            raise AssertionError(f"{page.name}: `{line}` does not parse") from exc


#: Pages the README links to that other parts of the documentation provide.
PROVIDED_ELSEWHERE = {"docs/api.md", "docs/records.md"}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page: Path) -> None:
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", page.read_text()):
        path = (page.parent / target).resolve()
        if str(path.relative_to(ROOT)) in PROVIDED_ELSEWHERE:
            continue
        assert path.exists(), f"{page.name} links to a missing {target}"


def test_the_readme_shows_commands_and_python() -> None:
    readme = ROOT / "README.md"
    assert len(_commands(readme)) >= 8
    assert _blocks(readme, "python")


def test_the_readme_python_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    for block in _blocks(ROOT / "README.md", "python"):
        exec(compile(block, "README.md", "exec"), {"__name__": "__readme__"})
    out = capsys.readouterr().out
    assert "true top" in out


def test_the_scene_key_table_is_current_and_complete() -> None:
    module = _scene_keys_module()
    page = (ROOT / "docs" / "scenes.md").read_text()
    assert module.page_with_table(page) == page, "run: python docs/scene_keys.py"
    documented = {re.sub(r"\.(NAME|KEY)(?=\.|$)", ".*", k) for k, *_ in module.rows()}
    assert documented == set(known_keys())


def test_the_custom_scene_template_loads() -> None:
    cfg = load_scene(str(ROOT / "scenes" / "example_custom.toml"))
    assert "tin" in cfg.object_types and cfg.conveyor.speed == 0.15


HISTORY = re.compile(r"\bsession \d|\(was \d|\bthe issue\b|issue's|\bearlier (value|version|"
                     r"code)|last session|seed-paper\.md|NOTES\.md|/work/", re.I)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_pages_speak_of_the_product_only(page: Path) -> None:
    hits = [line for line in page.read_text().splitlines() if HISTORY.search(line)]
    assert not hits, hits

"""The public API: every name a package exports in ``__all__`` exists (mink once shipped stale
names), and the CLI lists every subcommand module it names."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import stackpick_sim
from stackpick_sim.cli.main import COMMAND_MODULES, build_parser

PACKAGES = ["stackpick_sim"] + [
    m.name for m in pkgutil.walk_packages(stackpick_sim.__path__, "stackpick_sim.") if m.ispkg]


@pytest.mark.parametrize("name", PACKAGES)
def test_every_name_in_all_exists(name: str) -> None:
    module = importlib.import_module(name)
    for exported in getattr(module, "__all__", []):
        assert hasattr(module, exported), f"{name}.__all__ names missing {exported!r}"


def test_top_level_package_declares_all() -> None:
    assert stackpick_sim.__all__


def test_every_subcommand_has_help() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(COMMAND_MODULES) <= {c.replace("-", "_") for c in sub.choices}  # type: ignore[union-attr]
    for name, command in sub.choices.items():  # type: ignore[union-attr]
        assert command.description, f"stackpick {name} --help has no description"


def test_version_is_printed(capsys: pytest.CaptureFixture[str]) -> None:
    from stackpick_sim.cli.main import main, package_version

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"stackpick {package_version()}"
    assert package_version()[0].isdigit()


def test_every_command_taking_seeds_has_the_same_default() -> None:
    from stackpick_sim.cli.common import DEFAULT_SEEDS, parse_seeds

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    takers = []
    for name, command in sub.choices.items():  # type: ignore[union-attr]
        action = next((a for a in command._actions if a.dest == "seeds"), None)
        if action is not None:
            takers.append(name)
            assert action.default in (DEFAULT_SEEDS, None), name  # None: bench-detect --data
            assert DEFAULT_SEEDS in (action.help or ""), name
    assert {"dataset", "run", "sweep", "bench-detect"} <= set(takers)
    assert parse_seeds(DEFAULT_SEEDS)

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

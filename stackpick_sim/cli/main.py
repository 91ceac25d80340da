"""The ``stackpick`` command line.

Each subcommand lives in its own module ``stackpick_sim/cli/<name>_cmd.py`` exposing
``register(subparsers) -> None``, which adds its parser and sets ``func=run`` where
``run(args: argparse.Namespace) -> int`` returns the exit code. Any
:class:`~stackpick_sim.exceptions.StackpickError` becomes one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import os
import sys
from collections.abc import Sequence

from stackpick_sim.exceptions import StackpickError
from stackpick_sim.glcheck import gl_failure_message
from stackpick_sim.liboutput import route_mujoco_warnings

#: Subcommand modules, in the order --help lists them.
COMMAND_MODULES: tuple[str, ...] = ("render", "dataset", "detect", "bench_detect", "run",
                                     "replay", "sweep", "report", "check")


def package_version() -> str:
    """The installed stackpick-sim's version, or "unknown" when it runs from a bare source tree."""
    try:
        return importlib.metadata.version("stackpick-sim")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="stackpick",
        description="MuJoCo digital twin of a vision-guided cell that picks the top object off "
        "stacks of cylinders on a moving conveyor.",
    )
    parser.add_argument("--version", action="version", version=f"stackpick {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"stackpick_sim.cli.{name}_cmd").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``stackpick`` script; returns the process exit code."""
    try:
        import mujoco  # noqa: F401 - it loads the GL backend at import and fails there if broken
    except Exception as exc:
        print(f"stackpick: error: {gl_failure_message(exc)}", file=sys.stderr)
        return 2
    route_mujoco_warnings()
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except StackpickError as exc:
        print(f"stackpick {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # an unwritable --out, a file where a directory should be, ...
        where = f" {exc.filename!r}" if exc.filename else ""
        print(f"stackpick {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"stackpick {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

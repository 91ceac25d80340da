"""Arguments shared by the subcommands: scene selection, overrides, seed ranges."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from stackpick_sim.config.loader import available_scenes, load_scene
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import ConfigError

#: The seeds a command runs when --seeds is not given (every command that takes --seeds).
DEFAULT_SEEDS = "0:10"
#: --seeds' help text.
SEEDS_HELP = f"N, START:STOP (end exclusive) or N,N,... (default: {DEFAULT_SEEDS})"


def add_scene_args(parser: argparse.ArgumentParser) -> None:
    """``--scene NAME_OR_PATH`` and repeatable ``--set key=value``."""
    parser.add_argument(
        "--scene", default="paper", metavar="NAME_OR_PATH",
        help=f"scene name ({', '.join(available_scenes())}) or path to a .toml file "
        "(default: paper)")
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scene key, value parsed as TOML; repeatable, e.g. "
        "--set conveyor.speed=0.2 --set objects.count=[4,6] --set camera.noise_std=3")


def scene_from_args(args: argparse.Namespace) -> SceneConfig:
    """The scene config named by ``--scene`` with the ``--set`` overrides applied."""
    return load_scene(args.scene, args.overrides)


def parse_seeds(text: str) -> list[int]:
    """``"7"`` -> [7]; ``"0:100"`` -> 0..99 (end exclusive); ``"1,5,9"`` -> [1, 5, 9]."""
    try:
        if ":" in text:
            start_s, _, stop_s = text.partition(":")
            start, stop = int(start_s), int(stop_s)
            if not 0 <= start < stop:
                raise ValueError
            return list(range(start, stop))
        seeds = [int(s) for s in text.split(",")]
        if any(s < 0 for s in seeds):
            raise ValueError
        return seeds
    except ValueError:
        raise ConfigError(f"--seeds {text!r} is not a seed list; use N, START:STOP with "
                          "0 <= START < STOP, or N,N,... (non-negative integers)") from None


def bounded_int(minimum: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``minimum``, or a clear usage error."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value

    return parse


#: argparse type for one seed (a non-negative integer).
seed_arg = bounded_int(0)
#: argparse type for a count (an integer >= 1).
positive_int = bounded_int(1)

"""Pipeline stages by name: built-ins, ``module:attr`` paths and entry points.

A stage is named by a string, so that run specs stay plain strings and every worker (a
local process or a Ray task) resolves it itself:

* a built-in: detectors ``ours``, ``oracle``, ``rht``, ``findellipses``; estimators
  ``belt``, ``image``; controller ``ibvs``;
* ``package.module:attr``: a class or factory in an importable module (the current
  directory is importable, so ``examples.hough_detector:HoughDetector`` works from the
  repository root);
* an entry point of the group ``stackpick_sim.detectors`` (``.estimators``,
  ``.controllers``) of an installed distribution, by its name.

Factories are called with the scene config (:class:`stackpick_sim.config.scene_config.
SceneConfig`); estimators also with the camera intrinsics and ``exact`` (the detector is
ground truth). The built-in ``oracle`` alone is also given the cell's truth.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any, Literal

from stackpick_sim.exceptions import ConfigError

Kind = Literal["detector", "estimator", "controller"]
KINDS: tuple[Kind, ...] = ("detector", "estimator", "controller")

#: Built-in stages: name -> ``module:attr`` of the factory.
BUILTINS: dict[str, dict[str, str]] = {
    "detector": {
        "ours": "stackpick_sim.episodes.detectors:VisionDetector",
        "oracle": "stackpick_sim.episodes.detectors:OracleDetector",
        "rht": "stackpick_sim.episodes.detectors:rht_detector",
        "findellipses": "stackpick_sim.episodes.detectors:findellipses_detector",
    },
    "estimator": {
        "belt": "stackpick_sim.episodes.hypotheses:belt_estimator",
        "image": "stackpick_sim.episodes.hypotheses:image_estimator",
    },
    "controller": {"ibvs": "stackpick_sim.episodes.controllers:IbvsController"},
}
#: The built-ins that are handed the cell's ground truth.
TRUTH_STAGES = frozenset({("detector", "oracle")})


class PluginError(ConfigError):
    """A stage name that names nothing loadable (unknown, not importable, not callable)."""


def group(kind: Kind) -> str:
    """The entry-point group of ``kind``: ``stackpick_sim.detectors`` etc."""
    return f"stackpick_sim.{kind}s"


def known(kind: Kind) -> list[str]:
    """Names of the built-ins and installed entry points of ``kind``."""
    names = list(BUILTINS[kind])
    names += sorted(ep.name for ep in entry_points(group=group(kind)) if ep.name not in names)
    return names


def _import_attr(path: str) -> Any:
    module_name, _, attr = path.partition(":")
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.append(os.getcwd())  # ``examples.x:Y`` from the directory a run starts in
    module = importlib.import_module(module_name)
    obj: Any = module
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def load(kind: Kind, name: str) -> Callable[..., Any]:
    """The factory of the ``kind`` stage ``name``; PluginError (one line) if there is none."""
    builtin = BUILTINS[kind].get(name)
    path = builtin
    if path is None and ":" not in name:
        found = [ep for ep in entry_points(group=group(kind)) if ep.name == name]
        if not found:
            raise PluginError(f"unknown {kind} {name!r}; known: {', '.join(known(kind))}, "
                              "or module:attr")
        path = found[0].value
    try:
        factory = _import_attr(path or name)
    except (ImportError, AttributeError, ValueError) as exc:
        raise PluginError(f"cannot load {kind} {name!r}: {type(exc).__name__}: {exc}; known: "
                          f"{', '.join(known(kind))}, or module:attr") from None
    if not callable(factory):
        raise PluginError(f"{kind} {name!r} is not a class or factory (got "
                          f"{type(factory).__name__})")
    return factory


def check(kind: Kind, name: str) -> None:
    """Raise PluginError unless ``name`` loads (the CLI's early check, in the driver)."""
    load(kind, name)


def version_of(stage: object) -> str | None:
    """A stage's ``version`` attribute (or its module's ``__version__``) as text, if any."""
    version = getattr(stage, "version", None)
    if version is None:
        module = sys.modules.get(type(stage).__module__)
        version = getattr(module, "__version__", None)
    return None if version is None else str(version)
